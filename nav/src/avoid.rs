//! Keeping off the walls: the last word on the position setpoint before the sticks.
//!
//! The global planner keeps a path a robot radius off the map's walls, but a drone does not fly
//! its path exactly: it coasts on through a turn (drag alone slows an attitude-mode multirotor,
//! over seconds) and overshoots where the path bends through a door. On true poses, with the
//! SLAM out of the question, every wall collision of four two-drone missions on the apartment
//! was a door jamb touched at 0.1–0.6 m/s, turning through the door or heading for a goal in it.
//! Like PX4's collision prevention, [`keep_clear`] moves the setpoint so that it never leads
//! toward a wall the map knows within `clearance_m` of the drone, and leads back out to that
//! distance when the drone is nearer. Near walls (a door) it also shortens the lead, so the
//! P term pushes less: a drone at 0.5–0.7 m/s cutting through a door at a slant touched its
//! jamb with the SLAM pose only 6 cm off. The setpoint it gives is worked out from the drone's
//! position, so it moves with the drone and no derivative term brakes a drift toward a wall;
//! [`brake_toward_walls`] does, limiting the speed toward each wall near the drone to what can
//! still stop short of it. A drone that flies a velocity has it cut the same way before it
//! leans: [`limit_approach`], to what can stop within its [`free_run`].

use crate::grid::{Cell, Grid};

/// How far to keep off the walls.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeepClear {
    /// No lead toward a wall nearer than this to the drone's centre, metres.
    pub clearance_m: f64,
    /// Within this of a wall (drone centre to wall), metres…
    pub slow_within_m: f64,
    /// …the setpoint leads the drone by at most this much (a slower approach), metres.
    pub slow_lead_m: f64,
    /// [`brake_toward_walls`]: a drone this near a wall (centre to wall) may not approach it
    /// at all, metres…
    pub stop_at_m: f64,
    /// …and farther out it may approach at this many m/s per metre beyond that, 1/s…
    pub approach_per_s: f64,
    /// …any faster is braked with this much stick per m/s…
    pub brake_gain: f64,
    /// …up to this much stick.
    pub brake_max: f64,
}

impl Default for KeepClear {
    /// For the simulated drone (radius 0.2 m): 15 cm to spare, so a door 0.7 m wide still lets
    /// it through its middle; slow through doors up to 1.2 m wide.
    fn default() -> Self {
        Self {
            clearance_m: 0.35,
            slow_within_m: 0.6,
            slow_lead_m: 0.2,
            // 5 cm to spare; 0.15 m/s at the clearance, 0.5 m/s at 0.6 m: stopping from
            // there takes about 0.3 m (a full stick tilts the drone 20°, and drag slows it).
            stop_at_m: 0.25,
            approach_per_s: 1.5,
            brake_gain: 0.6,
            brake_max: 0.3,
        }
    }
}

