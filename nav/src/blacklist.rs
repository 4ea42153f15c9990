//! Goals given up, and the second look they get before a mission calls itself complete.
//!
//! A robot gives a frontier's goal up when it reached it and looked around without the frontier
//! going away (unknown space inside furniture, a spot the camera cannot see from there), or when
//! it made no progress toward it. The planner then ignores frontiers near that goal, so the robot
//! does not fly back again and again. But a goal given up once may have failed by chance (the
//! look around came while the map lagged, another drone was in the way): when nothing else is
//! left, each such goal is tried once more before the mission ends. A goal given up twice is
//! ignored for good.
//!
//! A look around the SLAM lost the map in is no look at all: the camera never saw what the
//! goal was for (in SITL, a goal in the corridor given up twice that way hid the only way on to
//! 60 % of the apartment, and the mission called itself complete at 41 % coverage). Such a goal
//! ([`Blacklist::look_cut`]) is set aside like one given up, but its second looks go on until it
//! has failed [`MAX_TRIES`] times in all.

/// At most this many failures of one goal, cut looks included, before it is ignored for good.
pub const MAX_TRIES: u32 = 3;

/// A goal given up, and how often.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GivenUp {
    /// Where, map frame, metres.
    pub at: [f64; 2],
    /// How many times a robot gave it up.
    pub times: u32,
    /// How many of those were looks around cut short by a lost map.
    pub cut: u32,
    /// Released for its second look: the planner does not ignore it now.
    pub released: bool,
}

/// The goals given up in a mission.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Blacklist {
    entries: Vec<GivenUp>,
    /// Two goals within this distance are the same, metres.
    radius_m: f64,
}

impl Blacklist {
    /// An empty list; goals within `radius_m` of each other count as one.
    pub fn new(radius_m: f64) -> Self {
        Self {
            entries: vec![],
            radius_m,
        }
    }

    /// A robot gave up the goal `at`: ignored from now on (again, if it had been released).
    pub fn give_up(&mut self, at: [f64; 2]) {
        self.fail(at, false);
    }

    /// A robot's look around at the goal `at` was cut short by a lost map: ignored for now,
    /// but not counted as a look at it (see the module's documentation).
    pub fn look_cut(&mut self, at: [f64; 2]) {
        self.fail(at, true);
    }

    fn fail(&mut self, at: [f64; 2], cut: bool) {
        let near = self
            .entries
            .iter_mut()
            .find(|e| (e.at[0] - at[0]).hypot(e.at[1] - at[1]) <= self.radius_m);
        match near {
            Some(e) => {
                e.times += 1;
                e.cut += u32::from(cut);
                e.released = false;
            }
            None => self.entries.push(GivenUp {
                at,
                times: 1,
                cut: u32::from(cut),
                released: false,
            }),
        }
    }

    /// The goals the planner ignores now.
    pub fn ignored(&self) -> Vec<[f64; 2]> {
        self.entries
            .iter()
            .filter(|e| !e.released)
            .map(|e| e.at)
            .collect()
    }

    /// Releases every goal given up only once (looks cut short not counted, fewer than
    /// [`MAX_TRIES`] failures in all), not yet released, that hides one of the frontier goals in
    /// `hidden` (what the planner ignored, [`crate::Plan::ignored`]), for a second look; returns
    /// how many (0: nothing left to retry).
    pub fn second_look(&mut self, hidden: &[[f64; 2]]) -> usize {
        let r = self.radius_m;
        let mut n = 0;
        for e in &mut self.entries {
            let hides = hidden
                .iter()
                .any(|g| (e.at[0] - g[0]).hypot(e.at[1] - g[1]) <= r);
            let looks = e.times - e.cut;
            if looks <= 1 && e.times < MAX_TRIES && !e.released && hides {
                e.released = true;
                n += 1;
            }
        }
        n
    }

    /// Every goal given up, in the order first given up.
    pub fn entries(&self) -> &[GivenUp] {
        &self.entries
    }

    /// Number of distinct goals given up.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Nothing given up.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Forgets everything (a new mission).
    pub fn clear(&mut self) {
        self.entries.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_look_cut_short_is_not_a_look_but_tries_are_bounded() {
        let mut b = Blacklist::new(0.5);
        let hidden = [[1.0, 1.0]];
        // Two looks cut short by a lost map: still released for another.
        b.look_cut([1.0, 1.0]);
        assert_eq!(b.ignored(), vec![[1.0, 1.0]], "set aside for now");
        assert_eq!(b.second_look(&hidden), 1);
        b.look_cut([1.1, 1.0]);
        assert_eq!((b.entries()[0].times, b.entries()[0].cut), (2, 2));
        assert_eq!(b.second_look(&hidden), 1, "a cut look is not a look");
        // A third failure of any kind is the last.
        b.look_cut([1.0, 1.1]);
        assert_eq!(b.second_look(&hidden), 0);
        assert_eq!(b.ignored(), vec![[1.0, 1.0]]);
        // One cut and one whole look that failed: one more look, as for a goal given up once.
        let mut b = Blacklist::new(0.5);
        b.look_cut([1.0, 1.0]);
        b.give_up([1.0, 1.0]);
        assert_eq!(b.second_look(&hidden), 1);
        b.give_up([1.0, 1.0]);
        assert_eq!(b.second_look(&hidden), 0, "two whole looks failed");
    }

    #[test]
    fn a_goal_given_up_once_gets_one_second_look_then_is_ignored_for_good() {
        let mut b = Blacklist::new(0.5);
        b.give_up([1.0, 1.0]);
        b.give_up([5.0, 5.0]);
        b.give_up([9.0, 9.0]);
        assert_eq!(b.ignored(), vec![[1.0, 1.0], [5.0, 5.0], [9.0, 9.0]]);
        // Nothing else left: the two that hide a frontier are released once; the third hides
        // none (its frontier went away) and stays.
        let hidden = [[1.1, 1.1], [5.0, 4.6], [3.0, 3.0]];
        assert_eq!(b.second_look(&hidden), 2);
        assert_eq!(b.ignored(), vec![[9.0, 9.0]]);
        assert_eq!(
            b.second_look(&hidden),
            0,
            "a released goal is not released twice"
        );
        // The first fails again (a goal nearby counts as the same): ignored for good.
        b.give_up([1.2, 0.9]);
        assert_eq!(b.ignored(), vec![[1.0, 1.0], [9.0, 9.0]]);
        assert_eq!(b.entries()[0].times, 2);
        assert_eq!(b.second_look(&hidden), 0);
        assert_eq!(b.len(), 3);
    }

    #[test]
    fn goals_apart_are_counted_apart_and_clear_forgets_them() {
        let mut b = Blacklist::new(0.5);
        b.give_up([0.0, 0.0]);
        b.give_up([0.6, 0.0]);
        b.give_up([0.0, 0.4]);
        assert_eq!(b.len(), 2);
        assert_eq!(b.entries()[0].times, 2);
        b.clear();
        assert!(b.is_empty());
        assert_eq!(b.second_look(&[[0.0, 0.0]]), 0);
    }
}
