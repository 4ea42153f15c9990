//! The local planner (thesis Algorithm 7, 10 Hz): turn toward the current waypoint, then fly
//! forward; next waypoint within 0.5 m; no valid pose → no commands.
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

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

    #[test]
    fn angles_wrap_across_the_thesis_imu_jump() {
        // The thesis's IMU jumps from −179.9° to 179.9°: the error between them is 0.2°, not 359.8°.
        let e = wrap_angle((-179.9f64).to_radians() - 179.9f64.to_radians());
        assert!((e.to_degrees() - 0.2).abs() < 1e-9, "{}", e.to_degrees());
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
    }
}
