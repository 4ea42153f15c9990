//! The look around at a goal: which way to turn, and when the camera has seen enough.
//!
//! A robot that reaches a frontier's goal turns on the spot so its camera (about 60° wide) sees
//! every side. A whole turn took 10 s at every goal, yet most of what it looked at was known
//! already: the robot arrives facing the way it flew, and it flew through known space. The
//! sweep looks at the map instead. A ray from the robot per bearing tells whether the camera,
//! looking that way, would see unknown cells within its depth range (through free and unknown
//! cells, up to the first wall). The turn goes the way that brings every such bearing into view
//! soonest, and ends once none is left ahead of the camera.

use std::f64::consts::TAU;

use crate::grid::{Cell, Grid};

/// What the camera sees from where the robot looks around.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Half the camera's horizontal field of view, radians (a Kinect's is 0.55; a little less
    /// leaves a margin at the image's edge, where depth is sparse).
    pub half_fov_rad: f64,
    /// Nearest depth the camera measures, metres.
    pub min_range_m: f64,
    /// Farthest depth the occupancy map takes, metres (a bit under it: far depth is noisy and
    /// sparse).
    pub max_range_m: f64,
    /// A bearing shows the unknown when its ray crosses at least this many unknown cells in
    /// range: fewer are the ragged edges of walls.
    pub min_unknown_cells: usize,
    /// How far the turn's goal runs ahead of what the map shows, radians: the heading lags its
    /// goal and the map lags the camera (about 1.6 s at the look around's 36°/s).
    pub lag_rad: f64,
}

impl Default for View {
    fn default() -> Self {
        Self {
            half_fov_rad: 0.5,
            min_range_m: 0.4,
            max_range_m: 3.5,
            min_unknown_cells: 4,
            lag_rad: 1.0,
        }
    }
}

impl View {
    /// Bearings this near the left or right edge of the image do not count as seen, radians:
    /// depth is sparse there.
    pub const EDGE_MARGIN_RAD: f64 = 0.05;

    /// These settings for a camera that sees `camera_half_fov_rad` either side of its axis
    /// (from its intrinsics), less [`Self::EDGE_MARGIN_RAD`]. A field of view that is not a
    /// number or no wider than the margin (intrinsics that cannot be right) leaves them as they
    /// are.
    pub fn for_camera(self, camera_half_fov_rad: f64) -> Self {
        if camera_half_fov_rad.is_finite() && camera_half_fov_rad > 2.0 * Self::EDGE_MARGIN_RAD {
            Self {
                half_fov_rad: camera_half_fov_rad - Self::EDGE_MARGIN_RAD,
                ..self
            }
        } else {
            self
        }
    }
}

/// Bearings in the map frame (radians, + = counter-clockwise from +x) of `bins` equal sectors
/// around `at`: `true` for each whose central ray crosses unknown cells (at least
/// [`View::min_unknown_cells`]) between the camera's minimum and maximum range before it meets
/// a wall or leaves the map.
pub fn unknown_bearings(map: &Grid, at: [f64; 2], view: &View, bins: usize) -> Vec<bool> {
    unknown_cells(map, at, view, bins)
        .into_iter()
        .map(|n| n >= view.min_unknown_cells)
        .collect()
}

/// How many unknown cells the central ray of each of `bins` equal sectors around `at` crosses
/// between the camera's minimum and maximum range before it meets a wall or leaves the map:
/// how much a look that way would show ([`unknown_bearings`] counts those of at least
/// [`View::min_unknown_cells`]).
pub fn unknown_cells(map: &Grid, at: [f64; 2], view: &View, bins: usize) -> Vec<usize> {
    let step = map.resolution() / 2.0;
    (0..bins)
        .map(|b| {
            let bearing = bearing_of(b, bins);
            let (dx, dy) = (bearing.cos(), bearing.sin());
            let mut unknown = 0;
            let mut last = None;
            let mut s = 0.0;
            while s <= view.max_range_m {
                let Some(c) = map.cell_of([at[0] + s * dx, at[1] + s * dy]) else {
                    break;
                };
                match map.get(c) {
                    Cell::Occupied => break,
                    Cell::Unknown if s >= view.min_range_m && last != Some(c) => unknown += 1,
                    _ => {}
                }
                last = Some(c);
                s += step;
            }
            unknown
        })
        .collect()
}