/// The setpoint `setpoint` (map frame, metres) made safe for a drone at `position`: at most
/// `slow_lead_m` from the drone within `slow_within_m` of an occupied cell of `map`; no part of
/// it toward any occupied cell nearer than `clearance_m` (drone centre to the cell's nearest
/// point), plus a push away from such cells by how far the drone is inside that distance.
/// Unknown cells are not walls (the planner keeps paths in known free space). A position off
/// the map, or non-positive distances, leave the setpoint as it is.
pub fn keep_clear(
    map: &Grid,
    position: [f64; 2],
    setpoint: [f64; 2],
    keep: &KeepClear,
) -> [f64; 2] {
    let near = walls_near(map, position, keep.clearance_m.max(keep.slow_within_m));
    if near.is_empty() {
        return setpoint;
    }
    let mut lead = [setpoint[0] - position[0], setpoint[1] - position[1]];
    let nearest = near.iter().map(|&(_, d)| d).fold(f64::INFINITY, f64::min);
    let length = lead[0].hypot(lead[1]);
    if nearest < keep.slow_within_m && keep.slow_lead_m > 0.0 && length > keep.slow_lead_m {
        lead = [
            lead[0] * keep.slow_lead_m / length,
            lead[1] * keep.slow_lead_m / length,
        ];
    }
    let walls: Vec<([f64; 2], f64)> = near
        .into_iter()
        .filter(|&(_, d)| d < keep.clearance_m)
        .map(|(n, d)| (n, keep.clearance_m - d))
        .collect();
    let walls = nearest_sides(walls);
    // No component toward a wall (twice over: taking one side's out can add some toward a side
    // at an angle to it, in a corner).
    for _ in 0..2 {
        for &(n, _) in &walls {
            let toward = lead[0] * n[0] + lead[1] * n[1];
            if toward < 0.0 {
                lead = [lead[0] - toward * n[0], lead[1] - toward * n[1]];
            }
        }
    }
    // Out to the clearance: the directions weighted by depth, as long as the deepest intrusion
    // (walls on opposite sides, as in a narrow door, cancel).
    let (mut push, mut deepest) = ([0.0f64; 2], 0.0f64);
    for &(n, depth) in &walls {
        push = [push[0] + depth * n[0], push[1] + depth * n[1]];
        deepest = deepest.max(depth);
    }
    let norm = push[0].hypot(push[1]);
    if norm > 1e-9 {
        let scale = deepest.min(norm) / norm;
        lead = [lead[0] + scale * push[0], lead[1] + scale * push[1]];
    }
    [position[0] + lead[0], position[1] + lead[1]]
}

/// Sticks that brake a drone at `position` moving at `velocity` (map frame: metres, m/s)
/// toward a wall the map knows faster than it could stop short of it: per side of the drone
/// within `clearance_m` or `slow_within_m` of it, an approach faster than `approach_per_s`
/// times its distance beyond `stop_at_m` is braked with `brake_gain` stick per m/s of the
/// excess, away from that wall. The result is the map-frame x and y of a stick push (rotate it
/// into the body frame), at most `brake_max` long; none for a drone moving along or away from
/// the walls.
///
/// [`keep_clear`] takes the lead toward a wall out of the setpoint, but it steers from the
/// drone's position: the setpoint moves with the drone and a controller's derivative term,
/// differencing it, sees no motion to brake. A drone drifting toward a door's jamb at 0.3 m/s
/// while it crossed the door 0.2 m off its path was not braked and touched the jamb (true
/// poses); this is the brake, like PX4's collision prevention, which limits the speed toward
/// an obstacle to what can still stop short of it.
pub fn brake_toward_walls(
    map: &Grid,
    position: [f64; 2],
    velocity: [f64; 2],
    keep: &KeepClear,
) -> [f64; 2] {
    if !(keep.brake_gain > 0.0 && keep.brake_max > 0.0 && velocity.iter().all(|v| v.is_finite())) {
        return [0.0; 2];
    }
    let within = keep.clearance_m.max(keep.slow_within_m);
    let near = walls_near(map, position, within);
    // Nearest first: the depth inside `within` orders the sides.
    let sides = nearest_sides(near.into_iter().map(|(n, d)| (n, within - d)).collect());
    let mut push = [0.0f64; 2];
    for (n, depth) in sides {
        let distance = within - depth;
        let toward = -(velocity[0] * n[0] + velocity[1] * n[1]);
        let allowed = keep.approach_per_s * (distance - keep.stop_at_m).max(0.0);
        if toward > allowed {
            let stick = (keep.brake_gain * (toward - allowed)).min(keep.brake_max);
            push = [push[0] + stick * n[0], push[1] + stick * n[1]];
        }
    }
    let length = push[0].hypot(push[1]);
    if length > keep.brake_max {
        push = [
            push[0] * keep.brake_max / length,
            push[1] * keep.brake_max / length,
        ];
    }
    push
}

