//! The local planners (10 Hz). [`LocalPlanner`] is thesis Algorithm 7 as written for a drone
//! without position hold: turn toward the current waypoint, then fly forward; next waypoint within
//! 0.5 m; no valid pose → no commands. [`PathFollower`] is the same idea for a drone under position
//! control: turn first, then pursue a carrot along the path.
//!
//! The thesis's pseudo-code tests `distance < 0.5 m` the wrong way round (it would fly only when
//! already there); this follows its text: a waypoint is reached within 0.5 m.

/// A robot's pose in the map frame: metres and radians (yaw counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose2 {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// Heading, radians, counter-clockwise from +x.
    pub yaw: f64,
}

/// Local planner settings.
#[derive(Debug, Clone)]
pub struct LocalConfig {
    /// Turn on the spot while the bearing error is larger than this, radians (thesis: 10°).
    pub turn_threshold_rad: f64,
    /// A waypoint is reached within this distance, metres (thesis: 0.5 m).
    pub reach_m: f64,
    /// Forward stick while flying toward a waypoint, 0–1.
    pub forward: f64,
}

impl Default for LocalConfig {
    fn default() -> Self {
        Self {
            turn_threshold_rad: 10f64.to_radians(),
            reach_m: 0.5,
            forward: 0.3,
        }
    }
}

/// What the local planner asks of the controllers this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LocalCommand {
    /// No valid pose, or nothing to do: zero pitch and yaw commands (hover).
    Hover,
    /// Turn to this heading with zero pitch.
    Turn {
        /// Heading to turn to, radians.
        yaw: f64,
    },
    /// Hold this heading and pitch forward.
    Forward {
        /// Heading to hold, radians.
        yaw: f64,
        /// Forward stick, 0–1.
        pitch: f64,
    },
    /// The last waypoint has been reached.
    Arrived,
}

/// Follows a list of waypoints.
#[derive(Debug, Clone, Default)]
pub struct LocalPlanner {
    config: LocalConfig,
    waypoints: Vec<[f64; 2]>,
    next: usize,
}

/// The angle wrapped into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let mut a = a.rem_euclid(std::f64::consts::TAU);
    if a > std::f64::consts::PI {
        a -= std::f64::consts::TAU;
    }
    a
}

impl LocalPlanner {
    /// A planner with no waypoints.
    pub fn new(config: LocalConfig) -> Self {
        Self {
            config,
            waypoints: vec![],
            next: 0,
        }
    }

    /// New waypoints from the global planner: start again from the first.
    pub fn set_path(&mut self, waypoints: Vec<[f64; 2]>) {
        self.waypoints = waypoints;
        self.next = 0;
    }

    /// Index of the waypoint being flown to.
    pub fn current(&self) -> Option<usize> {
        (self.next < self.waypoints.len()).then_some(self.next)
    }

    /// One tick with the latest pose (`None`: invalid).
    pub fn step(&mut self, pose: Option<Pose2>) -> LocalCommand {
        let Some(pose) = pose.filter(|p| p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite())
        else {
            return LocalCommand::Hover;
        };
        if self.waypoints.is_empty() {
            return LocalCommand::Hover;
        }
        while let Some(w) = self.waypoints.get(self.next) {
            let (dx, dy) = (w[0] - pose.x, w[1] - pose.y);
            if dx.hypot(dy) >= self.config.reach_m {
                let bearing = dy.atan2(dx);
                return if wrap_angle(bearing - pose.yaw).abs() > self.config.turn_threshold_rad {
                    LocalCommand::Turn { yaw: bearing }
                } else {
                    LocalCommand::Forward {
                        yaw: bearing,
                        pitch: self.config.forward,
                    }
                };
            }
            self.next += 1;
        }
        LocalCommand::Arrived
    }
}