/// The bearing at the centre of bin `b` of `bins`.
fn bearing_of(b: usize, bins: usize) -> f64 {
    (b as f64 + 0.5) * TAU / bins as f64
}

/// How far a bearing lies from `start` turning in `direction` (+1 counter-clockwise, −1
/// clockwise), in [0, 2π).
fn turned(bearing: f64, start: f64, direction: f64) -> f64 {
    ((bearing - start) * direction).rem_euclid(TAU)
}

/// How far a camera facing `yaw` must turn in `direction` (+1 counter-clockwise, −1
/// clockwise) before `bearing` comes into its view, radians (0: in view now).
fn turn_to_see(bearing: f64, yaw: f64, direction: f64, view: &View) -> f64 {
    let o = turned(bearing, yaw, direction);
    if o <= view.half_fov_rad || o >= TAU - view.half_fov_rad {
        0.0
    } else {
        o - view.half_fov_rad
    }
}

/// The way to turn from heading `yaw` so that every bearing of `unknown` (from
/// [`unknown_bearings`]) not in view now comes into view soonest: +1 counter-clockwise, −1
/// clockwise (counter-clockwise on a tie).
pub fn direction(unknown: &[bool], yaw: f64, view: &View) -> f64 {
    let need = |direction: f64| {
        unknown
            .iter()
            .enumerate()
            .filter(|&(_, &u)| u)
            .map(|(b, _)| turn_to_see(bearing_of(b, unknown.len()), yaw, direction, view))
            .fold(0.0, f64::max)
    };
    // A tie (the same turn either way, to rounding) goes counter-clockwise.
    if need(-1.0) < need(1.0) - 1e-9 {
        -1.0
    } else {
        1.0
    }
}

/// The way to turn from heading `yaw` so that what the map shows unknown comes into view
/// soonest on average, each bearing weighed by its unknown `cells` (from [`unknown_cells`];
/// bearings with fewer than [`View::min_unknown_cells`] weigh nothing): +1 counter-clockwise,
/// −1 clockwise (counter-clockwise on a tie). Where [`direction`] ends the whole look
/// soonest, this sees the most first: a room through a door before the shadow of a jamb, so
/// the planner can send a waiting robot there while the look goes on.
pub fn direction_most_unknown_first(cells: &[usize], yaw: f64, view: &View) -> f64 {
    let wait = |direction: f64| -> f64 {
        cells
            .iter()
            .enumerate()
            .filter(|&(_, &n)| n >= view.min_unknown_cells)
            .map(|(b, &n)| n as f64 * turn_to_see(bearing_of(b, cells.len()), yaw, direction, view))
            .sum()
    };
    if wait(-1.0) < wait(1.0) - 1e-9 {
        -1.0
    } else {
        1.0
    }
}

/// Whether a look around that began facing `yaw0`, turning in `direction`, and has turned its
/// heading goal through `swept` radians, still has something to look at: a bearing of `unknown`
/// from the leading edge of the view now (less [`View::lag_rad`]) to where a whole turn would
/// leave the view.
pub fn still_unknown_ahead(
    unknown: &[bool],
    yaw0: f64,
    direction: f64,
    swept: f64,
    view: &View,
) -> bool {
    let from = swept + view.half_fov_rad - view.lag_rad;
    let to = TAU - view.half_fov_rad;
    unknown.iter().enumerate().any(|(b, &u)| {
        let o = turned(bearing_of(b, unknown.len()), yaw0, direction);
        // The bearings just behind the start (o near 2π) were in view when the turn began.
        u && o >= from && o <= to
    })
}

