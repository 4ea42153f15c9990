//! The SLAM on sequences rendered by the simulator, with its ground truth to compare against:
//! drones flown through the built-in apartment (turning on the spot, flying routes that close
//! loops, two drones that start apart and must end in one map), and a camera moved along the
//! real TUM fr1/xyz motion-capture trajectory.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use link::Sticks;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use nav::grid::Cell;
use sitl::{Camera, Sim, SimConfig, World};
use slam::dataset::Pinhole;
use slam::eval::{Alignment, ate};
use slam::system::{Frame, RobotSetup, Slam, SlamConfig, Tracking};
use slam::trajectory::{Stamped, read_tum};

/// A waypoint for the test pilot: x, y, z (metres), yaw (radians).
type Waypoint = [f64; 4];

/// Flies the simulated vehicles along waypoint lists with a ground-truth pilot (the test's, not
/// the station's), feeding every camera frame (10 Hz) to the SLAM with the vehicle's IMU heading
/// and sonar height. Returns the SLAM, the true camera trajectories and the lost-frame counts.
struct Flight {
    sim: Sim,
    slam: Slam,
    truth: Vec<Vec<Stamped>>,
    lost: Vec<usize>,
    frames: Vec<usize>,
    /// Frames reported [`Tracking::Weak`] (a pose not to fly on) and [`Tracking::Tracked`].
    weak: Vec<usize>,
    tracked: Vec<usize>,
    /// Of the weak frames, those that came with visual odometry, and the largest error of its
    /// displacement against the true motion of the body, metres.
    weak_odometry: Vec<usize>,
    weak_odometry_error_m: f64,
    /// Give every frame the true body pose as the vehicle's prediction, this far (metres) off
    /// in height; `None`: no prediction (a hand-held camera).
    predicted_height_error: Option<f64>,
    /// … this far off along the map's x axis, metres…
    predicted_x_error: f64,
    /// … plus this much per second of flight (a filter that believes in a motion that is
    /// not there), m/s…
    predicted_x_drift_mps: f64,
    /// … and known to this standard deviation, metres (`None`: not said).
    predicted_sigma: Option<f64>,
    /// Why frames were lost.
    lost_why: Vec<String>,
    /// Give every frame its true camera pose (mapping with known poses).
    known_poses: bool,
    /// Added to every IMU heading, radians (an IMU that disagrees with the camera); `None`:
    /// no heading at all (turning too fast for it to be trusted).
    heading_bias: Option<f64>,
    /// The heading is read while steady (not lagging the camera): a prior on the map.
    heading_steady: bool,
    /// The camera sees nothing (covered, or facing a bare wall too close): no colour, no depth.
    blind: bool,
    /// The depth camera reads nothing while the colour camera sees (every wall beyond its
    /// range).
    no_depth: bool,
    /// Added to the IMU's roll, radians (`None`: no roll and pitch given).
    roll_bias: Option<f64>,
}

fn body_from_camera() -> Isometry3<f64> {
    sitl::Vehicle::new(sitl::VehicleParams::default(), 0.0, 0.0, 0.0).map_from_camera()
}

impl Flight {
    fn new(drones: usize, known_start: &[bool], config: SlamConfig) -> Self {
        let world = Arc::new(World::load("apartment").expect("built-in world"));
        let mut sim = Sim::new(
            world,
            drones,
            SimConfig {
                camera: Some(Camera::kinect(320, 240)),
                camera_hz: 10.0,
                ..SimConfig::default()
            },
        )
        .expect("sim");
        let setups = (0..drones)
            .map(|k| {
                let s = sim.vehicle(k).state();
                RobotSetup {
                    body_from_camera: body_from_camera(),
                    start: known_start[k].then(|| {
                        Isometry3::new(
                            Vector3::new(s.position[0], s.position[1], 0.0),
                            Vector3::z() * s.yaw,
                        )
                    }),
                }
            })
            .collect();
        for k in 0..drones {
            sim.vehicle_mut(k).set_armed(true);
        }
        Self {
            sim,
            slam: Slam::new(config, setups),
            truth: vec![vec![]; drones],
            lost: vec![0; drones],
            frames: vec![0; drones],
            weak: vec![0; drones],
            tracked: vec![0; drones],
            weak_odometry: vec![0; drones],
            weak_odometry_error_m: 0.0,
            predicted_height_error: None,
            predicted_x_error: 0.0,
            predicted_x_drift_mps: 0.0,
            predicted_sigma: None,
            lost_why: vec![],
            known_poses: false,
            heading_bias: Some(0.0),
            heading_steady: true,
            blind: false,
            no_depth: false,
            roll_bias: Some(0.0),
        }
    }

    /// Flies every drone through its waypoints (reached within 0.15 m and 5°, then the next).
    fn fly(&mut self, routes: &[Vec<Waypoint>], max_seconds: f64) {
        let n = routes.len();
        let mut next = vec![0usize; n];
        let steps = (max_seconds * 100.0) as usize;
        for _ in 0..steps {
            if (0..n).all(|k| next[k] >= routes[k].len()) {
                break;
            }
            for (k, route) in routes.iter().enumerate() {
                let goal = route.get(next[k]).copied().unwrap_or_else(|| {
                    let s = self.sim.vehicle(k).state();
                    [s.position[0], s.position[1], s.position[2], s.yaw]
                });
                let (sticks, reached) = pilot(self.sim.vehicle(k).state(), goal);
                if reached {
                    next[k] += 1;
                }
                self.sim.vehicle_mut(k).set_sticks(sticks);
            }
            self.sim.step(Duration::from_millis(10));
            self.frames_due();
        }
    }