/// Path follower settings.
#[derive(Debug, Clone)]
pub struct FollowerConfig {
    /// The carrot lies this far ahead along the path, metres…
    pub lookahead_m: f64,
    /// …but at most this far round the next corner of the path, so the drone does not cut it.
    pub corner_m: f64,
    /// Turn on the spot while the bearing to the carrot is off by more than this, radians.
    pub turn_threshold_rad: f64,
    /// Having turned, fly again once the bearing is within this, radians.
    pub resume_threshold_rad: f64,
    /// The path's end is reached within this distance, metres.
    pub reach_m: f64,
    /// A bend of the path sharper than this is slowed for, radians…
    pub bend_rad: f64,
    /// …to this speed at the bend, m/s…
    pub bend_speed_mps: f64,
    /// …and this many m/s more per metre before it (how fast the drone may brake, 1/s).
    pub bend_slow_per_s: f64,
    /// Nowhere faster than this, m/s (infinite: no limit but the bends').
    pub max_speed_mps: f64,
    /// Flying, the camera faces the path this far ahead (metres along it, round its bends),
    /// though never more than [`FollowerConfig::resume_threshold_rad`] off the carrot's
    /// bearing: it turns into a bend before the drone reaches it, instead of facing whatever
    /// wall lies beyond the bend. 0: it faces the carrot.
    pub view_m: f64,
}

impl Default for FollowerConfig {
    fn default() -> Self {
        Self {
            lookahead_m: 0.6,
            corner_m: 0.15,
            turn_threshold_rad: 30f64.to_radians(),
            resume_threshold_rad: 10f64.to_radians(),
            reach_m: 0.3,
            // Into a door off a corridor at 0.3 m/s; 0.8 m/s half a metre before it.
            bend_rad: 45f64.to_radians(),
            bend_speed_mps: 0.3,
            bend_slow_per_s: 1.0,
            // Indoors, with a camera that maps 4 m ahead. Pursuing its carrot down a corridor
            // the simulated drone reached 1.1 m/s, too fast to brake for a door's bend.
            max_speed_mps: 0.7,
            view_m: 0.0,
        }
    }
}

/// What the path follower asks of the position controller this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Follow {
    /// No valid pose or no path: hold position.
    Hover,
    /// Hold `at` (the nearest point of the path) and turn to `yaw`.
    Turn {
        /// Where to hold, map frame.
        at: [f64; 2],
        /// Heading to turn to, radians.
        yaw: f64,
    },
    /// Fly to the carrot, facing `yaw` (the camera looks where the drone goes: the carrot, or
    /// the path further ahead, [`FollowerConfig::view_m`]), at most at `speed_mps`.
    Track {
        /// Position setpoint, map frame.
        carrot: [f64; 2],
        /// Heading, radians.
        yaw: f64,
        /// The speed the drone may fly here, to take the next sharp bend without overshooting
        /// it and at most [`FollowerConfig::max_speed_mps`], m/s (infinite: no limit).
        speed_mps: f64,
    },
    /// The end of the path has been reached.
    Arrived,
}

/// Algorithm 7 for a drone with position control: turn first when the path bends away, then
/// pursue a carrot a fixed distance ahead along the path (pure pursuit), so the drone stays on
/// the path the global planner made clear of obstacles instead of cutting its corners.
#[derive(Debug, Clone, Default)]
pub struct PathFollower {
    config: FollowerConfig,
    path: Vec<[f64; 2]>,
    segment: usize,
    turning: bool,
}

impl PathFollower {
    /// A follower with no path.
    pub fn new(config: FollowerConfig) -> Self {
        Self {
            config,
            path: vec![],
            segment: 0,
            turning: false,
        }
    }

    /// A new path: start again from its first segment.
    pub fn set_path(&mut self, path: Vec<[f64; 2]>) {
        self.path = path;
        self.segment = 0;
    }

    /// The path being followed.
    pub fn path(&self) -> &[[f64; 2]] {
        &self.path
    }