/// The ways to turn (+1 counter-clockwise, −1 clockwise) of robots that take off together and
/// look around where they start, at `starts` (x, y, heading; map frame; `None`: unknown).
/// Robots within `together_m` of one another see the same room, so their looks are one: each
/// turns the way that, with the others' turns, brings every bearing into some camera's view
/// soonest, and each look ends once the map shows nothing unknown ahead of it
/// ([`still_unknown_ahead`]). Turning the same way from about the same heading (a tie, as every
/// bearing is unknown at the start) two cameras see the same walls all the way round; turning
/// apart, each sees half. A robot with no other near it, or with no start, gets `None`: its own
/// look around decides.
pub fn shared_turns(starts: &[Option<[f64; 3]>], together_m: f64, view: &View) -> Vec<Option<f64>> {
    let mut turns = vec![None; starts.len()];
    for group in groups(starts, together_m) {
        // Every choice of ways is tried: 2^n of them, n at most MAX_SHARED.
        for chunk in group.chunks(MAX_SHARED).filter(|c| c.len() > 1) {
            let headings: Vec<f64> = chunk
                .iter()
                .filter_map(|&k| starts[k])
                .map(|s| s[2])
                .collect();
            let ways = |mask: usize| -> Vec<f64> {
                (0..chunk.len())
                    .map(|i| if mask >> i & 1 == 0 { 1.0 } else { -1.0 })
                    .collect()
            };
            // The first choice of the least turn wins: all counter-clockwise on a tie.
            let best = (0..1usize << chunk.len())
                .map(|mask| (shared_turn(&headings, &ways(mask), view), mask))
                .fold((f64::INFINITY, 0), |best, next| {
                    if next.0 < best.0 - 1e-9 { next } else { best }
                });
            for (&k, way) in chunk.iter().zip(ways(best.1)) {
                turns[k] = Some(way);
            }
        }
    }
    turns
}

/// The bearings the cameras of robots sharing one look around ([`shared_turns`]) have had in
/// view between them, so that each ends its turn once every side has been seen by one of them.
/// The map alone does not tell a robot that: each asks it from where it stands, and through a
/// door or past a corner it shows unknown that the others' cameras have already faced (of four
/// drones taking off together in the apartment, three turned 150° and the last 280°, about as
/// long as one drone alone).
#[derive(Debug, Clone, PartialEq)]
pub struct SharedLook {
    seen: [bool; Self::BINS],
}

impl Default for SharedLook {
    fn default() -> Self {
        Self {
            seen: [false; Self::BINS],
        }
    }
}

impl SharedLook {
    /// Bearings are counted in this many equal sectors (5°: a turn at 36°/s and 10 Hz moves
    /// the view by less than one).
    pub const BINS: usize = 72;

    /// A look around with nothing seen yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A camera of the group faces `heading` (radians, map frame) and sees as `view` says (its
    /// own camera's field of view): the sectors whose centre lies in its view are seen. A
    /// heading that is no number sees nothing.
    pub fn see(&mut self, heading: f64, view: &View) {
        if !heading.is_finite() {
            return;
        }
        let half = view.half_fov_rad;
        for (b, seen) in self.seen.iter_mut().enumerate() {
            let off = (bearing_of(b, Self::BINS) - heading).rem_euclid(TAU);
            *seen |= off <= half || off >= TAU - half;
        }
    }

    /// Whether every side has been in some camera's view.
    pub fn complete(&self) -> bool {
        self.seen.iter().all(|&s| s)
    }
}

/// At most this many robots share one look around ([`shared_turns`] tries every choice of ways
/// among them; a larger group is cut into groups of this many).
pub const MAX_SHARED: usize = 10;