    /// Holds every drone at its waypoint for `seconds`.
    fn hold(&mut self, goals: &[Waypoint], seconds: f64) {
        for _ in 0..(seconds * 100.0) as usize {
            for (k, &goal) in goals.iter().enumerate() {
                let (sticks, _) = pilot(self.sim.vehicle(k).state(), goal);
                self.sim.vehicle_mut(k).set_sticks(sticks);
            }
            self.sim.step(Duration::from_millis(10));
            self.frames_due();
        }
    }

    fn frames_due(&mut self) {
        let due = self.sim.due_cameras();
        for f in self.sim.render(&due) {
            let k = usize::from(f.frame.vehicle);
            let readings = self.sim.sense(k).expect("vehicle");
            let rgb = image::RgbImage::from_raw(f.frame.width, f.frame.height, f.frame.rgb.clone())
                .expect("rgb");
            let grey = if self.blind {
                image::GrayImage::new(f.frame.width, f.frame.height)
            } else {
                image::DynamicImage::ImageRgb8(rgb).into_luma8()
            };
            let i = f.frame.intrinsics;
            let t = f.frame.stamp.as_secs_f64();
            let report = self
                .slam
                .process(Frame {
                    robot: k,
                    stamp: t,
                    grey,
                    depth: if self.blind || self.no_depth {
                        vec![0; f.frame.depth_mm.len()]
                    } else {
                        f.frame.depth_mm.clone()
                    },
                    depth_scale: 0.001,
                    camera: Pinhole {
                        fx: i.fx.into(),
                        fy: i.fy.into(),
                        cx: i.cx.into(),
                        cy: i.cy.into(),
                    },
                    heading: self.heading_bias.map(|b| readings.yaw + b),
                    heading_steady: self.heading_steady,
                    turning_heading: None,
                    height: readings.sonar,
                    tilt: self.roll_bias.map(|b| {
                        let s = self.sim.vehicle(k).state();
                        [s.roll + b, s.pitch]
                    }),
                    predicted_body: self.predicted_height_error.map(|dz| {
                        let s = self.sim.vehicle(k).state();
                        Isometry3::new(
                            Vector3::new(
                                s.position[0]
                                    + self.predicted_x_error
                                    + self.predicted_x_drift_mps * t,
                                s.position[1],
                                s.position[2] + dz,
                            ),
                            Vector3::z() * s.yaw,
                        )
                    }),
                    predicted_sigma_m: self.predicted_sigma,
                    known_camera_pose: self.known_poses.then_some(f.map_from_camera),
                })
                .expect("frame");
            self.frames[k] += 1;
            match &report.tracking {
                Tracking::Lost(why) => {
                    eprintln!("drone {} at {t:.1} s: lost: {why}", k + 1);
                    self.lost[k] += 1;
                    self.lost_why.push(why.clone());
                }
                Tracking::Weak { .. } => {
                    self.weak[k] += 1;
                    if let (Some(o), Some(before)) = (&report.odometry, self.truth[k].last()) {
                        self.weak_odometry[k] += 1;
                        assert!(
                            (o.since - before.t).abs() < 1e-9,
                            "measured since {}",
                            o.since
                        );
                        let body = body_from_camera();
                        let moved =
                            body * before.pose.inverse() * f.map_from_camera * body.inverse();
                        let off = (o.previous_from_body.translation.vector
                            - moved.translation.vector)
                            .norm();
                        self.weak_odometry_error_m = self.weak_odometry_error_m.max(off);
                    }
                }
                Tracking::Tracked { .. } => self.tracked[k] += 1,
                _ => {}
            }
            self.truth[k].push(Stamped {
                t,
                pose: f.map_from_camera,
            });
        }
    }