    /// One tick with the latest pose (`None`: invalid).
    pub fn step(&mut self, pose: Option<Pose2>) -> Follow {
        let Some(pose) = pose.filter(|p| p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite())
        else {
            return Follow::Hover;
        };
        let p = [pose.x, pose.y];
        let (Some(&first), Some(&end)) = (self.path.first(), self.path.last()) else {
            return Follow::Hover;
        };
        if dist(p, end) < self.config.reach_m {
            return Follow::Arrived;
        }
        if self.path.len() == 1 {
            return self.aim(pose, first, first, None, self.config.max_speed_mps);
        }
        // Progress: the nearest point on the segments from the current one on (never backwards).
        let (mut best, mut best_d, mut best_t) = (self.segment, f64::INFINITY, 0.0);
        for k in self.segment..self.path.len() - 1 {
            let (t, q) = project(p, self.path[k], self.path[k + 1]);
            let d = dist(p, q);
            if d < best_d - 1e-9 {
                (best, best_d, best_t) = (k, d, t);
            }
        }
        self.segment = best;
        let (a, b) = (self.path[best], self.path[best + 1]);
        let nearest = [a[0] + best_t * (b[0] - a[0]), a[1] + best_t * (b[1] - a[1])];
        let carrot = self.along(best, nearest, self.config.lookahead_m, self.config.corner_m);
        let speed = self.next_bend(best, nearest).map_or(f64::INFINITY, |d| {
            self.config.bend_speed_mps + self.config.bend_slow_per_s * d
        });
        let speed = speed.min(self.config.max_speed_mps);
        let view = (self.config.view_m > 0.0)
            .then(|| self.along(best, nearest, self.config.view_m, f64::INFINITY));
        self.aim(pose, nearest, carrot, view, speed)
    }

    /// The point `length` metres along the path from `from` (on segment `segment`), but at
    /// most `corner` metres round the first corner after `from`; the path's end if it is
    /// shorter.
    fn along(&self, segment: usize, from: [f64; 2], length: f64, corner: f64) -> [f64; 2] {
        let mut left = length;
        let mut from = from;
        for k in segment..self.path.len() - 1 {
            let to = self.path[k + 1];
            let len = dist(from, to);
            if len >= left {
                let f = left / len.max(1e-12);
                return [
                    from[0] + f * (to[0] - from[0]),
                    from[1] + f * (to[1] - from[1]),
                ];
            }
            left = (left - len).min(corner);
            from = to;
        }
        self.path.last().copied().unwrap_or(from)
    }

    /// How far along the path from `nearest` (on segment `segment`) its next bend sharper than
    /// [`FollowerConfig::bend_rad`] lies, metres; `None` when it bends no more than that.
    fn next_bend(&self, segment: usize, nearest: [f64; 2]) -> Option<f64> {
        let mut along = 0.0;
        let mut from = nearest;
        for k in segment + 1..self.path.len().saturating_sub(1) {
            let (a, b, c) = (self.path[k - 1], self.path[k], self.path[k + 1]);
            along += dist(from, b);
            from = b;
            if b == a || b == c {
                continue;
            }
            let bend =
                wrap_angle((c[1] - b[1]).atan2(c[0] - b[0]) - (b[1] - a[1]).atan2(b[0] - a[0]));
            if bend.abs() > self.config.bend_rad {
                return Some(along);
            }
        }
        None
    }

