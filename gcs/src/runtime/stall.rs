//! A mission that stopped going anywhere: the planner still counts a frontier as reachable (its
//! plan is not complete, so the mission does not end) while it gives no exploring drone a goal.
//! Nothing else ends that state before the timeout or the batteries, so after a while the
//! mission says why each drone hovers and lands them all rather than hover on.
//!
//! A planner fault is what gets there: a frontier behind a drone, weighed with the turn to face
//! its path, once cost more than one it could not reach, and a three-drone mission's last drone
//! hovered 330 s to the timeout.

/// How long a stall lasts before the mission ends on it, seconds: past a look around (10 s, 20 s
/// on few matches) and a drone's landing for a lost pose (30 s), which also leave a plan without
/// goals for a while.
pub const STALL_S: f64 = 60.0;

/// Watches the plans for a stall.
#[derive(Debug, Clone, Default)]
pub struct Stall {
    since: Option<f64>,
}

impl Stall {
    /// A plan taken at mission time `now`: `open` when it counts a reachable frontier, `going`
    /// when some drone has a goal. Returns for how long the mission has stalled, seconds (0 when
    /// it has not).
    pub fn observe(&mut self, now: f64, open: bool, going: bool) -> f64 {
        if !open || going {
            self.since = None;
            return 0.0;
        }
        now - *self.since.get_or_insert(now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stall_is_timed_from_the_first_plan_without_goals_and_ends_with_a_goal_or_the_end() {
        let mut stall = Stall::default();
        assert_eq!(stall.observe(0.0, true, true), 0.0);
        assert_eq!(stall.observe(1.0, true, false), 0.0);
        assert_eq!(stall.observe(31.0, true, false), 30.0);
        // A goal given again: the clock starts over.
        assert_eq!(stall.observe(32.0, true, true), 0.0);
        assert_eq!(stall.observe(33.0, true, false), 0.0);
        assert_eq!(stall.observe(40.0, true, false), 7.0);
        // Nothing reachable left is the end of the mission, not a stall.
        assert_eq!(stall.observe(41.0, false, false), 0.0);
        assert_eq!(stall.observe(42.0, true, false), 0.0);
        assert_eq!(stall.observe(42.0 + STALL_S, true, false), STALL_S);
    }
}