/// The velocity `want` (map frame, m/s) for a drone at `position`, no faster than can still
/// stop short of the walls the map knows ahead: at most `approach_per_s` times the
/// [`free_run`] toward it. Head-on to a wall that is the approach [`brake_toward_walls`]
/// allows (`approach_per_s` per metre beyond `stop_at_m`); along a wall, or through a door's
/// middle, the run is free and the speed kept. A velocity that is not finite is returned as it
/// is.
///
/// For a drone flying a velocity ([`brake_toward_walls`] brakes one that already moves): a
/// speed loop flying at full speed toward a steer point 0.2 m off a wall, from 0.5 m, leaned
/// its whole output at the wall, beyond what the wall brake can hold, and touched it at
/// 0.6 m/s (true poses).
pub fn limit_approach(
    map: &Grid,
    position: [f64; 2],
    want: [f64; 2],
    keep: &KeepClear,
) -> [f64; 2] {
    let speed = want[0].hypot(want[1]);
    if !(speed.is_finite() && speed > 1e-9 && keep.approach_per_s > 0.0) {
        return want;
    }
    let direction = [want[0] / speed, want[1] / speed];
    let reach = speed / keep.approach_per_s;
    let run = free_run(map, position, direction, reach, keep.stop_at_m);
    if run < reach {
        let allowed = keep.approach_per_s * run;
        [direction[0] * allowed, direction[1] * allowed]
    } else {
        want
    }
}

/// How far (metres, at most `reach_m`) a drone at `position` can fly along the unit
/// `direction` before its centre comes nearer than `stop_at_m` to a wall the map knows (or, if
/// it is already nearer, nearer than it is): stepped at half the map's cells. Off the map
/// (or once the walk leaves it), or with no distance to keep, the whole reach.
pub fn free_run(
    map: &Grid,
    position: [f64; 2],
    direction: [f64; 2],
    reach_m: f64,
    stop_at_m: f64,
) -> f64 {
    if !(stop_at_m > 0.0 && reach_m > 0.0) {
        return reach_m.max(0.0);
    }
    let nearest = |p: [f64; 2]| {
        walls_near(map, p, stop_at_m)
            .iter()
            .map(|&(_, d)| d)
            .fold(f64::INFINITY, f64::min)
    };
    // Already nearer than `stop_at_m` (pushed out by `keep_clear`): no nearer, with a little
    // slack for the cells' corners passing by.
    let floor = nearest(position).min(stop_at_m) - 1e-3;
    let step = map.resolution() / 2.0;
    let mut run = 0.0;
    while run < reach_m {
        let next = (run + step).min(reach_m);
        let p = [
            position[0] + direction[0] * next,
            position[1] + direction[1] * next,
        ];
        if map.cell_of(p).is_none() {
            // Past the map's edge nothing is known: free from there (and the walk ends however
            // far the reach).
            return reach_m;
        }
        if nearest(p) < floor {
            return run;
        }
        run = next;
    }
    reach_m
}

/// A stick push (map-frame x and y, as [`brake_toward_walls`] gives) that brakes a drone
/// moving at `velocity` faster than `limit` m/s: against its motion, `brake_gain` stick per m/s
/// of the excess, at most `brake_max` (the same brake as for a wall). None at or below the limit.
///
/// A path follower's carrot leads the drone by a fixed distance, so a drone keeps its speed
/// into a path's bend; slowed by the bend's speed limit ([`crate::local::Follow::Track`]), it
/// takes a door off a corridor without overshooting into the jamb beyond it.
pub fn brake_to_speed(velocity: [f64; 2], limit: f64, keep: &KeepClear) -> [f64; 2] {
    let speed = velocity[0].hypot(velocity[1]);
    if !(speed.is_finite() && speed > limit && keep.brake_gain > 0.0) {
        return [0.0; 2];
    }
    let stick = (keep.brake_gain * (speed - limit)).min(keep.brake_max);
    [-velocity[0] / speed * stick, -velocity[1] / speed * stick]
}