    /// Turn to the carrot, or fly to it facing `view` (the path further ahead, if one is
    /// watched: [`FollowerConfig::view_m`]).
    fn aim(
        &mut self,
        pose: Pose2,
        nearest: [f64; 2],
        carrot: [f64; 2],
        view: Option<[f64; 2]>,
        speed_mps: f64,
    ) -> Follow {
        let bearing = |to: [f64; 2]| (to[1] - pose.y).atan2(to[0] - pose.x);
        let yaw = bearing(carrot);
        let error = wrap_angle(yaw - pose.yaw).abs();
        self.turning = if self.turning {
            error > self.config.resume_threshold_rad
        } else {
            error > self.config.turn_threshold_rad
        };
        if self.turning {
            return Follow::Turn { at: nearest, yaw };
        }
        // A view point nearer than the carrot (the path's end) has no bearing worth facing.
        let facing = match view {
            Some(v) if dist([pose.x, pose.y], v) > self.config.lookahead_m => {
                let off = self.config.resume_threshold_rad;
                wrap_angle(yaw + wrap_angle(bearing(v) - yaw).clamp(-off, off))
            }
            _ => yaw,
        };
        Follow::Track {
            carrot,
            yaw: facing,
            speed_mps,
        }
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The nearest point to `p` on segment `a`–`b`, and its parameter in [0, 1].
fn project(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> (f64, [f64; 2]) {
    let (vx, vy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = vx * vx + vy * vy;
    let t = if len2 < 1e-18 {
        0.0
    } else {
        (((p[0] - a[0]) * vx + (p[1] - a[1]) * vy) / len2).clamp(0.0, 1.0)
    };
    (t, [a[0] + t * vx, a[1] + t * vy])
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    #[test]
    fn turns_first_then_flies_then_advances() {
        let mut lp = LocalPlanner::new(LocalConfig::default());
        lp.set_path(vec![[0.0, 0.0], [0.0, 5.0], [5.0, 5.0]]);
        // At the first waypoint facing +x: it is reached at once; the next is straight left (+y).
        match lp.step(Some(Pose2 {
            x: 0.0,
            y: 0.1,
            yaw: 0.0,
        })) {
            LocalCommand::Turn { yaw } => assert!((yaw - FRAC_PI_2).abs() < 0.03),
            c => panic!("{c:?}"),
        }
        assert_eq!(lp.current(), Some(1));
        // Within 10° of the bearing: fly.
        let c = lp.step(Some(Pose2 {
            x: 0.0,
            y: 1.0,
            yaw: FRAC_PI_2 - 0.1,
        }));
        assert!(
            matches!(c, LocalCommand::Forward { pitch, .. } if pitch > 0.0),
            "{c:?}"
        );
        // Within 0.5 m of (0, 5): next waypoint (5, 5) is to the right (bearing 0).
        let c = lp.step(Some(Pose2 {
            x: 0.0,
            y: 4.6,
            yaw: FRAC_PI_2,
        }));
        assert!(
            matches!(c, LocalCommand::Turn { yaw } if yaw.abs() < 0.1),
            "{c:?}"
        );
        assert_eq!(
            lp.step(Some(Pose2 {
                x: 4.8,
                y: 5.0,
                yaw: 0.0
            })),
            LocalCommand::Arrived
        );
    }

    #[test]
    fn invalid_pose_gives_zero_commands_and_new_paths_restart() {
        let mut lp = LocalPlanner::new(LocalConfig::default());
        lp.set_path(vec![[3.0, 0.0]]);
        assert_eq!(lp.step(None), LocalCommand::Hover);
        assert_eq!(
            lp.step(Some(Pose2 {
                x: f64::NAN,
                y: 0.0,
                yaw: 0.0
            })),
            LocalCommand::Hover
        );
        assert!(matches!(
            lp.step(Some(Pose2 {
                x: 0.0,
                y: 0.0,
                yaw: 0.0
            })),
            LocalCommand::Forward { .. }
        ));
        lp.set_path(vec![[0.0, -3.0]]);
        assert_eq!(lp.current(), Some(0));
        assert!(matches!(
            lp.step(Some(Pose2 {
                x: 0.0,
                y: 0.0,
                yaw: 0.0
            })),
            LocalCommand::Turn { .. }
        ));
        lp.set_path(vec![]);
        assert_eq!(
            lp.step(Some(Pose2 {
                x: 0.0,
                y: 0.0,
                yaw: 0.0
            })),
            LocalCommand::Hover
        );
    }

    fn pose(x: f64, y: f64, yaw: f64) -> Option<Pose2> {
        Some(Pose2 { x, y, yaw })
    }

    #[test]
    fn the_follower_turns_first_then_pursues_a_carrot_on_the_path() {
        let mut f = PathFollower::new(FollowerConfig::default());
        f.set_path(vec![[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]);
        // Facing +y at the start: the path goes +x, so turn first, holding the path's nearest point.
        match f.step(pose(0.0, 0.1, FRAC_PI_2)) {
            Follow::Turn { at, yaw } => {
                // Toward the carrot (0.6, 0) from (0, 0.1).
                assert!(
                    (yaw - (-0.1f64).atan2(0.6)).abs() < 1e-9
                        && at[0].abs() < 1e-9
                        && at[1].abs() < 1e-9,
                    "{at:?} {yaw}"
                );
            }
            c => panic!("{c:?}"),
        }
        // Still 20° off: keep turning (hysteresis), then within 10° fly.
        assert!(matches!(f.step(pose(0.0, 0.0, 0.35)), Follow::Turn { .. }));
        match f.step(pose(1.0, 0.05, 0.0)) {
            Follow::Track { carrot, .. } => {
                // 0.6 m ahead of the nearest point (1, 0), on the path — not toward (4, 0) from
                // the drone, which would keep its 5 cm error.
                assert!(
                    (carrot[0] - 1.6).abs() < 1e-9 && carrot[1].abs() < 1e-9,
                    "{carrot:?}"
                );
            }
            c => panic!("{c:?}"),
        }
        // Near the corner the carrot goes round it (at most 0.15 m): turn toward it, then track it.
        assert!(
            matches!(f.step(pose(3.8, 0.0, 0.0)), Follow::Turn { yaw, .. } if (yaw - 0.15f64.atan2(0.2)).abs() < 1e-9)
        );
        match f.step(pose(3.8, 0.0, 0.15f64.atan2(0.2))) {
            Follow::Track { carrot, .. } => assert!(
                (carrot[0] - 4.0).abs() < 1e-9 && (carrot[1] - 0.15).abs() < 1e-9,
                "{carrot:?}"
            ),
            c => panic!("{c:?}"),
        }
        // Progress never goes back to the first segment.
        f.step(pose(4.0, 1.0, FRAC_PI_2));
        match f.step(pose(3.0, 0.0, FRAC_PI_2)) {
            Follow::Turn { at, .. } | Follow::Track { carrot: at, .. } => {
                assert!(at[0] >= 3.99, "{at:?}")
            }
            c => panic!("{c:?}"),
        }
        assert_eq!(f.step(pose(4.0, 3.8, FRAC_PI_2)), Follow::Arrived);
    }

    /// The heading the follower with `config` flies at `at`, facing +x, on `path`.
    fn facing_at(config: &FollowerConfig, path: &[[f64; 2]], at: [f64; 2]) -> f64 {
        track_at(config.clone(), path.to_vec(), at).0
    }

    #[test]
    fn the_camera_turns_into_a_bend_before_the_drone_reaches_it() {
        // Bends of up to 90° flown while turning (as the station flies them).
        let carrot_only = FollowerConfig {
            turn_threshold_rad: FRAC_PI_2,
            resume_threshold_rad: PI / 3.0,
            ..FollowerConfig::default()
        };
        let ahead = FollowerConfig {
            view_m: 1.0,
            ..carrot_only.clone()
        };
        let corner = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]];
        // Far from the bend both face along the path.
        for c in [&carrot_only, &ahead] {
            assert!(facing_at(c, &corner, [1.0, 0.0]).abs() < 1e-9);
        }
        // Half a metre before it the carrot is 0.1 m round the corner, at (4, 0.1): facing the
        // carrot, the camera looks past the bend (at the wall beyond it, in a corridor)…
        let carrot = facing_at(&carrot_only, &corner, [3.5, 0.0]);
        assert!((carrot - 0.1f64.atan2(0.5)).abs() < 1e-9, "{carrot}");
        // …facing the path 1 m ahead, (4, 0.5), it looks half way into the bend.
        let view = facing_at(&ahead, &corner, [3.5, 0.0]);
        assert!((view - FRAC_PI_4).abs() < 1e-9, "{view}");
        // Never more than the resume threshold off the carrot (the drone would stop and turn):
        // round a bend of 108° the path 2 m ahead lies at 89° from (3.5, 0).
        let back = [[0.0, 0.0], [4.0, 0.0], [3.0, 3.0]];
        let far = FollowerConfig {
            view_m: 2.0,
            ..carrot_only.clone()
        };
        let carrot = facing_at(&carrot_only, &back, [3.5, 0.0]);
        let view = facing_at(&far, &back, [3.5, 0.0]);
        assert!(
            (view - carrot - far.resume_threshold_rad).abs() < 1e-9,
            "{view} {carrot}"
        );
        // Where the path ends within the carrot's reach, the carrot is faced.
        let short = [[0.0, 0.0], [0.3, 0.3]];
        let end = facing_at(&ahead, &short, [0.0, 0.0]);
        assert!((end - FRAC_PI_4).abs() < 1e-9, "{end}");
    }

    /// The heading and speed limit the follower with `config` flies at `at`, facing +x, on
    /// `path`.
    fn track_at(config: FollowerConfig, path: Vec<[f64; 2]>, at: [f64; 2]) -> (f64, f64) {
        let mut f = PathFollower::new(config);
        f.set_path(path);
        match f.step(pose(at[0], at[1], 0.0)) {
            Follow::Track { yaw, speed_mps, .. } => (yaw, speed_mps),
            c => panic!("{c:?}"),
        }
    }

    /// The speed limit the follower with `config` sets at `at` facing +x on `path`.
    fn speed_at(config: FollowerConfig, path: Vec<[f64; 2]>, at: [f64; 2]) -> f64 {
        track_at(config, path, at).1
    }

    #[test]
    fn the_follower_slows_for_a_sharp_bend_by_how_near_it_is() {
        let c = FollowerConfig {
            max_speed_mps: f64::INFINITY,
            ..FollowerConfig::default()
        };
        let speed_at = |path, at| speed_at(c.clone(), path, at);
        let corner = vec![[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]];
        for x in [1.0, 3.0, 3.5] {
            let expected = c.bend_speed_mps + c.bend_slow_per_s * (4.0 - x);
            let speed = speed_at(corner.clone(), [x, 0.0]);
            assert!(
                (speed - expected).abs() < 1e-9,
                "at {x}: {speed}, not {expected}"
            );
        }
        // A gentle bend (27°) is flown at speed; the sharp one after it (63°) counts from here.
        let gentle_then_sharp = vec![[0.0, 0.0], [2.0, 0.0], [4.0, 1.0], [4.0, 4.0]];
        let expected = c.bend_speed_mps + c.bend_slow_per_s * (1.0 + 5f64.sqrt());
        let speed = speed_at(gentle_then_sharp, [1.0, 0.0]);
        assert!((speed - expected).abs() < 1e-9, "{speed}, not {expected}");
        // No bend, or only gentle ones (a repeated point is none): no limit.
        assert_eq!(
            speed_at(vec![[0.0, 0.0], [4.0, 0.0]], [1.0, 0.0]),
            f64::INFINITY
        );
        assert_eq!(
            speed_at(
                vec![[0.0, 0.0], [2.0, 0.0], [2.0, 0.0], [4.0, 1.0]],
                [1.0, 0.0]
            ),
            f64::INFINITY
        );
    }

    #[test]
    fn the_follower_never_asks_for_more_than_its_top_speed() {
        let c = FollowerConfig::default();
        let top = c.max_speed_mps;
        assert!(top.is_finite() && top > c.bend_speed_mps);
        // A straight path, a far bend, a single point: the top speed; near a bend, the bend's.
        let corner = vec![[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]];
        assert_eq!(
            speed_at(c.clone(), vec![[0.0, 0.0], [4.0, 0.0]], [1.0, 0.0]),
            top
        );
        assert_eq!(speed_at(c.clone(), corner.clone(), [1.0, 0.0]), top);
        assert_eq!(speed_at(c.clone(), vec![[2.0, 0.0]], [0.0, 0.0]), top);
        let near = speed_at(c.clone(), corner, [3.7, 0.0]);
        assert!(
            (near - (c.bend_speed_mps + 0.3 * c.bend_slow_per_s)).abs() < 1e-9,
            "{near}"
        );
    }

    #[test]
    fn the_follower_hovers_without_pose_or_path() {
        let mut f = PathFollower::new(FollowerConfig::default());
        assert_eq!(f.step(pose(0.0, 0.0, 0.0)), Follow::Hover);
        f.set_path(vec![[1.0, 0.0]]);
        assert_eq!(f.step(None), Follow::Hover);
        assert_eq!(f.step(pose(f64::NAN, 0.0, 0.0)), Follow::Hover);
        assert!(matches!(f.step(pose(0.0, 0.0, 0.0)), Follow::Track { .. }));
        assert_eq!(f.step(pose(0.9, 0.0, 0.0)), Follow::Arrived);
    }

    #[test]
    fn angles_wrap_across_the_thesis_imu_jump() {
        // The thesis's IMU jumps from −179.9° to 179.9°: the error between them is 0.2°, not 359.8°.
        let e = wrap_angle((-179.9f64).to_radians() - 179.9f64.to_radians());
        assert!((e.to_degrees() - 0.2).abs() < 1e-9, "{}", e.to_degrees());
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
    }
}
