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
//! has failed [`MAX_TRIES`] times in all. Each of them turns the other way from the look that
//! was cut ([`Blacklist::look_turn`]): the same turn from the same spot loses the map at the
//! same bearing (in SITL, a look in the corridor lost it three times facing the same door,
//! and the mission again called itself complete at 40 %).

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
    /// The way the look around turned (+1 counter-clockwise, −1 clockwise) if the last
    /// failure was a look cut short.
    pub cut_turn: Option<f64>,
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
        self.fail(at, None);
    }

    /// A robot's look around at the goal `at`, turning `turn` (+1 counter-clockwise, −1
    /// clockwise), was cut short by a lost map: ignored for now, but not counted as a look at
    /// it (see the module's documentation).
    pub fn look_cut(&mut self, at: [f64; 2], turn: f64) {
        self.fail(at, Some(turn));
    }

    /// The way a look around at `goal` should turn: the other way from the last look at it,
    /// if that was cut short; `None` to choose freely.
    pub fn look_turn(&self, goal: [f64; 2]) -> Option<f64> {
        self.near(goal)
            .and_then(|e| e.cut_turn)
            .map(|turn| -turn.signum())
    }

    /// Whether two goals count as one.
    fn same(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        (a[0] - b[0]).hypot(a[1] - b[1]) <= self.radius_m
    }

    /// Whether the goal given up `e` hides one of the frontier goals in `hidden`.
    fn hides(&self, e: &GivenUp, hidden: &[[f64; 2]]) -> bool {
        hidden.iter().any(|&g| self.same(e.at, g))
    }

    fn near(&self, at: [f64; 2]) -> Option<&GivenUp> {
        self.entries.iter().find(|e| self.same(e.at, at))
    }

    fn fail(&mut self, at: [f64; 2], cut_turn: Option<f64>) {
        let cut = cut_turn.is_some();
        let near = self.entries.iter().position(|e| self.same(e.at, at));
        match near.map(|i| &mut self.entries[i]) {
            Some(e) => {
                e.times += 1;
                e.cut += u32::from(cut);
                e.released = false;
                e.cut_turn = cut_turn;
            }
            None => self.entries.push(GivenUp {
                at,
                times: 1,
                cut: u32::from(cut),
                released: false,
                cut_turn,
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
        let release: Vec<usize> = (0..self.entries.len())
            .filter(|&i| {
                let e = &self.entries[i];
                let looks = e.times - e.cut;
                looks <= 1 && e.times < MAX_TRIES && !e.released && self.hides(e, hidden)
            })
            .collect();
        for &i in &release {
            self.entries[i].released = true;
        }
        release.len()
    }

    /// The goals ignored now that hide one of the frontier goals in `hidden`: what the
    /// map still had to explore behind goals given up.
    pub fn hiding(&self, hidden: &[[f64; 2]]) -> Vec<[f64; 2]> {
        self.left_behind(hidden).map(|e| e.at).collect()
    }

    /// The goals that hide one of the frontier goals in `hidden` and were never looked at:
    /// every failure there was a look cut short by a lost map. A mission ending with some
    /// may have left a building's wing unseen behind them.
    pub fn never_seen(&self, hidden: &[[f64; 2]]) -> Vec<[f64; 2]> {
        self.left_behind(hidden)
            .filter(|e| e.cut == e.times)
            .map(|e| e.at)
            .collect()
    }

    /// The entries ignored now that hide one of the frontier goals in `hidden`.
    fn left_behind<'a>(&'a self, hidden: &'a [[f64; 2]]) -> impl Iterator<Item = &'a GivenUp> {
        self.entries
            .iter()
            .filter(move |e| !e.released && self.hides(e, hidden))
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
        b.look_cut([1.0, 1.0], -1.0);
        assert_eq!(b.ignored(), vec![[1.0, 1.0]], "set aside for now");
        assert_eq!(b.second_look(&hidden), 1);
        b.look_cut([1.1, 1.0], 1.0);
        assert_eq!((b.entries()[0].times, b.entries()[0].cut), (2, 2));
        assert_eq!(b.second_look(&hidden), 1, "a cut look is not a look");
        // A third failure of any kind is the last.
        b.look_cut([1.0, 1.1], -1.0);
        assert_eq!(b.second_look(&hidden), 0);
        assert_eq!(b.ignored(), vec![[1.0, 1.0]]);
        // One cut and one whole look that failed: one more look, as for a goal given up once.
        let mut b = Blacklist::new(0.5);
        b.look_cut([1.0, 1.0], 1.0);
        b.give_up([1.0, 1.0]);
        assert_eq!(b.second_look(&hidden), 1);
        b.give_up([1.0, 1.0]);
        assert_eq!(b.second_look(&hidden), 0, "two whole looks failed");
    }

    #[test]
    fn only_goals_that_still_hide_a_frontier_are_left_behind() {
        let mut b = Blacklist::new(0.5);
        b.give_up([1.0, 1.0]); // looked at: its frontier went away
        b.give_up([4.0, 1.0]); // its frontier stayed
        b.look_cut([8.0, 1.0], 1.0);
        let hidden = [[4.2, 1.0], [8.0, 1.1]];
        assert_eq!(b.hiding(&hidden), vec![[4.0, 1.0], [8.0, 1.0]]);
        // Released for a second look, a goal hides nothing: the planner sees its frontier.
        assert_eq!(b.second_look(&hidden), 2);
        assert!(b.hiding(&hidden).is_empty());
        b.give_up([4.0, 1.1]);
        assert_eq!(b.hiding(&hidden), vec![[4.0, 1.0]]);
    }

    #[test]
    fn a_second_look_after_a_cut_one_turns_the_other_way() {
        let mut b = Blacklist::new(0.5);
        assert_eq!(b.look_turn([1.0, 1.0]), None, "nothing known: free");
        b.look_cut([1.0, 1.0], -1.0);
        assert_eq!(b.look_turn([1.2, 1.0]), Some(1.0));
        assert_eq!(b.look_turn([3.0, 3.0]), None, "another goal");
        // Cut again turning that way: the third turns back.
        b.look_cut([1.0, 1.0], 1.0);
        assert_eq!(b.look_turn([1.0, 1.0]), Some(-1.0));
        // A whole look that failed: the next chooses freely.
        b.give_up([1.0, 1.0]);
        assert_eq!(b.look_turn([1.0, 1.0]), None);
    }

    #[test]
    fn goals_only_ever_cut_short_are_never_seen() {
        let mut b = Blacklist::new(0.5);
        for _ in 0..MAX_TRIES {
            b.look_cut([1.0, 1.0], 1.0);
        }
        b.look_cut([5.0, 5.0], 1.0);
        b.give_up([5.0, 5.0]);
        b.give_up([9.0, 9.0]);
        b.look_cut([3.0, 3.0], -1.0);
        let hidden = [[1.1, 1.0], [5.0, 5.0], [9.0, 9.0]];
        assert_eq!(b.never_seen(&hidden), vec![[1.0, 1.0]]);
        // Its frontier went away (seen from elsewhere): nothing unseen behind it.
        assert!(b.never_seen(&[[5.0, 5.0]]).is_empty());
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