/// How far cameras facing `headings`, each turning its way of `ways` at one rate, must turn
/// before every bearing has been in some camera's view, radians.
pub fn shared_turn(headings: &[f64], ways: &[f64], view: &View) -> f64 {
    const BINS: usize = 72;
    (0..BINS)
        .map(|b| {
            headings
                .iter()
                .zip(ways)
                .map(|(&h, &way)| turn_to_see(bearing_of(b, BINS), h, way, view))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

/// The robots of `starts` (their indices) in groups whose members are linked by starts within
/// `together_m` of one another; robots without a start are in none. These are the groups that
/// share a look around ([`shared_turns`], [`SharedLook`]).
pub fn groups(starts: &[Option<[f64; 3]>], together_m: f64) -> Vec<Vec<usize>> {
    let mut grouped = vec![false; starts.len()];
    let mut groups = vec![];
    for (k, start) in starts.iter().enumerate() {
        if start.is_none() || grouped[k] {
            continue;
        }
        grouped[k] = true;
        let mut members = vec![k];
        let mut next = 0;
        while let Some(&m) = members.get(next) {
            next += 1;
            let Some(a) = starts[m] else { continue };
            for (j, b) in starts.iter().enumerate() {
                if let Some(b) = b
                    && !grouped[j]
                    && (a[0] - b[0]).hypot(a[1] - b[1]) <= together_m
                {
                    grouped[j] = true;
                    members.push(j);
                }
            }
        }
        members.sort_unstable();
        groups.push(members);
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A 6 × 6 m room of known free space, walls on every side, the robot in its middle;
    /// `unknown` cells (x range, y range in metres) left unobserved.
    fn room(unknown: &[([f64; 2], [f64; 2])]) -> Grid {
        let res = 0.05;
        let mut g = Grid::new(120, 120, res, [-3.0, -3.0], Cell::Free);
        for i in 0..120 {
            for c in [(i, 0), (i, 119), (0, i), (119, i)] {
                g.set(c, Cell::Occupied);
            }
        }
        for &(xs, ys) in unknown {
            for y in 0..120 {
                for x in 0..120 {
                    let p = g.center_of((x, y));
                    if (xs[0]..xs[1]).contains(&p[0]) && (ys[0]..ys[1]).contains(&p[1]) {
                        g.set((x, y), Cell::Unknown);
                    }
                }
            }
        }
        g
    }

    #[test]
    fn a_shared_look_is_complete_once_the_cameras_have_faced_every_side_between_them() {
        let view = View::default();
        let mut look = SharedLook::new();
        assert!(!look.complete());
        // Two cameras back to back see two sectors as wide as their view, and no more.
        look.see(0.0, &view);
        look.see(PI, &view);
        look.see(f64::NAN, &view);
        assert!(!look.complete());
        // One turning counter-clockwise from east and one from west, a quarter turn each (at
        // 5° steps): the east-north and west-south quarters are seen, the rest is not yet.
        for step in 0..=18 {
            let a = f64::from(step) * 5f64.to_radians();
            look.see(a, &view);
            look.see(PI + a, &view);
        }
        assert!(
            !look.complete(),
            "a quarter turn each leaves two gaps of 90° - fov"
        );
        // Each gap closes once the camera before it has turned on by 90° - two half views.
        let gap = PI / 2.0 - 2.0 * view.half_fov_rad;
        let short = PI / 2.0 + gap - 0.1;
        look.see(short, &view);
        look.see(PI + short, &view);
        assert!(
            !look.complete(),
            "{:.0}° short of closing the gaps",
            0.1f64.to_degrees()
        );
        let past = PI / 2.0 + gap + 0.05;
        look.see(past, &view);
        look.see(PI + past, &view);
        assert!(look.complete());
    }

    #[test]
    fn a_known_room_shows_no_unknown_and_an_unseen_corner_shows_where_it_is() {
        let view = View::default();
        let known = unknown_bearings(&room(&[]), [0.0, 0.0], &view, 72);
        assert!(known.iter().all(|u| !u), "{known:?}");
        // The corner to the south-west (around bearing −135°, i.e. 225°).
        let corner = room(&[([-2.9, -1.0], [-2.9, -1.0])]);
        let u = unknown_bearings(&corner, [0.0, 0.0], &view, 72);
        let seen: Vec<f64> = (0..72)
            .filter(|&b| u[b])
            .map(|b| bearing_of(b, 72).to_degrees())
            .collect();
        assert!(!seen.is_empty());
        assert!(
            seen.iter().all(|d| (200.0..250.0).contains(d)),
            "bearings {seen:?}"
        );
    }

    #[test]
    fn walls_hide_what_lies_behind_them_and_range_limits_the_view() {
        let view = View::default();
        // Unknown beyond the east wall (outside the room): hidden by it.
        let mut g = Grid::new(160, 120, 0.05, [-3.0, -3.0], Cell::Unknown);
        for y in 1..119 {
            for x in 1..119 {
                g.set((x, y), Cell::Free);
            }
        }
        for i in 0..120 {
            for c in [(i, 0), (i, 119), (0, i), (119, i)] {
                g.set(c, Cell::Occupied);
            }
        }
        let u = unknown_bearings(&g, [0.0, 0.0], &view, 72);
        assert!(u.iter().all(|u| !u), "{u:?}");
        // Unknown 3.8 m east of the robot, beyond the 3.5 m the map takes: not worth a look.
        let far = room(&[([2.5, 2.95], [-0.2, 0.2])]);
        let u = unknown_bearings(&far, [-1.3, 0.0], &view, 72);
        assert!(u.iter().all(|u| !u), "{u:?}");
        let u = unknown_bearings(&far, [0.0, 0.0], &view, 72);
        assert!(u[0] || u[71], "2.5 m east is in range: {u:?}");
    }

    #[test]
    fn the_turn_goes_the_short_way_and_ends_once_the_unknown_has_been_in_view() {
        let view = View::default();
        // Unknown 90° to the right of a robot facing +x (south: bearing 270°).
        let south = room(&[([-0.3, 0.3], [-2.9, -1.5])]);
        let u = unknown_bearings(&south, [0.0, 0.0], &view, 72);
        assert_eq!(
            direction(&u, 0.0, &view),
            -1.0,
            "clockwise is 90°, not 270°"
        );
        // Facing north-west instead (135°): counter-clockwise reaches 270° sooner.
        assert_eq!(direction(&u, 135f64.to_radians(), &view), 1.0);
        // Clockwise from +x: ahead until the view's leading edge has passed 90° (less the
        // lag margin of one view), then nothing is left.
        let ahead =
            |swept_deg: f64| still_unknown_ahead(&u, 0.0, -1.0, swept_deg.to_radians(), &view);
        assert!(ahead(0.0));
        assert!(ahead(60.0));
        assert!(ahead(110.0), "the map may not show what the camera saw yet");
        assert!(!ahead(150.0));
        // The unknown on every side: as far either way, so counter-clockwise.
        assert_eq!(direction(&[true; 72], 0.0, &view), 1.0);
        // Nothing unknown at all: nothing to look at, the way does not matter.
        let none = vec![false; 72];
        assert_eq!(direction(&none, 1.0, &view), 1.0);
        assert!(!still_unknown_ahead(&none, 1.0, 1.0, 0.0, &view));
    }

    #[test]
    fn most_unknown_first_turns_toward_a_room_through_a_door_before_a_sliver_the_short_way() {
        let view = View::default();
        // Facing north (90°): a sliver of unknown just out of view to the right (bearings
        // 35–47°, a jamb's shadow), and an unknown room through a door to the west (bearings
        // 153–207°).
        let map = room(&[([1.2, 1.6], [1.0, 1.4]), ([-2.9, -1.0], [-0.5, 0.5])]);
        let cells = unknown_cells(&map, [0.0, 0.0], &view, 72);
        let bearings = unknown_bearings(&map, [0.0, 0.0], &view, 72);
        assert_eq!(
            bearings,
            cells
                .iter()
                .map(|&n| n >= view.min_unknown_cells)
                .collect::<Vec<_>>()
        );
        let (west, sliver) = (cells[35] + cells[36], cells[7] + cells[8]);
        assert!(
            west > 2 * sliver && sliver > 0,
            "west {west}, sliver {sliver}"
        );
        let north = 90f64.to_radians();
        // Seeing everything: counter-clockwise the view's edge turns 288° to the sliver,
        // clockwise 269° to the door; the shortest whole look is clockwise…
        assert_eq!(direction(&bearings, north, &view), -1.0);
        // …but counter-clockwise the room is in view after 88°, not 215–269°.
        assert_eq!(direction_most_unknown_first(&cells, north, &view), 1.0);
        // With the room on the right instead, both agree.
        let east = room(&[([0.6, 2.9], [-1.0, 1.0])]);
        let cells = unknown_cells(&east, [0.0, 0.0], &view, 72);
        assert_eq!(direction_most_unknown_first(&cells, north, &view), -1.0);
        // Bearings below the ragged-edge threshold weigh nothing: none left, counter-clockwise.
        let edges: Vec<usize> = vec![view.min_unknown_cells - 1; 72];
        assert_eq!(direction_most_unknown_first(&edges, north, &view), 1.0);
    }

    #[test]
    fn the_unknown_in_view_at_the_start_is_not_a_reason_to_turn() {
        let view = View::default();
        // Unknown straight ahead (east) only: seen as the turn begins, so the turn can end.
        let east = room(&[([1.5, 2.9], [-0.3, 0.3])]);
        let u = unknown_bearings(&east, [0.0, 0.0], &view, 72);
        assert!(u.iter().any(|&u| u));
        let swept = 2.0 * view.half_fov_rad + 0.01;
        assert!(!still_unknown_ahead(&u, 0.0, 1.0, swept, &view));
        assert!(!still_unknown_ahead(&u, 0.0, -1.0, swept, &view));
        // Behind the robot (west) it stays ahead until the view has turned to it.
        let west = room(&[([-2.9, -1.5], [-0.3, 0.3])]);
        let u = unknown_bearings(&west, [0.0, 0.0], &view, 72);
        assert!(still_unknown_ahead(&u, 0.0, 1.0, 2.0, &view));
        assert!(!still_unknown_ahead(&u, 0.0, 1.0, 4.0, &view));
    }

    #[test]
    fn robots_taking_off_together_turn_apart_and_share_one_look_around() {
        let view = View::default();
        let hf = view.half_fov_rad;
        // Side by side, facing the same way: turning one way both, every bearing is in view
        // only after a whole turn less the view; turning apart, after half of one.
        let pair = [Some([0.0, 0.0, 1.0]), Some([1.0, 0.0, 1.0])];
        let turns = shared_turns(&pair, 2.0, &view);
        assert!(turns[0].is_some() && turns[1].is_some(), "{turns:?}");
        assert_ne!(turns[0], turns[1]);
        let step = TAU / 72.0;
        assert!((shared_turn(&[1.0, 1.0], &[1.0, 1.0], &view) - (TAU - 2.0 * hf)).abs() < step);
        assert!((shared_turn(&[1.0, 1.0], &[1.0, -1.0], &view) - (PI - hf)).abs() < step);
        // The apartment's four starts (facing within 90° of one another): 106° of a turn each,
        // where all counter-clockwise (the tie of every bearing unknown) needed 211°.
        let headings = [1.9635, -2.7489, 1.9635, 2.3562];
        let starts = [
            Some([13.1, 2.1, headings[0]]),
            Some([14.1, 2.1, headings[1]]),
            Some([13.1, 3.3, headings[2]]),
            Some([14.1, 3.3, headings[3]]),
        ];
        let ways: Vec<f64> = shared_turns(&starts, 2.0, &view)
            .into_iter()
            .flatten()
            .collect();
        assert_eq!(ways.len(), 4);
        assert_ne!(ways[0], ways[2], "the two facing alike turn apart");
        let together = shared_turn(&headings, &[1.0; 4], &view);
        let shared = shared_turn(&headings, &ways, &view);
        assert!(together > 200f64.to_radians(), "{}", together.to_degrees());
        assert!(shared < 110f64.to_radians(), "{}", shared.to_degrees());
        // No choice of ways does better.
        for mask in 0..16usize {
            let other: Vec<f64> = (0..4)
                .map(|i| if mask >> i & 1 == 0 { 1.0 } else { -1.0 })
                .collect();
            assert!(shared_turn(&headings, &other, &view) >= shared - 1e-9);
        }
    }

    #[test]
    fn only_robots_near_one_another_share_a_look_around() {
        let view = View::default();
        // A lone robot, one without a start, and a chain (each within 2 m of the next, the
        // ends 3 m apart): the chain is one group, the others decide for themselves.
        let starts = [
            Some([0.0, 0.0, 0.0]),
            Some([20.0, 0.0, 0.0]),
            None,
            Some([1.5, 0.0, 0.0]),
            Some([3.0, 0.0, 0.0]),
        ];
        let turns = shared_turns(&starts, 2.0, &view);
        assert_eq!((turns[1], turns[2]), (None, None));
        assert!(turns[0].is_some() && turns[3].is_some() && turns[4].is_some());
        // Apart by more than `together_m`, nobody shares.
        assert_eq!(shared_turns(&starts, 1.0, &view), vec![None; 5]);
        assert!(shared_turns(&[], 2.0, &view).is_empty());
        // A group larger than MAX_SHARED is cut into groups that each turn apart.
        let crowd: Vec<Option<[f64; 3]>> = (0..MAX_SHARED + 3)
            .map(|k| Some([0.1 * k as f64, 0.0, 0.0]))
            .collect();
        let turns = shared_turns(&crowd, 2.0, &view);
        assert!(turns.iter().all(Option::is_some));
        for chunk in turns.chunks(MAX_SHARED) {
            assert!(
                chunk.contains(&Some(1.0)) && chunk.contains(&Some(-1.0)),
                "{chunk:?}"
            );
        }
    }

    #[test]
    fn a_wider_camera_is_done_sooner_and_bad_intrinsics_change_nothing() {
        let kinect = View::default();
        let wide = kinect.for_camera(1.05);
        assert!((wide.half_fov_rad - 1.0).abs() < 1e-12);
        assert_eq!(
            (wide.max_range_m, wide.lag_rad),
            (kinect.max_range_m, kinect.lag_rad)
        );
        // A Kinect's own intrinsics give about the default.
        assert!((kinect.for_camera(0.5476).half_fov_rad - kinect.half_fov_rad).abs() < 0.01);
        for nonsense in [f64::NAN, f64::INFINITY, -0.3, 0.0, 0.1] {
            assert_eq!(kinect.for_camera(nonsense), kinect, "{nonsense}");
        }
        // Unknown behind the robot (west, 169°–191°), turning counter-clockwise: the wide view
        // has it all in sight (and the map has caught up) by 200°, the narrow one not yet.
        let west = room(&[([-2.9, -1.5], [-0.3, 0.3])]);
        let u = unknown_bearings(&west, [0.0, 0.0], &kinect, 72);
        let ahead =
            |view: &View, deg: f64| still_unknown_ahead(&u, 0.0, 1.0, deg.to_radians(), view);
        assert!(ahead(&kinect, 200.0) && ahead(&wide, 150.0));
        assert!(!ahead(&wide, 200.0));
        assert!(!ahead(&kinect, 230.0));
        // The wide view needs less of a turn to see south (270°) the short way round.
        let south = room(&[([-0.3, 0.3], [-2.9, -1.5])]);
        let u = unknown_bearings(&south, [0.0, 0.0], &kinect, 72);
        assert_eq!(direction(&u, 0.0, &wide), -1.0);
        let ahead = |view: &View| still_unknown_ahead(&u, 0.0, -1.0, 110f64.to_radians(), view);
        assert!(!ahead(&wide) && ahead(&kinect));
    }
}