/// The nearest wall point on each side of the drone: the intrusions deepest first, each kept
/// only if its direction is more than 45° from every one kept before. A straight wall's cells
/// beside the nearest one lie at angles to it; taken as walls of their own, they would forbid
/// flying along the wall, and only its nearest point bounds the drone. Two walls of a corner, or
/// the two jambs of a door, are sides of their own.
fn nearest_sides(mut walls: Vec<([f64; 2], f64)>) -> Vec<([f64; 2], f64)> {
    walls.sort_by(|a, b| b.1.total_cmp(&a.1));
    let cos_45 = std::f64::consts::FRAC_1_SQRT_2;
    let mut sides: Vec<([f64; 2], f64)> = vec![];
    for (n, depth) in walls {
        if sides
            .iter()
            .all(|(m, _)| n[0] * m[0] + n[1] * m[1] < cos_45)
        {
            sides.push((n, depth));
        }
    }
    sides
}

/// Every occupied cell nearer than `within_m` to `position`: the unit direction from the cell's
/// nearest point to the position, and the distance between them.
pub(crate) fn walls_near(map: &Grid, position: [f64; 2], within_m: f64) -> Vec<([f64; 2], f64)> {
    if !(within_m > 0.0 && position.iter().all(|v| v.is_finite())) {
        return vec![];
    }
    let Some((cx, cy)) = map.cell_of(position) else {
        return vec![];
    };
    let res = map.resolution();
    let half = res / 2.0;
    let reach = (within_m / res).ceil() as usize + 1;
    let mut walls = vec![];
    for y in cy.saturating_sub(reach)..(cy + reach + 1).min(map.height()) {
        for x in cx.saturating_sub(reach)..(cx + reach + 1).min(map.width()) {
            if map.get((x, y)) != Cell::Occupied {
                continue;
            }
            let c = map.center_of((x, y));
            // The cell's nearest point to the drone.
            let q = [
                position[0].clamp(c[0] - half, c[0] + half),
                position[1].clamp(c[1] - half, c[1] + half),
            ];
            let (dx, dy) = (position[0] - q[0], position[1] - q[1]);
            let d = dx.hypot(dy);
            if d >= within_m {
                continue;
            }
            // Inside the cell (the pose is off): away from its centre.
            let (dx, dy) = if d > 1e-9 {
                (dx, dy)
            } else {
                (position[0] - c[0], position[1] - c[1])
            };
            let len = dx.hypot(dy);
            if len > 1e-9 {
                walls.push(([dx / len, dy / len], d));
            }
        }
    }
    walls
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only the clearance: no slowing down.
    fn clearance(clearance_m: f64) -> KeepClear {
        KeepClear {
            clearance_m,
            slow_within_m: 0.0,
            slow_lead_m: 0.0,
            ..KeepClear::default()
        }
    }

    /// 4 m × 4 m of free space at 5 cm with a wall along x = 2.0–2.05 m, from y = 0 to `top`.
    fn wall_east(top: f64) -> Grid {
        let mut g = Grid::new(80, 80, 0.05, [0.0, 0.0], Cell::Free);
        for y in 0..80 {
            if f64::from(y as u32) * 0.05 < top {
                g.set((40, y), Cell::Occupied);
            }
        }
        g
    }

    /// 4 m × 4 m of free space at 5 cm with a wall across x = 2.0–2.05 m and a door 0.8 m wide
    /// in it at y = 1.6–2.4.
    fn wall_with_a_door() -> Grid {
        let mut g = Grid::new(80, 80, 0.05, [0.0, 0.0], Cell::Free);
        for y in 0..80 {
            let yc = (y as f64 + 0.5) * 0.05;
            if !(1.6..2.4).contains(&yc) {
                g.set((40, y), Cell::Occupied);
            }
        }
        g
    }

    #[test]
    fn a_drone_faster_than_its_limit_is_braked_against_its_motion() {
        let keep = KeepClear::default();
        // 1 m/s, 0.2 m/s over 0.8: 0.6 × 0.2 = 0.12 stick, straight back.
        let push = brake_to_speed([0.6, 0.8], 0.8, &keep);
        assert!(
            (push[0] + 0.6 * 0.12).abs() < 1e-12 && (push[1] + 0.8 * 0.12).abs() < 1e-12,
            "{push:?}"
        );
        // Far over the limit: no more than the brake's most.
        let push = brake_to_speed([0.0, -2.0], 0.3, &keep);
        assert!(
            (push[1] - keep.brake_max).abs() < 1e-12 && push[0] == 0.0,
            "{push:?}"
        );
        // At or below the limit, with none, or with no velocity to trust: nothing.
        for (velocity, limit) in [
            ([0.3, 0.4], 0.5),
            ([0.3, 0.4], 0.8),
            ([3.0, 0.0], f64::INFINITY),
            ([f64::NAN, 0.0], 0.1),
        ] {
            assert_eq!(brake_to_speed(velocity, limit, &keep), [0.0; 2]);
        }
    }

    #[test]
    fn far_from_walls_the_setpoint_is_left_alone() {
        let g = wall_east(4.0);
        assert_eq!(
            keep_clear(&g, [1.0, 2.0], [1.5, 2.3], &clearance(0.35)),
            [1.5, 2.3]
        );
        // Unknown space is not a wall.
        let unknown = Grid::new(80, 80, 0.05, [0.0, 0.0], Cell::Unknown);
        assert_eq!(
            keep_clear(&unknown, [1.0, 2.0], [3.0, 2.0], &clearance(0.35)),
            [3.0, 2.0]
        );
        // Off the map, or no clearance asked.
        assert_eq!(
            keep_clear(&g, [-1.0, 2.0], [3.0, 2.0], &clearance(0.35)),
            [3.0, 2.0]
        );
        assert_eq!(
            keep_clear(&g, [1.9, 2.0], [3.0, 2.0], &clearance(0.0)),
            [3.0, 2.0]
        );
    }

    #[test]
    fn a_setpoint_into_a_near_wall_keeps_only_what_runs_along_it() {
        let g = wall_east(4.0);
        // 0.3 m from the wall's face (x = 2.0), inside 0.35 m: the lead into the wall goes, the
        // lead along it stays, and the drone is led back out by 5 cm.
        let p = [1.7, 2.0];
        let s = keep_clear(&g, p, [2.5, 2.6], &clearance(0.35));
        assert!((s[0] - (1.7 - 0.05)).abs() < 1e-9, "{s:?}");
        assert!((s[1] - 2.6).abs() < 1e-9, "{s:?}");
        // A setpoint away from the wall is not pulled back toward it.
        let away = keep_clear(&g, p, [1.0, 2.0], &clearance(0.35));
        assert!(away[0] <= 1.0 && (away[1] - 2.0).abs() < 1e-9, "{away:?}");
    }

    #[test]
    fn a_drone_at_a_corner_of_the_wall_is_led_round_it_not_into_it() {
        // The wall ends at y = 2.0; the drone is just past its end and to its west.
        let g = wall_east(2.0);
        let p = [1.8, 2.15];
        let s = keep_clear(&g, p, [2.6, 1.5], &clearance(0.35));
        // Nothing of the setpoint leads toward the wall's end (at (2.0, 2.0)).
        let n = [p[0] - 2.0, p[1] - 2.0];
        let lead = [s[0] - p[0], s[1] - p[1]];
        assert!(lead[0] * n[0] + lead[1] * n[1] >= 0.0, "{s:?}");
    }

    #[test]
    fn a_door_with_room_on_both_sides_is_flown_through() {
        let g = wall_with_a_door();
        // In the door's middle, 0.4 m from either jamb: nothing changes.
        assert_eq!(
            keep_clear(&g, [2.02, 2.0], [2.6, 2.0], &clearance(0.35)),
            [2.6, 2.0]
        );
        // 0.15 m off its middle: led back toward the middle, still through the door.
        let s = keep_clear(&g, [2.02, 2.15], [2.6, 2.15], &clearance(0.35));
        assert!(s[0] > 2.5 && s[1] < 2.15, "{s:?}");
    }

    #[test]
    fn near_a_wall_the_lead_is_short() {
        let g = wall_east(4.0);
        let keep = KeepClear::default();
        // 0.5 m from the wall, heading along it 0.4 m ahead: 0.2 m ahead.
        let s = keep_clear(&g, [1.5, 2.0], [1.5, 2.4], &keep);
        assert!(
            (s[0] - 1.5).abs() < 1e-9 && (s[1] - 2.2).abs() < 1e-9,
            "{s:?}"
        );
        // 0.7 m from it: as it was.
        assert_eq!(keep_clear(&g, [1.3, 2.0], [1.3, 2.4], &keep), [1.3, 2.4]);
        // A lead shorter than that is kept.
        assert_eq!(keep_clear(&g, [1.5, 2.0], [1.5, 2.1], &keep), [1.5, 2.1]);
    }

    #[test]
    fn an_approach_faster_than_can_stop_short_of_a_wall_is_braked() {
        let g = wall_east(4.0);
        let keep = KeepClear::default();
        // 0.35 m from the wall's face, at 0.3 m/s toward it: 0.15 m/s over what may still stop
        // short of it, braked away from the wall (−x) with 0.6 × 0.15 of stick.
        let b = brake_toward_walls(&g, [1.65, 2.0], [0.3, 0.0], &keep);
        assert!((b[0] + 0.09).abs() < 1e-9 && b[1].abs() < 1e-9, "{b:?}");
        // The same speed along the wall, or away from it: no brake.
        assert_eq!(
            brake_toward_walls(&g, [1.65, 2.0], [0.0, 0.3], &keep),
            [0.0; 2]
        );
        assert_eq!(
            brake_toward_walls(&g, [1.65, 2.0], [-0.3, 0.0], &keep),
            [0.0; 2]
        );
        // Slow enough to stop short of it; far from it; no velocity known.
        assert_eq!(
            brake_toward_walls(&g, [1.65, 2.0], [0.1, 0.0], &keep),
            [0.0; 2]
        );
        assert_eq!(
            brake_toward_walls(&g, [1.0, 2.0], [0.8, 0.0], &keep),
            [0.0; 2]
        );
        assert_eq!(
            brake_toward_walls(&g, [1.65, 2.0], [f64::NAN, 0.0], &keep),
            [0.0; 2]
        );
        // At the wall, fast: as hard as allowed and no more.
        let hard = brake_toward_walls(&g, [1.75, 2.0], [2.0, 0.5], &keep);
        assert!((hard[0] + keep.brake_max).abs() < 1e-9 && hard[1].abs() < 1e-9);
    }

    #[test]
    fn a_velocity_toward_a_near_wall_is_cut_to_what_can_stop_short_of_it() {
        let g = wall_east(4.0);
        let keep = KeepClear::default();
        let close = |v: [f64; 2], to: [f64; 2]| (v[0] - to[0]).hypot(v[1] - to[1]) < 0.03;
        // 0.5 m from the wall's face, head-on at 0.8 m/s: 1.5 × (0.5 − 0.25) = 0.375 m/s, as
        // the wall brake allows.
        let v = limit_approach(&g, [1.5, 2.0], [0.8, 0.0], &keep);
        assert!(close(v, [0.375, 0.0]), "{v:?}");
        // At 45° toward it: 0.354 m to run before 0.25 m off it, so 0.53 m/s, the same 0.375 m/s
        // toward it, in the same direction.
        let d = std::f64::consts::FRAC_1_SQRT_2;
        let v = limit_approach(&g, [1.5, 2.0], [0.8 * d, 0.8 * d], &keep);
        assert!(close(v, [0.375, 0.375]), "{v:?}");
        // Along it, even nearer than it may approach; away from it; slow enough; far from it;
        // nothing to limit: as asked.
        for (p, want) in [
            ([1.8, 2.0], [0.0, 0.8]),
            ([1.5, 2.0], [-0.8, 0.2]),
            ([1.8, 2.0], [-0.3, 0.5]),
            ([1.5, 2.0], [0.3, 0.0]),
            ([0.5, 2.0], [0.8, 0.0]),
            ([1.5, 2.0], [0.0, 0.0]),
        ] {
            assert_eq!(limit_approach(&g, p, want, &keep), want, "{p:?}, {want:?}");
        }
        // Nearer than it may approach, toward it: stopped.
        let v = limit_approach(&g, [1.8, 2.0], [0.5, 0.3], &keep);
        assert!(v[0].hypot(v[1]) < 1e-9, "{v:?}");
        let nan = limit_approach(&g, [1.8, 2.0], [f64::NAN, 0.0], &keep);
        assert!(nan[0].is_nan());
    }

    #[test]
    fn past_the_end_of_a_wall_the_run_is_free() {
        // The wall ends at y = 2.0; flying north 0.3 m west of it, from beside it to past it.
        let g = wall_east(2.0);
        assert_eq!(free_run(&g, [1.7, 1.0], [0.0, 1.0], 2.0, 0.25), 2.0);
        // Flying east just past its end: nothing ahead either.
        assert_eq!(free_run(&g, [1.0, 2.3], [1.0, 0.0], 2.0, 0.25), 2.0);
        // Flying east toward it, 1 m from it: 0.75 m, to a step.
        let run = free_run(&g, [1.0, 1.0], [1.0, 0.0], 2.0, 0.25);
        assert!((run - 0.75).abs() <= 0.025 + 1e-9, "{run}");
        // Off the map's west edge, nothing is known, however far it looks.
        assert_eq!(free_run(&g, [0.5, 1.0], [-1.0, 0.0], 1e12, 0.25), 1e12);
    }

    #[test]
    fn in_a_corner_a_velocity_is_cut_toward_both_walls() {
        // The wall along x = 2.0 up to y = 2.0, and one along y = 2.0–2.05 west of it.
        let mut g = wall_east(2.05);
        for x in 0..40 {
            g.set((x, 40), Cell::Occupied);
        }
        let keep = KeepClear::default();
        // 0.3 m from either wall, flying into the corner: 0.07 m before 0.25 m off both, so
        // about 0.1 m/s.
        let v = limit_approach(&g, [1.7, 1.7], [0.6, 0.6], &keep);
        assert!(
            v[0].hypot(v[1]) < 0.11 && (v[0] - v[1]).abs() < 1e-9,
            "{v:?}"
        );
    }

    #[test]
    fn a_drone_drifting_into_a_jamb_through_a_door_is_braked_toward_the_middle() {
        // The drone crosses the door 0.2 m off its middle, drifting toward the near jamb (+y)
        // as it goes.
        let g = wall_with_a_door();
        let keep = KeepClear::default();
        let b = brake_toward_walls(&g, [2.02, 2.2], [0.5, 0.3], &keep);
        assert!(b[1] < -0.05, "{b:?}");
        // Nothing slows it along its way through.
        assert!(b[0].abs() < 1e-9, "{b:?}");
    }

    #[test]
    fn a_pose_inside_a_wall_is_led_out_of_it() {
        let g = wall_east(4.0);
        // 1 cm into the wall's 5 cm: out on the near side, to the clearance.
        let s = keep_clear(&g, [2.01, 2.0], [2.01, 2.0], &clearance(0.35));
        assert!(s[0] < 2.0 - 0.3, "{s:?}");
    }
}