    /// Mean yaw error of drone `k`'s final trajectory in the map frame (the camera's optical
    /// axis, which points along the body's x), radians.
    fn mean_yaw_error(&self, k: usize) -> f64 {
        let est = self.slam.trajectory(k);
        let yaw = |pose: &Isometry3<f64>| {
            let axis = pose.rotation * Vector3::z();
            axis.y.atan2(axis.x)
        };
        let pairs = slam::eval::associate(&self.truth[k], &est, 1e-3);
        let sum: f64 = pairs
            .iter()
            .map(|&(i, j)| {
                let d = yaw(&est[j].pose) - yaw(&self.truth[k][i].pose);
                (d + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
            })
            .sum();
        sum / pairs.len().max(1) as f64
    }

    /// ATE of drone `k`'s final trajectory: SE(3)-aligned, or in the map frame as it is.
    fn ate(&self, k: usize, alignment: Option<Alignment>) -> f64 {
        let est = self.slam.trajectory(k);
        match alignment {
            Some(a) => ate(&self.truth[k], &est, a, 1e-3).map_or(f64::INFINITY, |e| e.rmse_m),
            None => {
                // No alignment: the map frame must be the world's.
                let pairs = slam::eval::associate(&self.truth[k], &est, 1e-3);
                let sum: f64 = pairs
                    .iter()
                    .map(|&(i, j)| {
                        (self.truth[k][i].pose.translation.vector - est[j].pose.translation.vector)
                            .norm_squared()
                    })
                    .sum();
                (sum / pairs.len().max(1) as f64).sqrt()
            }
        }
    }
}

/// A ground-truth pilot: sticks toward a waypoint, and whether it is reached.
fn pilot(s: &sitl::VehicleState, goal: Waypoint) -> (Sticks, bool) {
    let (dx, dy) = (goal[0] - s.position[0], goal[1] - s.position[1]);
    let (c, sn) = (s.yaw.cos(), s.yaw.sin());
    let (fwd, left) = (c * dx + sn * dy, -sn * dx + c * dy);
    let (vf, vl) = (
        c * s.velocity[0] + sn * s.velocity[1],
        -sn * s.velocity[0] + c * s.velocity[1],
    );
    let yaw_err = (goal[3] - s.yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    // An uncompensated pilot, as these flights were made: the autopilot ignores a stick within
    // 5 % of centre (its dead zone) and holds its position there.
    let clamp = |v: f64, l: f64| {
        let v = f64::from(v.clamp(-l, l) as f32);
        (if v.abs() <= 0.05 {
            0.0
        } else {
            (v - 0.05 * v.signum()) / 0.95
        }) as f32
    };
    let sticks = Sticks {
        pitch: clamp(0.5 * fwd - 0.6 * vf, 0.35),
        roll: clamp(-(0.5 * left - 0.6 * vl), 0.35),
        yaw: clamp(-1.5 * yaw_err, 0.4),
        throttle: clamp(1.5 * (goal[2] - s.position[2]), 0.6),
    };
    let reached = dx.hypot(dy) < 0.15
        && (goal[2] - s.position[2]).abs() < 0.1
        && yaw_err.abs() < 5f64.to_radians();
    (sticks, reached)
}

/// A full turn on the spot at (x, y, z), in 30° steps from `yaw`.
fn turn(x: f64, y: f64, z: f64, yaw: f64) -> Vec<Waypoint> {
    (0..=12)
        .map(|i| [x, y, z, yaw + f64::from(i) * 30f64.to_radians()])
        .collect()
}

fn start_of(f: &Flight, k: usize) -> (f64, f64, f64) {
    let s = f.sim.vehicle(k).state();
    (s.position[0], s.position[1], s.yaw)
}

/// Half a turn on the spot, the camera blind for `blind_s` seconds (tracking lost), then — after
/// `then` has set up how the way back is sensed — the turn back: the frames lost on the way back
/// and how many there were.
fn lost_and_back(f: &mut Flight, blind_s: f64, then: impl FnOnce(&mut Flight)) -> (usize, usize) {
    let (x, y, yaw) = start_of(f, 0);
    let route = turn(x, y, 1.0, yaw);
    f.fly(&[route[..5].to_vec()], 30.0);
    f.blind = true;
    f.hold(&[route[4]], blind_s);
    let (lost_blind, frames_blind) = (f.lost[0], f.frames[0]);
    assert!(lost_blind > 0, "the blind camera loses tracking");
    f.blind = false;
    then(f);
    let back: Vec<Waypoint> = route[..5].iter().rev().copied().collect();
    f.fly(&[back], 30.0);
    (f.lost[0] - lost_blind, f.frames[0] - frames_blind)
}

#[test]
fn a_drone_turning_on_the_spot_is_tracked_and_closes_its_loop() {
    let mut f = Flight::new(1, &[true], SlamConfig::default());
    let (x, y, yaw) = start_of(&f, 0);
    let mut route = vec![[x, y, 1.0, yaw]];
    route.extend(turn(x, y, 1.0, yaw));
    f.fly(&[route], 60.0);
    f.slam.finish();
    let e = f.ate(0, None);
    eprintln!(
        "{} frames, {} lost, ATE {e:.3} m (map frame)",
        f.frames[0], f.lost[0]
    );
    assert!(
        f.lost[0] * 20 <= f.frames[0],
        "{} of {} lost",
        f.lost[0],
        f.frames[0]
    );
    assert!(e < 0.05, "ATE {e:.3} m");
    assert!(f.slam.stats().loop_closures > 0, "the turn closes a loop");
}

#[test]
fn a_loop_closure_that_turns_otherwise_than_the_imu_reads_is_refused() {
    // The turn on the spot above, with an IMU that reads 6° more from half way round: every
    // closure from the end of the turn to its start then turns 6° otherwise than the headings
    // of its keyframes — as a look-alike place matched by mistake does (4–9° in SITL) — and
    // none is taken. Without the check, the same flight closes its loop.
    let run = |gate: Option<f64>| {
        // (Unchecked closures are held to the usual inlier count: only the heading check
        // differs between the two runs.)
        let config = SlamConfig {
            loop_max_heading_disagreement: gate,
            loop_min_inliers_unchecked: SlamConfig::default().loop_min_inliers,
            ..SlamConfig::default()
        };
        let mut f = Flight::new(1, &[true], config);
        let (x, y, yaw) = start_of(&f, 0);
        let route = turn(x, y, 1.0, yaw);
        f.fly(&[route[..7].to_vec()], 30.0);
        f.heading_bias = Some(6f64.to_radians());
        f.fly(&[route[7..].to_vec()], 30.0);
        f.slam.finish();
        f.slam.loop_closures()
    };
    let unchecked = run(None);
    assert!(!unchecked.is_empty(), "the turn closes its loop");
    let checked = run(Some(3f64.to_radians()));
    assert!(checked.is_empty(), "{} closures taken", checked.len());
}

#[test]
fn a_loop_closure_with_no_imu_headings_to_check_it_needs_more_inliers() {
    // The same turn, the IMU's heading missing from half way round (a vehicle turning too fast
    // for it to be trusted): the closures from the end of the turn to its start cannot be
    // checked, so they must be stronger than usual — here impossibly strong, and none is taken.
    let run = |needed: usize| {
        let config = SlamConfig {
            loop_min_inliers_unchecked: needed,
            ..SlamConfig::default()
        };
        let mut f = Flight::new(1, &[true], config);
        let (x, y, yaw) = start_of(&f, 0);
        let route = turn(x, y, 1.0, yaw);
        f.fly(&[route[..7].to_vec()], 30.0);
        f.heading_bias = None;
        f.fly(&[route[7..].to_vec()], 30.0);
        f.slam.finish();
        f.slam.loop_closures()
    };
    assert!(!run(SlamConfig::default().loop_min_inliers).is_empty());
    assert!(run(10_000).is_empty());
}

#[test]
fn only_a_steady_heading_is_a_prior_on_the_map() {
    // The turn on the spot, the IMU reading 5° more than the truth all the way round (as a
    // heading that lags the camera does while the drone turns), inside the prior's gate, and
    // the loop-closure check off: only the priors differ between the two runs. As priors the
    // headings turn the map toward them; marked unsteady they leave it where the camera saw it.
    let run = |steady: bool| {
        let config = SlamConfig {
            loop_max_heading_disagreement: None,
            ..SlamConfig::default()
        };
        let mut f = Flight::new(1, &[true], config);
        f.heading_bias = Some(5f64.to_radians());
        f.heading_steady = steady;
        let (x, y, yaw) = start_of(&f, 0);
        f.fly(&[turn(x, y, 1.0, yaw)], 60.0);
        f.slam.finish();
        f.mean_yaw_error(0).to_degrees()
    };
    let pulled = run(true);
    let free = run(false);
    eprintln!("mean yaw error: {pulled:.2}° with the priors, {free:.2}° without");
    // Measured: 3.1° with the priors, 0.5° without (the camera's own drift over the turn).
    assert!(pulled > 2.0, "{pulled:.2}°: the priors should pull the map");
    assert!(free.abs() < 1.0, "{free:.2}°: nothing should pull the map");
}

#[test]
fn a_vehicle_whose_depth_camera_reads_nothing_is_tracked_on_the_map_by_projection() {
    // Half a turn with depth, then the turn back with the depth camera reading nothing (as
    // with every wall beyond its range) while the colour camera still sees: the map's points,
    // seen with depth on the way out, place the frames on their pixels. Without that the
    // vehicle would be lost for the whole way back.
    let mut f = Flight::new(1, &[true], SlamConfig::default());
    f.predicted_height_error = Some(0.0);
    let (x, y, yaw) = start_of(&f, 0);
    let route = turn(x, y, 1.0, yaw);
    f.fly(&[route[..7].to_vec()], 40.0);
    assert_eq!(f.lost[0], 0, "{:?}", f.lost_why);
    let (keyframes, frames_before, tracked_before) =
        (f.slam.stats().keyframes, f.frames[0], f.tracked[0]);
    f.no_depth = true;
    let back: Vec<Waypoint> = route[..7].iter().rev().copied().collect();
    f.fly(&[back], 40.0);
    let frames = f.frames[0] - frames_before;
    eprintln!(
        "{} of {frames} frames without depth lost: {:?}",
        f.lost[0], f.lost_why
    );
    assert!(frames > 50, "{frames} frames");
    assert!(f.lost[0] * 10 < frames, "{} of {frames} lost", f.lost[0]);
    // Most of them poses to fly on (not weak: away from the motion so far).
    let tracked = f.tracked[0] - tracked_before;
    eprintln!("{tracked} of {frames} tracked");
    assert!(tracked * 10 >= frames * 8, "{tracked} of {frames} tracked");
    let placed = f.slam.estimate(0).map_or(0, |e| e.projection_frames);
    assert!(
        placed + f.lost[0] >= frames,
        "{placed} placed by projection"
    );
    // No keyframe without depth; the way back on the way out's.
    assert_eq!(f.slam.stats().keyframes, keyframes);
    f.slam.finish();
    let error = f.ate(0, None);
    assert!(error < 0.05, "ATE {error:.3} m");
}

#[test]
fn a_vehicle_lost_with_no_prediction_relocalises_only_on_a_strong_match() {
    // Half a turn, the camera blind for a second (tracking lost), then the turn back with no
    // IMU heading and no prediction from the vehicle's filter: nothing can check where a match
    // puts the vehicle, so relocalisation needs `relocalisation_min_inliers_unpredicted` — here
    // impossibly many, and the vehicle stays lost; at the usual count it is found again.
    let run = |needed: usize| {
        let config = SlamConfig {
            relocalisation_min_inliers_unpredicted: needed,
            ..SlamConfig::default()
        };
        let mut f = Flight::new(1, &[true], config);
        lost_and_back(&mut f, 1.0, |f| f.heading_bias = None)
    };
    let (lost, frames) = run(10_000);
    assert_eq!(lost, frames, "relocalised on a match below the bound");
    let (lost, frames) = run(SlamConfig::default().relocalisation_min_inliers);
    assert!(
        lost * 4 < frames,
        "{lost} of {frames} frames lost after the blind second"
    );
}

#[test]
fn a_lost_vehicle_is_relocalised_only_as_far_from_its_prediction_as_the_prediction_is_unsure() {
    // Half a turn, the camera blind for two seconds (tracking lost), then the turn back, the
    // vehicle's filter predicting the body `x_error` metres off along x and saying it is sure
    // to `sigma`. A sure prediction that far off cannot be where a match puts the vehicle, so
    // no match is taken (in SITL a wrong one, 0.7 m along a bare wall, was taken 0.3 s after a
    // drone was lost, and it flew on it into the wall); an unsure one can, and the match is
    // where the vehicle is, not where the prediction said.
    let run = |x_error: f64, sigma: f64| {
        let mut f = Flight::new(1, &[true], SlamConfig::default());
        f.predicted_height_error = Some(0.0);
        f.predicted_sigma = Some(sigma);
        let (lost, frames) = lost_and_back(&mut f, 2.0, |f| f.predicted_x_error = x_error);
        eprintln!("{x_error} m off, sure to {sigma} m: {lost} of {frames} frames lost");
        (lost, frames, f)
    };
    let (lost, frames, _) = run(0.0, 0.05);
    assert!(
        lost * 4 < frames,
        "{lost} of {frames} lost on a right prediction"
    );
    let (lost, frames, f) = run(0.6, 0.05);
    assert_eq!(
        lost, frames,
        "relocalised 0.6 m from a prediction sure to 5 cm"
    );
    assert!(
        f.lost_why
            .iter()
            .any(|w| w.contains("from the prediction (gate 0.30 m")),
        "{:?}",
        &f.lost_why[f.lost_why.len().saturating_sub(3)..]
    );
    let (lost, frames, f) = run(0.6, 0.3);
    assert!(
        lost * 4 < frames,
        "{lost} of {frames} lost on an unsure prediction"
    );
    let ate = f.ate(0, None);
    assert!(ate < 0.05, "ATE {ate:.3} m: placed where the match says");
}

#[test]
fn a_lost_vehicle_is_not_relocalised_facing_otherwise_than_its_imu_reads() {
    // Half a turn, the camera blind for two seconds (tracking lost), then the turn back with
    // the IMU reading `bias` more than the truth (marked unsteady: no prior on the map) and the
    // filter's prediction right but unsure, so only the heading can tell a match wrong. In SITL
    // the wrong relocalisations faced 17–20° from the truth, the right ones within 9.4°.
    let run = |bias: f64| {
        let mut f = Flight::new(1, &[true], SlamConfig::default());
        f.predicted_height_error = Some(0.0);
        f.predicted_sigma = Some(0.3);
        let (lost, frames) = lost_and_back(&mut f, 2.0, |f| {
            f.heading_bias = Some(bias.to_radians());
            f.heading_steady = false;
        });
        eprintln!("IMU {bias}° off: {lost} of {frames} frames lost");
        (lost, frames, f.lost_why)
    };
    let (lost, frames, _) = run(5.0);
    assert!(lost * 4 < frames, "{lost} of {frames} lost, the IMU 5° off");
    let (lost, frames, why) = run(20.0);
    assert_eq!(
        lost, frames,
        "relocalised facing 20° from the IMU's heading"
    );
    assert!(
        why.iter()
            .any(|w| w.contains("from the IMU's heading (gate 12°)")),
        "{:?}",
        &why[why.len().saturating_sub(3)..]
    );
}

#[test]
fn mapping_with_known_poses_adds_no_keyframes_where_one_already_holds_the_view() {
    // A drone turns on the spot, then twice more: the later turns see what the first one's
    // keyframes already hold, so the SLAM's memory stops growing (an hour of exploration flies
    // mostly through mapped space).
    let config = SlamConfig {
        known_poses: true,
        ..SlamConfig::default()
    };
    let views = (std::f64::consts::TAU / config.keyframe_rotation).round() as usize;
    let mut f = Flight::new(1, &[true], config);
    f.known_poses = true;
    let (x, y, yaw) = start_of(&f, 0);
    let mut route = vec![[x, y, 1.0, yaw]];
    route.extend(turn(x, y, 1.0, yaw));
    f.fly(&[route.clone()], 60.0);
    let after_one_turn = f.slam.stats().keyframes;
    f.fly(&[turn(x, y, 1.0, yaw)], 60.0);
    f.fly(&[turn(x, y, 1.0, yaw)], 60.0);
    let after_three = f.slam.stats().keyframes;
    f.slam.finish();
    eprintln!(
        "{after_one_turn} keyframes after one turn, {after_three} after three, {} frames",
        f.frames[0]
    );
    // A full turn is `views` keyframes apart (45 at 8°); the later turns add at most a few
    // (hover drift moves the camera past the 0.15 m spacing now and then).
    assert!(
        (views - 5..=views + 10).contains(&after_one_turn),
        "{after_one_turn} keyframes for a turn of {views} views"
    );
    assert!(after_three <= after_one_turn + 4, "{after_three}");
    // Every frame still has its pose: the trajectory is the true one.
    assert_eq!(f.slam.trajectory(0).len(), f.frames[0]);
    assert!(f.ate(0, None) < 1e-6, "ATE {}", f.ate(0, None));
}

#[test]
fn on_a_vehicle_registrations_off_its_measured_height_are_refused() {
    // Hovering and turning, the vehicle's filter predicting its pose; then the same with a
    // filter whose height is 0.6 m off: no registration can agree with it, so none is taken
    // (a drone must not fly on a pose its rangefinder contradicts).
    let run = |height_error: f64| {
        let mut f = Flight::new(1, &[true], SlamConfig::default());
        f.predicted_height_error = Some(height_error);
        let (x, y, yaw) = start_of(&f, 0);
        f.fly(&[vec![[x, y, 1.0, yaw], [x, y, 1.0, yaw + 0.8]]], 15.0);
        f
    };
    assert_refused_only_when_off(&run(0.0), &run(0.6), "off the predicted height");
}

#[test]
fn on_a_vehicle_a_weak_registration_away_from_the_motion_is_not_to_be_flown_on() {
    // Taking off and hovering, the vehicle's filter predicting its pose, with every
    // registration counted as one on too few inliers: those that stray at all from the motion
    // so far are reported weak (a pose the station must not fly on), and with a generous
    // agreement none is. Nothing is built on a weak one, so the frame it follows stays the
    // reference and tracking goes on.
    let run = |agreement: (f64, f64)| {
        let mut f = Flight::new(
            1,
            &[true],
            SlamConfig {
                keyframe_min_inliers: usize::MAX,
                weak_agreement: agreement,
                ..SlamConfig::default()
            },
        );
        f.predicted_height_error = Some(0.0);
        let (x, y, yaw) = start_of(&f, 0);
        f.fly(&[vec![[x, y, 1.0, yaw]]], 10.0);
        f.hold(&[[x, y, 1.0, yaw]], 2.0);
        eprintln!(
            "agreement {agreement:?}: {} frames, {} tracked, {} weak, {} lost",
            f.frames[0], f.tracked[0], f.weak[0], f.lost[0]
        );
        f
    };
    let strict = run((0.0, 0.0));
    assert_eq!(strict.tracked[0], 0, "every registration strays a little");
    assert!(
        strict.weak[0] * 10 >= strict.frames[0] * 9,
        "{} of {} weak",
        strict.weak[0],
        strict.frames[0]
    );
    let lenient = run((1.0, 1.0));
    assert_eq!(lenient.weak[0], 0);
    assert!(lenient.tracked[0] * 10 >= lenient.frames[0] * 9);
}

/// One drone, `setup` then flown 0.8 m forward and held 2 s, every registration counted as one
/// on too few inliers and the motion so far allowed any error: what decides whether one is
/// built on is the vehicle alone.
fn few_inliers_forward(name: &str, setup: impl FnOnce(&mut Flight)) -> Flight {
    forward_and_hold(
        name,
        SlamConfig {
            keyframe_min_inliers: usize::MAX,
            weak_agreement: (1.0, 1.0),
            ..SlamConfig::default()
        },
        setup,
    )
}

/// One drone, `setup` then flown 0.8 m forward and held 2 s with `config`.
fn forward_and_hold(name: &str, config: SlamConfig, setup: impl FnOnce(&mut Flight)) -> Flight {
    let mut f = Flight::new(1, &[true], config);
    setup(&mut f);
    let (x, y, yaw) = start_of(&f, 0);
    let ahead = [x + 0.8 * yaw.cos(), y + 0.8 * yaw.sin(), 1.0, yaw];
    f.fly(&[vec![[x, y, 1.0, yaw], ahead]], 15.0);
    f.hold(&[ahead], 2.0);
    eprintln!(
        "{name}: {} frames, {} tracked, {} weak, {} lost, {} keyframes",
        f.frames[0],
        f.tracked[0],
        f.weak[0],
        f.lost[0],
        f.slam.stats().keyframes
    );
    f
}

#[test]
fn on_a_vehicle_a_weak_registration_away_from_its_own_predicted_move_is_not_built_on() {
    // Flying forward and hovering, every registration counted as one on too few inliers
    // (`few_inliers_forward`): the vehicle's own prediction is then the only check. Told the truth, it passes every registration; predicting a slide of 0.3 m/s that
    // is not there, it makes the registrations weak once they are 0.1 m from its move, and
    // nothing more is built on them (a bare wall's registration slides with the prediction it
    // starts from, so only the vehicle can tell).
    let run = |drift_mps: f64| {
        few_inliers_forward(&format!("drift {drift_mps} m/s"), |f| {
            f.predicted_height_error = Some(0.0);
            f.predicted_x_drift_mps = drift_mps;
        })
    };
    let honest = run(0.0);
    assert_eq!(honest.weak[0], 0);
    assert!(honest.tracked[0] * 10 >= honest.frames[0] * 9);
    let honest_keyframes = honest.slam.stats().keyframes;
    assert!(honest_keyframes >= 5, "{honest_keyframes} keyframes");
    let drifting = run(0.3);
    assert!(
        drifting.weak[0] * 10 >= drifting.frames[0] * 8,
        "{} of {} weak",
        drifting.weak[0],
        drifting.frames[0]
    );
    assert!(drifting.slam.stats().keyframes * 2 <= honest_keyframes);
    let counted = drifting.slam.estimate(0).map_or(0, |e| e.weak_frames);
    assert_eq!(counted, drifting.weak[0]);
}

#[test]
fn on_a_vehicle_a_registration_on_fewer_than_the_checked_inliers_away_from_its_move_is_weak_while_the_check_is_fresh()
 {
    // Flying forward and hovering, every registration counted as one on enough inliers for a
    // keyframe but fewer than `vehicle_check_inliers`, so the only frame to check by is the
    // first. Told the truth, the vehicle passes every one; predicting a slide that is not
    // there, it makes them weak once the slide is 0.1 m beyond the drift it is allowed
    // (`vehicle_drift_mps`), for as long as the first frame is fresh enough to check by.
    let run = |drift_mps: f64, vehicle_check_s: f64, vehicle_drift_mps: f64| {
        let config = SlamConfig {
            keyframe_min_inliers: 0,
            vehicle_check_inliers: usize::MAX,
            vehicle_check_s,
            vehicle_drift_mps,
            ..SlamConfig::default()
        };
        forward_and_hold(
            &format!(
                "drift {drift_mps} m/s, checked for {vehicle_check_s} s, \
                 {vehicle_drift_mps} m/s allowed"
            ),
            config,
            |f| {
                f.predicted_height_error = Some(0.0);
                f.predicted_x_drift_mps = drift_mps;
            },
        )
    };
    let honest = run(0.0, f64::INFINITY, 0.0);
    assert_eq!(honest.weak[0], 0);
    assert!(honest.tracked[0] * 10 >= honest.frames[0] * 9);
    let always = run(0.3, f64::INFINITY, 0.0);
    assert!(
        always.weak[0] * 10 >= always.frames[0] * 8,
        "{} of {} weak",
        always.weak[0],
        always.frames[0]
    );
    // Checked for 1 s: the frames from a third of a second (0.1 m of slide) to a second.
    let fresh = run(0.3, 1.0, 0.0);
    assert!(
        fresh.weak[0] > 0 && fresh.weak[0] * 3 <= always.weak[0],
        "{} weak checked for 1 s, {} always",
        fresh.weak[0],
        always.weak[0]
    );
    assert_eq!(run(0.3, 0.0, 0.0).weak[0], 0);
    // Allowed 0.1 m/s: a prediction drifting slower than that refuses nothing however long
    // the check lasts, and one drifting at 0.15 m/s refuses only from 2 s on (0.1 m beyond
    // 0.2 m), not from 0.7 s as when it is allowed none.
    assert_eq!(run(0.08, f64::INFINITY, 0.1).weak[0], 0);
    let strict = run(0.15, f64::INFINITY, 0.0);
    let allowed = run(0.15, f64::INFINITY, 0.1);
    assert!(
        allowed.weak[0] > 0 && allowed.weak[0] < strict.weak[0],
        "{} weak allowed 0.1 m/s, {} allowed none",
        allowed.weak[0],
        strict.weak[0]
    );
    // By default, a slide of 0.5 m/s (stop 94's seed 1045, 25–27 inliers 1.0–1.4 s after the
    // last frame to check by) is refused from a quarter of a second to 3 s after that frame,
    // not only to 1 s as the check once did.
    let d = SlamConfig::default();
    let by_default = run(0.5, d.vehicle_check_s, d.vehicle_drift_mps);
    let for_1_s = run(0.5, 1.0, d.vehicle_drift_mps);
    assert!(
        by_default.weak[0] >= 2 * for_1_s.weak[0] && for_1_s.weak[0] > 0,
        "{} weak by default, {} checked for 1 s",
        by_default.weak[0],
        for_1_s.weak[0]
    );
}

#[test]
fn on_a_vehicle_whose_filter_predicts_nothing_a_registration_on_few_inliers_is_not_built_on() {
    // Flying forward and hovering with an IMU but no prediction (its filter has given up, too
    // long without a pose to fly on), every registration counted as one on too few inliers:
    // nothing can check them against the vehicle's move, so none is built on. A hand-held
    // camera (no IMU) builds on every one.
    let run = |imu: bool| {
        few_inliers_forward(&format!("imu {imu}"), |f| {
            if !imu {
                f.heading_bias = None;
            }
        })
    };
    let vehicle = run(true);
    assert_eq!(vehicle.tracked[0], 0, "a registration built on");
    assert!(
        vehicle.weak[0] * 10 >= vehicle.frames[0] * 8,
        "{} of {} weak",
        vehicle.weak[0],
        vehicle.frames[0]
    );
    // Not flown on, a weak frame still measures how the body moved since the frame before
    // (visual odometry for the vehicle's filter): each within 2 cm, 0.2 m/s over a frame.
    assert!(
        vehicle.weak_odometry[0] * 10 >= vehicle.weak[0] * 9,
        "{} of {} weak frames measured their motion",
        vehicle.weak_odometry[0],
        vehicle.weak[0]
    );
    assert!(
        vehicle.weak_odometry_error_m < 0.02,
        "visual odometry {} m off",
        vehicle.weak_odometry_error_m
    );
    let hand_held = run(false);
    assert_eq!(hand_held.weak[0], 0);
    assert!(hand_held.tracked[0] * 10 >= hand_held.frames[0] * 8);
    let keyframes = |f: &Flight| f.slam.stats().keyframes;
    assert!(
        keyframes(&vehicle) * 2 <= keyframes(&hand_held),
        "{} keyframes on the vehicle, {} hand-held",
        keyframes(&vehicle),
        keyframes(&hand_held)
    );
}

/// `good` (a flight whose sensors tell the truth) lost at most 1 frame in 20; `off` (the same
/// flight, one sensor off) had every frame but perhaps its first refused, for `why`.
fn assert_refused_only_when_off(good: &Flight, off: &Flight, why: &str) {
    assert!(
        good.lost[0] * 20 <= good.frames[0],
        "{} of {} lost: {:?}",
        good.lost[0],
        good.frames[0],
        &good.lost_why[..good.lost_why.len().min(3)]
    );
    assert!(
        off.lost[0] + 1 >= off.frames[0],
        "{} of {} lost",
        off.lost[0],
        off.frames[0]
    );
    assert!(
        off.lost_why.iter().any(|w| w.contains(why)),
        "{:?}",
        &off.lost_why[..off.lost_why.len().min(3)]
    );
}

#[test]
fn registrations_that_contradict_the_imus_gravity_are_refused() {
    // Flying to and fro and turning, the IMU's roll and pitch given: right registrations agree
    // with them (so the conventions of both agree). Then an IMU whose roll reads 15° off: no
    // registration can agree with it, so none is taken.
    let run = |roll_bias: f64| {
        let mut f = Flight::new(1, &[true], SlamConfig::default());
        f.roll_bias = Some(roll_bias);
        let (x, y, yaw) = start_of(&f, 0);
        let (c, s) = (yaw.cos(), yaw.sin());
        f.fly(
            &[vec![
                [x, y, 1.0, yaw],
                [x + 0.8 * c, y + 0.8 * s, 1.0, yaw],
                [x, y, 1.0, yaw + 0.8],
            ]],
            20.0,
        );
        f
    };
    assert_refused_only_when_off(
        &run(0.0),
        &run(15f64.to_radians()),
        "from the IMU's gravity",
    );
}

#[test]
fn a_drone_flying_a_loop_through_the_apartment_stays_within_centimetres() {
    // Start 1 is in the south-east room; out through its door to the corridor, west along it,
    // and back: a loop of about 14 m.
    let mut f = Flight::new(1, &[true], SlamConfig::default());
    let (x, y, yaw) = start_of(&f, 0);
    let route = vec![
        [x, y, 1.0, yaw],
        [x, y, 1.0, std::f64::consts::FRAC_PI_2],
        [x, 4.7, 1.0, std::f64::consts::FRAC_PI_2],
        [x, 4.7, 1.0, std::f64::consts::PI],
        [9.0, 4.7, 1.0, std::f64::consts::PI],
        [7.0, 4.7, 1.0, std::f64::consts::PI],
        [7.0, 4.7, 1.0, 0.0],
        [x, 4.7, 1.0, 0.0],
        [x, 4.7, 1.0, -std::f64::consts::FRAC_PI_2],
        [x, y, 1.0, -std::f64::consts::FRAC_PI_2],
    ];
    f.fly(&[route], 120.0);
    f.slam.finish();
    let e = f.ate(0, None);
    eprintln!(
        "{} frames, {} lost, ATE {e:.3} m, {:?}",
        f.frames[0],
        f.lost[0],
        f.slam.stats()
    );
    assert!(
        f.lost[0] * 20 <= f.frames[0],
        "{} of {} lost",
        f.lost[0],
        f.frames[0]
    );
    assert!(e < 0.05, "ATE {e:.3} m");
}

#[test]
fn a_camera_on_the_real_fr1_xyz_motion_is_tracked_to_within_two_centimetres() {
    // The real hand-held motion (motion capture, 30 s), replayed by a camera standing 1.3 m up
    // in the north-west room, looking across it; rendered at 30 Hz.
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/rgbd/tum_fr1_xyz_trajectories/freiburg1_xyz-groundtruth.txt");
    let gt = read_tum(&path).expect("fr1/xyz ground truth");
    let world = World::load("apartment").expect("built-in");
    let camera = Camera::kinect(320, 240);
    // Anchor: the first pose maps to a camera at (1.5, 7.5) facing east, level.
    let anchor = Isometry3::from_parts(
        Translation3::new(1.5, 7.5, 1.3),
        UnitQuaternion::from_matrix(&nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, //
            -1.0, 0.0, 0.0, //
            0.0, -1.0, 0.0,
        )),
    );
    let first = gt[0].pose;
    let mut slam = Slam::new(
        SlamConfig::default(),
        vec![RobotSetup {
            body_from_camera: Isometry3::identity(),
            start: None,
        }],
    );
    let (mut truth, mut lost, mut frames) = (vec![], 0, 0);
    let t0 = gt[0].t;
    let mut next = t0;
    for s in &gt {
        if s.t < next {
            continue;
        }
        next += 1.0 / 30.0;
        let pose = anchor * first.inverse() * s.pose;
        let (rgb, depth) = sitl::render::render(&world, &pose, &camera, Some((7, frames)));
        frames += 1;
        let grey = image::DynamicImage::ImageRgb8(
            image::RgbImage::from_raw(camera.width, camera.height, rgb).expect("rgb"),
        )
        .into_luma8();
        let k = camera.intrinsics;
        let report = slam
            .process(Frame::images_only(
                0,
                s.t - t0,
                grey,
                depth,
                0.001,
                Pinhole {
                    fx: k.fx.into(),
                    fy: k.fy.into(),
                    cx: k.cx.into(),
                    cy: k.cy.into(),
                },
            ))
            .expect("frame");
        if let Tracking::Lost(_) = report.tracking {
            lost += 1;
        }
        truth.push(Stamped { t: s.t - t0, pose });
    }
    slam.finish();
    let e = ate(&truth, &slam.trajectory(0), Alignment::Se3, 1e-3).expect("pairs");
    eprintln!(
        "{frames} frames, {lost} lost, ATE {:.4} m over {} poses",
        e.rmse_m, e.pairs
    );
    assert!(lost * 50 <= frames, "{lost} of {frames} lost");
    assert!(e.rmse_m < 0.02, "ATE {:.4} m", e.rmse_m);
}

#[test]
fn two_drones_that_start_apart_end_in_one_map() {
    // Drone 1 knows its start; drone 2 does not: it maps in its own frame until its views match
    // drone 1's, then its whole trajectory must land in the map frame where it really is.
    let mut f = Flight::new(2, &[true, false], SlamConfig::default());
    let (x1, y1, yaw1) = start_of(&f, 0);
    let (x2, y2, yaw2) = start_of(&f, 1);
    let mut r1 = vec![[x1, y1, 1.0, yaw1]];
    r1.extend(turn(x1, y1, 1.0, yaw1));
    let mut r2 = vec![[x2, y2, 1.15, yaw2]];
    r2.extend(turn(x2, y2, 1.15, yaw2));
    f.fly(&[r1, r2], 90.0);
    f.slam.finish();
    let stats = f.slam.stats();
    eprintln!("{stats:?}, lost {:?} of {:?}", f.lost, f.frames);
    assert_eq!(stats.merges, 1, "drone 2's frame is anchored in the map");
    let e2 = f.slam.estimate(1).expect("robot 2");
    assert!(e2.in_map);
    // In the map frame as it is (no alignment): both within centimetres of the truth.
    for k in 0..2 {
        let e = f.ate(k, None);
        assert!(e < 0.08, "drone {}: {e:.3} m in the map frame", k + 1);
    }
    // One map: the room the two drones share has its walls where the world has them, and no
    // floor or ceiling in the 2D projection.
    let grid = f.slam.map().project().expect("a map");
    let world = World::load("apartment").expect("built-in");
    let [free, occupied, _] = grid.counts();
    assert!(
        free > 5_000 && occupied > 500,
        "free {free}, occupied {occupied}"
    );
    let mut wrong = 0;
    for y in 0..grid.height() {
        for x in 0..grid.width() {
            if grid.get((x, y)) != Cell::Occupied {
                continue;
            }
            // An occupied cell must lie within 0.15 m of a solid world cell.
            let p = grid.center_of((x, y));
            let near_wall = [-0.15, 0.0, 0.15].iter().any(|dx| {
                [-0.15, 0.0, 0.15].iter().any(|dy| {
                    let (cx, cy) = world.cell_of([p[0] + dx, p[1] + dy]);
                    world.material(cx, cy).is_solid()
                })
            });
            if !near_wall {
                wrong += 1;
            }
        }
    }
    assert!(
        wrong * 50 < occupied,
        "{wrong} of {occupied} occupied cells are nowhere near a wall (floor, ceiling or a second copy)"
    );
}
