//! One multi-robot RGB-D SLAM (thesis 000 §4.5, extended): every camera of every robot feeds
//! **one** pose graph of keyframes.
//!
//! * **Tracking**: each frame is registered against its robot's reference keyframe (guided by a
//!   constant-velocity prediction), else against the previous frame, else against the local
//!   map (the keyframes around the prediction), else by projecting the local map's points onto
//!   the frame's pixels, with depth or without ([`crate::frontend::track_by_projection`]: a wall
//!   beyond the depth camera's range), else — relocalising — against the robot's recent
//!   keyframes, keyframes near the last known or predicted pose, and keyframes that look alike
//!   ([`PlaceIndex`]). A robot whose frames cannot be registered is lost: its pose is invalid
//!   until it relocalises. A frame without features with depth enough to be a reference
//!   becomes no keyframe.
//! * **Keyframes** (graph nodes, each with its robot id) when the camera has moved far enough
//!   from the reference; each is linked to the reference and to the robot's previous keyframes,
//!   and to **loop-closure candidates** of any robot: keyframes near its estimated pose, verified
//!   geometrically, and kept only if the correction they imply is plausible.
//! * **Coordinate frames**: robots with a known start map in the map frame from the start; a robot
//!   whose start is unknown maps in a frame of its own (gravity-aligned, floor at z = 0, heading
//!   from its IMU if it has one) until two agreeing verified matches with another frame's
//!   keyframes anchor it there; then its whole trajectory moves into that frame.
//! * **Side sensors**: the IMU heading and the rangefinder height become priors on the keyframes'
//!   yaw and height (spikes gated against the visual estimate), so the graph does not drift in
//!   the directions the vehicle can measure.
//! * **Back end**: each frame's graph is optimised (Levenberg–Marquardt with faer's sparse
//!   Cholesky, Huber kernel) on a background thread whenever a loop closes or priors accumulate;
//!   loop closures that still disagree afterwards are switched off. Poses are read at any moment
//!   without waiting: a robot's pose is kept relative to its reference keyframe, so it follows
//!   every correction.
//! * **Map**: keyframes of the map frame are cast into a [`LiveMap`], rebuilt in the background
//!   when an optimisation moves them.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::thread::JoinHandle;

use image::GrayImage;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::dataset::Pinhole;
use crate::features::Keypoint;
use crate::frontend::{
    FrontendConfig, Observation, Registration, RegistrationError, observe, register,
    track_by_projection,
};
use crate::livemap::{LiveMap, MapHandle, NodeCloud, RebuildStatus};
use crate::occupancy::{DepthImage, OccupancyConfig, depth_cloud};
use crate::optimize::{Kernel, Options, Report, optimize};
use crate::place::PlaceIndex;
use crate::posegraph::{Edge, Graph, Pose, vertex_id};
use crate::trajectory::Stamped;

/// SLAM settings.
#[derive(Debug, Clone)]
pub struct SlamConfig {
    /// Features and pairwise registration.
    pub frontend: FrontendConfig,
    /// When the reference keyframe alone no longer registers a frame, it is tracked (or
    /// relocalised, when lost) against the reference's local map: its features together with
    /// those of up to this many keyframes of the same map frame (any robot's) that look the
    /// same way from within [`SlamConfig::local_map_radius`] of the prediction. 0: off.
    pub local_map_keyframes: usize,
    /// How far from the predicted camera a keyframe of the local map may be, metres.
    pub local_map_radius: f64,
    /// A new keyframe after this much translation from the reference, metres…
    pub keyframe_translation: f64,
    /// …or this much rotation, radians.
    pub keyframe_rotation: f64,
    /// A motion larger than this between consecutive frames is a wrong registration, metres…
    pub max_frame_translation: f64,
    /// …or radians.
    pub max_frame_rotation: f64,
    /// Each keyframe is also registered against this many earlier keyframes of its robot.
    pub recent_links: usize,
    /// Loop-closure candidates lie within this distance of the new keyframe, metres…
    pub loop_radius: f64,
    /// …and look within this angle of its direction, radians.
    pub loop_angle: f64,
    /// At most this many loop-closure candidates are verified per keyframe.
    pub loop_candidates: usize,
    /// Keyframes of the robot's own last this-many are not loop-closure candidates (12 at the
    /// 8° spacing: the last 96° of a turn on the spot).
    pub loop_skip_recent: usize,
    /// A loop closure needs this many inliers.
    pub loop_min_inliers: usize,
    /// On a vehicle (frames with a predicted body pose, or a robot with an IMU), a tracked frame
    /// with fewer inliers is not built on (no keyframe, not the next frame's reference;
    /// [`Tracking::Weak`])…
    pub keyframe_min_inliers: usize,
    /// …unless the frame has a predicted body pose, and it agrees with the motion so far within
    /// this (metres, radians)…
    pub weak_agreement: (f64, f64),
    /// …and the body's move since the last frame registered on more is within this (metres,
    /// horizontally) of the move the vehicle itself predicts ([`Frame::predicted_body`]). A
    /// registration on a bare wall is free along it and settles wherever it starts, i.e. at
    /// the constant-velocity prediction, so agreeing with that motion proves nothing while the
    /// vehicle brakes: in SITL a drone stopping 0.5 m from a wall was registered on 12–21
    /// inliers sliding on at 0.7 m/s, built keyframes there, and tracked 0.9 m from the truth
    /// for the rest of its mission (one map in 24 left 74 % complete). Over four missions the
    /// low-inlier registrations that agreed with the motion were within 0.04 m of the
    /// vehicle's move (34 frames); that slide was about 0.14 m off it at its first frame and
    /// 0.35 m at its second.
    pub vehicle_agreement_m: f64,
    /// On a vehicle, a registration on at least [`SlamConfig::keyframe_min_inliers`] but fewer
    /// than this many is weak too when the body's move since the last frame placed on this
    /// many, at most [`SlamConfig::vehicle_check_s`] before, is off the vehicle's by more than
    /// [`SlamConfig::vehicle_agreement_m`] and the drift allowed since
    /// ([`SlamConfig::vehicle_drift_mps`]). In SITL a hovering drone turning beside a block was
    /// registered on 33 inliers 0.3 m from where it was, and the strong tracking after it held
    /// it there until it flew into the block. Right registrations move with the vehicle,
    /// whatever their inliers.
    pub vehicle_check_inliers: usize,
    /// The vehicle's predicted move checks a registration ([`SlamConfig::vehicle_check_inliers`])
    /// only this long after the frame it is measured from, seconds…
    pub vehicle_check_s: f64,
    /// …and allows it to be off by this much more (metres a second since that frame): a
    /// prediction without a fix drifts. In SITL one drifted 0.31 m in 1.8 s (stop 76, when
    /// the filter had nothing to fly on between fixes), and refusing right registrations
    /// against it left a drone on its drifting filter until it was lost; that is why the check
    /// once ended after 1 s. Since a weak frame's visual or depth odometry feeds the filter,
    /// the prediction's error changes by 0.25 m at most in 99 % of 1–3 s stretches without a
    /// frame on 50 inliers (24 missions, stop 94), while a drone relocalised 1.3 s before was
    /// registered on 25–27 inliers sliding 0.5 m along a corridor it hovered in, and the
    /// keyframes built there bent its map (stop 94, seed 1045).
    pub vehicle_drift_mps: f64,
    /// On a vehicle, a registration that needed features without depth
    /// ([`crate::frontend::track_by_projection`]) is weak unless it is this close to the motion
    /// so far (metres, radians), however many inliers it has.
    pub projection_agreement: (f64, f64),
    /// A registration that puts the body further than this (metres) above or below the height
    /// its filter predicts (or its rangefinder reads) is wrong, however many inliers it has: a
    /// wall's repeated pattern matched one block up or down.
    pub max_height_disagreement: f64,
    /// A registration that tilts the body further than this from the roll and pitch its IMU
    /// reads is wrong, radians. Measured in SITL (3 444 tracked frames against the truth):
    /// right registrations within 2.2° of gravity (99 %), the wrong ones that flew drones into
    /// walls 10–75° and growing frame by frame.
    pub max_tilt_disagreement: f64,
    /// A loop closure may correct the current estimate by at most this much, metres…
    pub loop_max_correction: f64,
    /// …and radians.
    pub loop_max_correction_angle: f64,
    /// A loop closure whose turn between its two keyframes differs from the turn their IMU
    /// headings read by more than this is a look-alike place matched by mistake, radians
    /// (`None`: not checked). Measured in SITL (967 closures against the truth): wrong ones
    /// were all 3.8–9.3° off in yaw, right ones under 2.6° (99 %).
    pub loop_max_heading_disagreement: Option<f64>,
    /// A loop closure between robots with IMUs that cannot be checked against their headings
    /// (one of its keyframes was taken while turning too fast for the heading to be trusted)
    /// needs this many inliers. (Cameras without an IMU keep [`SlamConfig::loop_min_inliers`].)
    /// In SITL most closures are of this kind (817 of 1 067 in four runs: drones turn a lot),
    /// the right ones with 55–81 inliers (10th percentile–median), the wrong ones 25–55.
    pub loop_min_inliers_unchecked: usize,
    /// Keyframes of other coordinate frames that look alike, verified per keyframe (merging).
    pub place_candidates: usize,
    /// Candidates tried per frame while relocalising.
    pub relocalisation_candidates: usize,
    /// A relocalisation needs this many inliers.
    pub relocalisation_min_inliers: usize,
    /// …and this many on a vehicle (a robot with an IMU) with no prediction to check it against
    /// (its filter has given up, its heading is not trusted while it turns): in SITL, ones
    /// with nothing to check them put drones 1.6–7 m from where they were.
    pub relocalisation_min_inliers_unpredicted: usize,
    /// Guided matching while relocalising searches this far around a point's predicted
    /// position, pixels (the prediction is poorer than while tracking).
    pub relocalisation_search_px: f32,
    /// While lost, a relocalisation further from the prediction than this (metres, radians)
    /// is a wrong match…
    pub relocalisation_gate: (f64, f64),
    /// …as is one further than the robot can have gone from the prediction since it was last
    /// placed, at this speed (m/s; a lost drone holds its place: those found again after 10 s
    /// blind in SITL had drifted under 1 m)…
    pub relocalisation_drift_mps: f64,
    /// …or, for a prediction whose uncertainty is known ([`Frame::predicted_sigma_m`]), further
    /// than this many of its standard deviations…
    pub relocalisation_gate_sigmas: f64,
    /// …but the gate is never narrower than this, metres. In SITL a match 0.7 m along a wall of
    /// repeated texture, taken 0.3 s after a drone was lost, put its pose there for the rest of
    /// the mission, and it pressed into the wall ten times.
    pub relocalisation_gate_min_m: f64,
    /// A relocalisation facing further than this from the heading the vehicle's IMU reads
    /// (steady or turning) is a look-alike place, radians. Over 611 findings of a lost drone
    /// in SITL, the right ones faced within 9.4° of the truth half a second on (median 1.8°),
    /// the wrong ones (0.7–1.1 m off, one kept for the rest of its mission) 17–20°.
    pub relocalisation_heading_gate: f64,
    /// While lost, consecutive frames at most this far apart (seconds) are registered on each
    /// other for [`Odometry`]…
    pub odometry_max_gap: f64,
    /// …which needs this many inliers.
    pub odometry_min_inliers: usize,
    /// Standard deviation of an unrefined registration with 100 inliers: metres and radians.
    pub link_sigma: (f64, f64),
    /// A refined registration's information is its Hessian times this (matching errors are not
    /// independent, so the Hessian is overconfident).
    pub link_information_scale: f64,
    /// Every link is at least this certain in every direction (standard deviations: metres,
    /// radians). A registration's Hessian can be nearly singular — a camera up against a bare
    /// wall constrains nothing along it — and must not leave a chain of keyframes free to
    /// slide. (Added while chasing optimisations that moved keyframes metres; it did not stop
    /// those.)
    pub link_max_sigma: (f64, f64),
    /// Standard deviation of the IMU heading prior, radians (`None`: headings unused).
    pub heading_sigma: Option<f64>,
    /// Standard deviation of the rangefinder height prior, metres (`None`: heights unused).
    pub height_sigma: Option<f64>,
    /// Standard deviation of the IMU gravity prior (roll and pitch) on a keyframe, radians
    /// (`None`: only the check of [`SlamConfig::max_tilt_disagreement`]), as RTAB-Map's
    /// `Optimizer/GravitySigma`. Without it nothing held the map level: in one SITL mission a
    /// chain of keyframes, each within the check of the last, leaned 6–7°, and the check then
    /// refused the right registrations there (309 of its 367 lost frames; 4 % of the lost
    /// frames over eight other missions).
    pub tilt_sigma: Option<f64>,
    /// A heading further than this from the visual estimate is a spike, radians.
    pub heading_gate: f64,
    /// A height further than this from the visual estimate is not the floor, metres.
    pub height_gate: f64,
    /// Two frame-to-frame anchorings agree within this (metres, radians) to merge frames.
    pub merge_agreement: (f64, f64),
    /// Optimise after this many keyframes with priors even without a loop closure.
    pub optimise_every: usize,
    /// After optimisation, loop closures with χ² above this are switched off.
    pub loop_reject_chi2: f64,
    /// Optimiser settings.
    pub optimiser: Options,
    /// Optimise on a background thread (the default) or inline, deterministically.
    pub background: bool,
    /// Mapping only: every frame carries its camera pose (ground truth, motion capture) and no
    /// tracking is done.
    pub known_poses: bool,
    /// The occupancy map.
    pub occupancy: OccupancyConfig,
    /// Rebuild the map when an optimisation moves a keyframe by more than this, metres…
    pub rebuild_translation: f64,
    /// …or radians.
    pub rebuild_rotation: f64,
}

impl Default for SlamConfig {
    fn default() -> Self {
        Self {
            frontend: FrontendConfig::default(),
            local_map_keyframes: 5,
            local_map_radius: 2.0,
            keyframe_translation: 0.15,
            keyframe_rotation: 8f64.to_radians(),
            max_frame_translation: 0.5,
            max_frame_rotation: 45f64.to_radians(),
            recent_links: 2,
            loop_radius: 2.0,
            loop_angle: 50f64.to_radians(),
            loop_candidates: 3,
            loop_skip_recent: 12,
            loop_min_inliers: 25,
            keyframe_min_inliers: 25,
            weak_agreement: (0.03, 1f64.to_radians()),
            vehicle_agreement_m: 0.1,
            vehicle_check_inliers: 50,
            vehicle_check_s: 3.0,
            vehicle_drift_mps: 0.1,
            projection_agreement: (0.05, 2f64.to_radians()),
            max_height_disagreement: 0.3,
            max_tilt_disagreement: 6f64.to_radians(),
            loop_max_correction: 1.0,
            loop_max_correction_angle: 20f64.to_radians(),
            loop_max_heading_disagreement: Some(3f64.to_radians()),
            loop_min_inliers_unchecked: 60,
            place_candidates: 2,
            relocalisation_candidates: 6,
            relocalisation_min_inliers: 25,
            relocalisation_min_inliers_unpredicted: 60,
            relocalisation_search_px: 60.0,
            relocalisation_gate: (1.0, 0.6),
            relocalisation_drift_mps: 0.3,
            relocalisation_gate_sigmas: 3.0,
            relocalisation_gate_min_m: 0.3,
            relocalisation_heading_gate: 12f64.to_radians(),
            odometry_max_gap: 0.5,
            odometry_min_inliers: 15,
            link_sigma: (0.01, 0.5f64.to_radians()),
            link_information_scale: 0.05,
            link_max_sigma: (0.1, 3f64.to_radians()),
            heading_sigma: Some(2f64.to_radians()),
            height_sigma: Some(0.03),
            tilt_sigma: Some(3f64.to_radians()),
            heading_gate: 10f64.to_radians(),
            height_gate: 0.3,
            merge_agreement: (0.2, 5f64.to_radians()),
            optimise_every: 10,
            loop_reject_chi2: 100.0,
            optimiser: Options {
                kernel: Kernel::Huber(3.5),
                max_iterations: 30,
                relative_tolerance: 1e-6,
                ..Options::default()
            },
            background: true,
            known_poses: false,
            occupancy: OccupancyConfig {
                pixel_step: 6,
                ..OccupancyConfig::default()
            },
            rebuild_translation: 0.03,
            rebuild_rotation: 1f64.to_radians(),
        }
    }
}

/// One robot's camera mounting and, where known, where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSetup {
    /// The camera's optical frame on the body (body: x forward, y left, z up).
    pub body_from_camera: Isometry3<f64>,
    /// The body's pose in the map at the first frame (on the floor), when known.
    pub start: Option<Isometry3<f64>>,
}

/// One RGB-D frame of one robot, with what its vehicle measured at the same time.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The robot (index into the setups given to [`Slam::new`]).
    pub robot: usize,
    /// Capture time, seconds.
    pub stamp: f64,
    /// The colour image in grey.
    pub grey: GrayImage,
    /// Depth, row-major, same size as `grey`, in units of `depth_scale`.
    pub depth: Vec<u16>,
    /// Metres per depth unit.
    pub depth_scale: f64,
    /// Intrinsics.
    pub camera: Pinhole,
    /// The body's heading from its IMU, radians (+ anticlockwise), if it has one.
    pub heading: Option<f64>,
    /// The body was not turning when `heading` was read: only then is the heading a prior on
    /// the map. A heading read while turning lags the camera (telemetry comes late) and, with
    /// keyframes taken mostly while turning, biased the map's yaw; relocalisation and the
    /// loop-closure check use any heading.
    pub heading_steady: bool,
    /// The IMU heading read while the body turned too fast for `heading` (`heading` is then
    /// `None`): it lags the camera by a few degrees, too much to check loop closures with, but
    /// a lost robot is still looked for facing this way (the relocalisation gate allows 0.6
    /// rad). Without it, a drone lost during a turn could be found only by a match strong
    /// enough to need no prediction ([`SlamConfig::relocalisation_min_inliers_unpredicted`]).
    pub turning_heading: Option<f64>,
    /// The body's height above the floor from its rangefinder, metres, if it has one.
    pub height: Option<f64>,
    /// The body's roll and pitch (FLU, radians: right side down, nose down) from its IMU or
    /// flight filter, if it has them: gravity's direction, which no registration may contradict.
    pub tilt: Option<[f64; 2]>,
    /// A prediction of the body's pose in the robot's frame (e.g. from an EKF), used to
    /// relocalise when tracking was lost.
    pub predicted_body: Option<Isometry3<f64>>,
    /// The horizontal standard deviation of `predicted_body`, metres, if known: a
    /// relocalisation far beyond it is refused ([`SlamConfig::relocalisation_gate_sigmas`]).
    pub predicted_sigma_m: Option<f64>,
    /// The camera's pose known from elsewhere (used, and required, in mapping-only mode:
    /// [`SlamConfig::known_poses`]).
    pub known_camera_pose: Option<Isometry3<f64>>,
}

impl Frame {
    /// A frame of robot `robot` at `stamp` with its images alone (a hand-held camera, a
    /// dataset): no heading, height, tilt, prediction or known pose. A vehicle's caller sets
    /// what it measured on top (`Frame { heading, ..Frame::images_only(…) }`).
    pub fn images_only(
        robot: usize,
        stamp: f64,
        grey: GrayImage,
        depth: Vec<u16>,
        depth_scale: f64,
        camera: Pinhole,
    ) -> Self {
        Self {
            robot,
            stamp,
            grey,
            depth,
            depth_scale,
            camera,
            heading: None,
            heading_steady: false,
            turning_heading: None,
            height: None,
            tilt: None,
            predicted_body: None,
            predicted_sigma_m: None,
            known_camera_pose: None,
        }
    }
}

/// What happened to one frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Tracking {
    /// The robot's first keyframe: its map starts here.
    Started,
    /// Registered against its reference keyframe or the previous frame.
    Tracked {
        /// Inliers of the registration.
        inliers: usize,
    },
    /// On a vehicle: registered on fewer than [`SlamConfig::keyframe_min_inliers`] inliers and
    /// away from the motion so far ([`SlamConfig::weak_agreement`]) or from the move the
    /// vehicle predicts ([`SlamConfig::vehicle_agreement_m`]). The frame keeps this pose,
    /// but nothing is built on it, and a vehicle should not be flown on it: in SITL, runs of
    /// such registrations on 17–22 inliers walked a drone's pose 0.6 m from the truth in 0.7 s
    /// while it turned near a door, and its position controller flew it into the jamb.
    Weak {
        /// Inliers of the registration.
        inliers: usize,
    },
    /// Placed at the pose it came with ([`Frame::known_camera_pose`]), not registered.
    Known,
    /// Registered again after being lost.
    Relocalised {
        /// The keyframe it was registered against.
        keyframe: usize,
    },
    /// Not registered: the pose is invalid until the robot relocalises.
    Lost(String),
}

/// The outcome of [`Slam::process`].
#[derive(Debug, Clone, PartialEq)]
pub struct FrameReport {
    /// Tracking.
    pub tracking: Tracking,
    /// The keyframe this frame became, if it did.
    pub keyframe: Option<usize>,
    /// Loop closures added with it.
    pub loop_closures: usize,
    /// Coordinate frames merged because of it: (kept, absorbed).
    pub merged: Option<(usize, usize)>,
    /// While lost, or placed weakly ([`Tracking::Weak`]): how the body moved since the
    /// robot's previous frame, registered on that frame alone ([`Odometry`]).
    pub odometry: Option<Odometry>,
}

/// Visual odometry of a robot the map cannot place (lost, or placed only weakly): its body's
/// motion between two consecutive frames, measured by registering one on the other. A
/// vehicle's filter can still fly on how far it moved (instead of on its model alone, which
/// drifts metres in seconds); kept out of the map and the graph, which it would bend.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    /// The earlier frame's time, seconds.
    pub since: f64,
    /// The body at the earlier frame from the body now.
    pub previous_from_body: Isometry3<f64>,
    /// Inliers of the registration.
    pub inliers: usize,
}

/// A robot's tracking state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotState {
    /// No frame processed yet.
    Waiting,
    /// The pose is valid.
    Tracking,
    /// Tracking was lost: the pose is invalid.
    Lost,
}

impl RobotState {
    /// Lower-case name for displays.
    pub fn name(self) -> &'static str {
        match self {
            RobotState::Waiting => "waiting",
            RobotState::Tracking => "tracking",
            RobotState::Lost => "lost",
        }
    }
}

/// A robot's current estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotEstimate {
    /// Tracking state.
    pub state: RobotState,
    /// The camera's pose in the robot's coordinate frame; `None` unless tracking.
    pub frame_from_camera: Option<Isometry3<f64>>,
    /// The body's pose in the robot's coordinate frame; `None` unless tracking.
    pub frame_from_body: Option<Isometry3<f64>>,
    /// Whether the robot's frame is the map frame (its pose is a map pose).
    pub in_map: bool,
    /// Time of the last frame processed, seconds.
    pub stamp: f64,
    /// Frames processed.
    pub frames: usize,
    /// Frames that could not be tracked.
    pub lost_frames: usize,
    /// Of those, frames whose motion since the previous frame visual odometry measured.
    pub odometry_frames: usize,
    /// Frames placed on features without depth ([`crate::frontend::track_by_projection`]).
    pub projection_frames: usize,
    /// Frames given a pose not to fly on ([`Tracking::Weak`]).
    pub weak_frames: usize,
    /// Keyframes in the graph.
    pub keyframes: usize,
}

impl RobotEstimate {
    /// The body's pose in the map, when tracking in the map frame.
    pub fn map_from_body(&self) -> Option<Isometry3<f64>> {
        self.frame_from_body.filter(|_| self.in_map)
    }

    /// The camera's pose in the map, when tracking in the map frame.
    pub fn map_from_camera(&self) -> Option<Isometry3<f64>> {
        self.frame_from_camera.filter(|_| self.in_map)
    }
}

/// Counters for displays and logs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SlamStats {
    /// Keyframes.
    pub keyframes: usize,
    /// Loop closures in the graph (switched-off ones excluded).
    pub loop_closures: usize,
    /// Loop closures switched off by the optimiser's check.
    pub rejected_loop_closures: usize,
    /// Coordinate frames merged.
    pub merges: usize,
    /// Optimisations applied.
    pub optimisations: usize,
    /// Map rebuilds swapped in.
    pub map_rebuilds: u64,
    /// Wall time of the last optimisation, seconds.
    pub last_optimisation_s: f64,
}

/// A loop closure or merge match between two keyframes, as verified by registration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopClosure {
    /// The robots of the two keyframes: (a, b).
    pub robots: (usize, usize),
    /// Capture times of the two keyframes, seconds: (a, b).
    pub stamps: (f64, f64),
    /// Keyframe b's camera in keyframe a's camera, as measured.
    pub a_from_b: Isometry3<f64>,
    /// Still in the graph (not switched off by a consistency check).
    pub alive: bool,
}

/// A frame that cannot be processed at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SlamError {
    /// The frame names a robot the SLAM was not set up with.
    #[error("frame of robot {robot}, but the SLAM was set up for {robots} robot(s)")]
    UnknownRobot {
        /// The robot in the frame.
        robot: usize,
        /// Robots set up.
        robots: usize,
    },
    /// Depth and colour differ in size.
    #[error("depth image has {depth} pixels, the colour image {colour}")]
    SizeMismatch {
        /// Depth pixels.
        depth: usize,
        /// Colour pixels.
        colour: usize,
    },
}

#[derive(Debug, Clone)]
struct Node {
    robot: usize,
    stamp: f64,
    frame: usize,
    /// Camera to its coordinate frame.
    pose: Isometry3<f64>,
    /// The keyframe it was created from (corrections propagate along this).
    parent: Option<usize>,
    /// The body's IMU heading at its capture, radians.
    heading: Option<f64>,
    observation: Arc<Observation>,
    cloud: Arc<Vec<Point3<f32>>>,
}

/// How far a keyframe at `other` (camera to frame) is from one at `new` in place and in view,
/// each as a share of its bound ([`SlamConfig::loop_radius`], [`SlamConfig::loop_angle`]); `None`
/// beyond either. Loop-closure candidates are tried lowest first: a drone turning on the spot has
/// many keyframes within reach, and only those looking the same way see the same things.
fn loop_candidate_rank(
    config: &SlamConfig,
    new: &Isometry3<f64>,
    other: &Isometry3<f64>,
) -> Option<f64> {
    let distance = (other.translation.vector - new.translation.vector).norm();
    let angle = (other.rotation * Vector3::z()).angle(&(new.rotation * Vector3::z()));
    (distance < config.loop_radius && angle < config.loop_angle)
        .then(|| distance / config.loop_radius + angle / config.loop_angle)
}

/// A match between two keyframes against their IMU headings.
#[derive(Debug, Clone, Copy, PartialEq)]
enum HeadingCheck {
    /// It turns as the headings do.
    Agrees,
    /// It turns this much more than the headings (radians, signed): a wrong match.
    Disagrees(f64),
    /// A robot with an IMU had no heading at one of the keyframes (it was turning too fast).
    Missing,
    /// The check is off, or a camera has no IMU at all.
    Unavailable,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LinkKind {
    Odometry,
    Loop,
}

#[derive(Debug, Clone)]
struct Link {
    a: usize,
    b: usize,
    a_from_b: Isometry3<f64>,
    info: Vec<f64>,
    kind: LinkKind,
    alive: bool,
}

#[derive(Debug, Clone)]
struct Prior {
    node: usize,
    /// The measured camera pose (only the informative directions matter).
    z: Isometry3<f64>,
    info: Vec<f64>,
    /// A start prior ties a robot to its coordinate frame's origin; dropped when the frame merges.
    start: bool,
    alive: bool,
}

/// The previous frame of a robot, kept as a short-baseline fallback.
#[derive(Debug, Clone)]
struct Previous {
    observation: Arc<Observation>,
    reference: usize,
    reference_from_camera: Isometry3<f64>,
}

#[derive(Debug, Clone)]
struct Robot {
    setup: RobotSetup,
    frame: usize,
    state: RobotState,
    /// The reference keyframe and the camera relative to it (the last known pose while lost).
    reference: Option<usize>,
    reference_from_camera: Isometry3<f64>,
    previous: Option<Previous>,
    /// Previous camera from current camera, for the constant-velocity prediction.
    velocity: Option<Isometry3<f64>>,
    /// The last frame placed on a registration strong enough to build on, on a vehicle: its
    /// reference keyframe, the camera relative to it, and the body the vehicle predicted then
    /// ([`Frame::predicted_body`]). Weak registrations are held to how far the vehicle says it
    /// moved since ([`SlamConfig::vehicle_agreement_m`]).
    trusted: Option<VehicleFix>,
    /// As [`Robot::trusted`], for frames on at least [`SlamConfig::vehicle_check_inliers`].
    checked: Option<VehicleFix>,
    nodes: Vec<usize>,
    stamp: f64,
    frames: usize,
    lost_frames: usize,
    odometry_frames: usize,
    projection_frames: usize,
    weak_frames: usize,
    /// Some frame came with an IMU heading (a vehicle, not a hand-held camera).
    has_imu: bool,
    /// Every tracked frame: time, reference keyframe, camera relative to it.
    track: Vec<(f64, usize, Isometry3<f64>)>,
    /// The last frame (for visual odometry): its time, what it saw, and whether the map
    /// placed it (neither lost nor weak).
    last_frame: Option<(f64, Arc<Observation>, bool)>,
}

/// A frame of a vehicle placed by the SLAM, kept to check later registrations by the vehicle's
/// own predicted move since it.
#[derive(Debug, Clone, Copy)]
struct VehicleFix {
    /// Its reference keyframe…
    node: usize,
    /// …and the camera relative to it.
    node_from_camera: Isometry3<f64>,
    /// The body the vehicle predicted then ([`Frame::predicted_body`]).
    predicted_body: Isometry3<f64>,
    /// The frame's time, seconds.
    stamp: f64,
}

/// One optimisation of one coordinate frame's graph.
struct Job {
    frame: usize,
    epoch: u64,
    nodes: Vec<usize>,
    graph: Graph<Isometry3<f64>>,
    /// Graph edge index → link id, for the loop closures.
    loops: Vec<(usize, usize)>,
}

struct Done {
    frame: usize,
    epoch: u64,
    nodes: Vec<usize>,
    result: Result<(Vec<Isometry3<f64>>, Report), String>,
    rejected: Vec<usize>,
}

/// Runs a job: optimise, then flag the loop closures that still disagree.
fn run_job(mut job: Job, options: &Options, reject_chi2: f64) -> Done {
    let initial = job.graph.poses.clone();
    let mut result = optimize(&mut job.graph, options);
    let mut rejected = vec![];
    if result.is_ok() {
        let mut e = [0.0; 6];
        let mut bad = vec![];
        for &(edge, link) in &job.loops {
            let ed = &job.graph.edges[edge];
            Isometry3::error(
                &job.graph.poses[ed.i],
                &job.graph.poses[ed.j],
                &ed.z,
                &mut e,
            );
            if crate::posegraph::quad(&ed.info, &e, 6) > reject_chi2 {
                rejected.push(link);
                bad.push(edge);
            }
        }
        if !bad.is_empty() {
            // Those closures pulled on every pose before the check caught them: optimise again
            // without them, from where this job started, so no published pose carries them.
            bad.sort_unstable();
            for edge in bad.into_iter().rev() {
                job.graph.edges.remove(edge);
            }
            job.graph.poses = initial;
            result = optimize(&mut job.graph, options);
        }
    }
    Done {
        frame: job.frame,
        epoch: job.epoch,
        nodes: job.nodes,
        result: result
            .map(|r| (job.graph.poses, r))
            .map_err(|e| e.to_string()),
        rejected,
    }
}

/// The background optimiser: one thread, one job at a time.
struct Worker {
    jobs: Sender<Job>,
    done: Receiver<Done>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    fn start(options: Options, reject_chi2: f64) -> Option<Self> {
        let (jobs, job_rx) = channel::<Job>();
        let (done_tx, done) = channel();
        let thread = std::thread::Builder::new()
            .name("slam-optimiser".into())
            .spawn(move || {
                for job in job_rx {
                    if done_tx.send(run_job(job, &options, reject_chi2)).is_err() {
                        return;
                    }
                }
            })
            .ok()?;
        Some(Self {
            jobs,
            done,
            thread: Some(thread),
        })
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        // Closing the job channel ends the thread after its current job.
        let (dead, _) = channel();
        drop(std::mem::replace(&mut self.jobs, dead));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The multi-robot SLAM.
pub struct Slam {
    config: SlamConfig,
    robots: Vec<Robot>,
    nodes: Vec<Node>,
    links: Vec<Link>,
    priors: Vec<Prior>,
    /// Per coordinate frame: epoch (bumped when a merge changes it), and whether it needs
    /// optimising.
    frames: Vec<(u64, bool)>,
    /// Keyframes with priors since the frame's last optimisation.
    since_optimised: Vec<usize>,
    /// Anchoring candidates between two frames: (kept, absorbed) → kept_from_absorbed.
    merge_votes: HashMap<(usize, usize), Vec<Isometry3<f64>>>,
    place: PlaceIndex,
    /// Mapping with known poses: keyframes by the cell (see [`Slam::view_cell`]) their camera
    /// is in, to find one already holding a view.
    views: HashMap<[i64; 3], Vec<usize>>,
    worker: Option<Worker>,
    in_flight: bool,
    map: LiveMap,
    stats: SlamStats,
}

/// Mapping with known poses, a keyframe within this many times the keyframe spacing (in
/// distance and in angle) of a new view already holds it: a hovering drone drifts a few
/// decimetres, and a view that close adds next to nothing to the map.
pub const KNOWN_VIEW_REUSE: f64 = 2.0;

/// Information matrix (6×6, row-major) with isotropic translation and rotation weights.
fn isotropic_info(sigma_t: f64, sigma_r: f64) -> Vec<f64> {
    let mut info = vec![0.0; 36];
    for k in 0..3 {
        info[k * 6 + k] = 1.0 / (sigma_t * sigma_t);
        info[(k + 3) * 6 + k + 3] = 1.0 / (sigma_r * sigma_r);
    }
    info
}

/// The body's yaw of a camera pose.
fn body_yaw(frame_from_camera: &Isometry3<f64>, camera_from_body: &Isometry3<f64>) -> f64 {
    let body = frame_from_camera * camera_from_body;
    let x = body.rotation * Vector3::x();
    x.y.atan2(x.x)
}

/// `pose` with its rotation's quaternion back at unit norm. Every composition rounds the norm a
/// little off 1, and nalgebra's unit quaternions trust it: a keyframe that follows its parent's
/// correction (`new · old⁻¹ · pose`) takes the parent's error three times over, so keyframes
/// added while optimisations ran grew it geometrically — to 24 % in SITL, where the "rotations"
/// stretched vectors and moved keyframes metres. Every pose a keyframe is given goes through
/// here.
fn rigid(mut pose: Isometry3<f64>) -> Isometry3<f64> {
    pose.rotation.renormalize();
    pose
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

impl Slam {
    /// A SLAM for the robots `setups` (robot k is `setups[k]`). Robots with a known start share
    /// the map frame; each other robot starts in a frame of its own — except that, when no
    /// start is known at all, robot 0's frame is the map.
    pub fn new(config: SlamConfig, setups: Vec<RobotSetup>) -> Self {
        let any_known = setups.iter().any(|s| s.start.is_some());
        let mut next_frame = 1;
        let robots: Vec<Robot> = setups
            .into_iter()
            .enumerate()
            .map(|(k, setup)| {
                let frame = if setup.start.is_some() || (!any_known && k == 0) {
                    0
                } else {
                    next_frame += 1;
                    next_frame - 1
                };
                Robot {
                    setup,
                    frame,
                    state: RobotState::Waiting,
                    reference: None,
                    reference_from_camera: Isometry3::identity(),
                    previous: None,
                    velocity: None,
                    trusted: None,
                    checked: None,
                    nodes: vec![],
                    stamp: 0.0,
                    frames: 0,
                    lost_frames: 0,
                    odometry_frames: 0,
                    projection_frames: 0,
                    weak_frames: 0,
                    last_frame: None,
                    has_imu: false,
                    track: vec![],
                }
            })
            .collect();
        let worker = if config.background {
            Worker::start(config.optimiser.clone(), config.loop_reject_chi2)
        } else {
            None
        };
        Self {
            map: LiveMap::new(config.occupancy.clone()),
            config,
            frames: vec![(0, false); next_frame],
            since_optimised: vec![0; next_frame],
            robots,
            nodes: vec![],
            links: vec![],
            priors: vec![],
            merge_votes: HashMap::new(),
            place: PlaceIndex::new(),
            views: HashMap::new(),
            worker,
            in_flight: false,
            stats: SlamStats::default(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &SlamConfig {
        &self.config
    }

    /// Number of robots.
    pub fn robots(&self) -> usize {
        self.robots.len()
    }

    /// Where robot `k`'s camera sits on its body (`None`: no such robot).
    pub fn body_from_camera(&self, k: usize) -> Option<Isometry3<f64>> {
        self.robots.get(k).map(|r| r.setup.body_from_camera)
    }

    /// A handle on the occupancy map of the map frame, for readers on other threads.
    pub fn map(&self) -> MapHandle {
        self.map.handle()
    }

    /// Counters.
    pub fn stats(&self) -> SlamStats {
        SlamStats {
            keyframes: self.nodes.len(),
            loop_closures: self
                .links
                .iter()
                .filter(|l| l.alive && l.kind == LinkKind::Loop)
                .count(),
            map_rebuilds: self.map.rebuilds(),
            ..self.stats
        }
    }

    /// Robot `k`'s current estimate.
    pub fn estimate(&self, k: usize) -> Option<RobotEstimate> {
        let r = self.robots.get(k)?;
        let frame_from_camera = match (r.state, r.reference) {
            (RobotState::Tracking, Some(n)) => Some(self.nodes[n].pose * r.reference_from_camera),
            _ => None,
        };
        let camera_from_body = r.setup.body_from_camera.inverse();
        Some(RobotEstimate {
            state: r.state,
            frame_from_body: frame_from_camera.map(|c| c * camera_from_body),
            frame_from_camera,
            in_map: r.frame == 0,
            stamp: r.stamp,
            frames: r.frames,
            lost_frames: r.lost_frames,
            odometry_frames: r.odometry_frames,
            projection_frames: r.projection_frames,
            weak_frames: r.weak_frames,
            keyframes: r.nodes.len(),
        })
    }

    /// Every tracked frame of robot `k` (camera to its frame) at the current keyframe poses.
    pub fn trajectory(&self, k: usize) -> Vec<Stamped> {
        self.robots.get(k).map_or_else(Vec::new, |r| {
            r.track
                .iter()
                .map(|&(t, n, rel)| Stamped {
                    t,
                    pose: self.nodes[n].pose * rel,
                })
                .collect()
        })
    }

    /// Every loop closure added so far, switched-off ones included (for diagnostics: against
    /// ground truth, a wrong one shows as a measurement far from the true relative pose).
    pub fn loop_closures(&self) -> Vec<LoopClosure> {
        self.links
            .iter()
            .filter(|l| l.kind == LinkKind::Loop)
            .map(|l| {
                let (a, b) = (&self.nodes[l.a], &self.nodes[l.b]);
                LoopClosure {
                    robots: (a.robot, b.robot),
                    stamps: (a.stamp, b.stamp),
                    a_from_b: l.a_from_b,
                    alive: l.alive,
                }
            })
            .collect()
    }

    /// Robot `k`'s keyframes (camera to its frame).
    pub fn keyframe_trajectory(&self, k: usize) -> Vec<Stamped> {
        self.robots.get(k).map_or_else(Vec::new, |r| {
            r.nodes
                .iter()
                .map(|&n| Stamped {
                    t: self.nodes[n].stamp,
                    pose: self.nodes[n].pose,
                })
                .collect()
        })
    }

    /// The pose graph of the map frame (vertex 0: the map's origin; robot k's keyframes carry
    /// GTSAM-style ids with letter `b'a' + k`), for export as g2o.
    pub fn graph(&self) -> Graph<Isometry3<f64>> {
        self.build_job(0).graph
    }

    /// Processes one frame.
    pub fn process(&mut self, frame: Frame) -> Result<FrameReport, SlamError> {
        let k = frame.robot;
        if k >= self.robots.len() {
            return Err(SlamError::UnknownRobot {
                robot: k,
                robots: self.robots.len(),
            });
        }
        let (w, h) = frame.grey.dimensions();
        if frame.depth.len() != (w as usize) * (h as usize) {
            return Err(SlamError::SizeMismatch {
                depth: frame.depth.len(),
                colour: (w as usize) * (h as usize),
            });
        }
        self.poll();
        if self.config.known_poses {
            let report = match frame.known_camera_pose {
                Some(pose) => self.place_known(&frame, pose),
                None => lost("mapping-only mode needs the camera's pose with every frame".into()),
            };
            let r = &mut self.robots[k];
            r.frames += 1;
            r.stamp = frame.stamp;
            if let Some(n) = r.reference {
                r.track.push((frame.stamp, n, r.reference_from_camera));
            }
            return Ok(report);
        }
        let observation = Arc::new(observe(
            &frame.grey,
            &frame.depth,
            frame.depth_scale,
            &frame.camera,
            &self.config.frontend,
        ));
        let robot = &mut self.robots[k];
        robot.frames += 1;
        robot.stamp = frame.stamp;
        robot.has_imu |= frame.heading.or(frame.turning_heading).is_some();
        let mut report = if robot.reference.is_none() {
            self.start(&frame, observation.clone())
        } else {
            self.track(&frame, observation.clone())
        };
        // Visual odometry where the map does not place the frame: a weak frame's since the
        // frame before, a lost frame's only since one the map did not place either (the steps
        // stop 91 measured against the truth; the step into a loss was never measured).
        let since_placed = self.robots[k].last_frame.as_ref().is_some_and(|l| l.2);
        let (measure, placed) = match report.tracking {
            Tracking::Weak { .. } => (true, false),
            Tracking::Lost(_) => (!since_placed, false),
            _ => (false, true),
        };
        if measure {
            report.odometry = self.frame_odometry(k, frame.stamp, &observation);
        }
        self.robots[k].last_frame = Some((frame.stamp, observation, placed));
        if let Tracking::Lost(_) = report.tracking {
            let r = &mut self.robots[k];
            r.odometry_frames += usize::from(report.odometry.is_some());
            r.lost_frames += 1;
            r.state = if r.reference.is_some() {
                RobotState::Lost
            } else {
                RobotState::Waiting
            };
            r.previous = None;
            r.velocity = None;
            r.trusted = None;
            r.checked = None;
        } else if let Some(n) = self.robots[k].reference {
            let r = &mut self.robots[k];
            // Placed on a registration of at least `needed` inliers (or none needed).
            let placed_on = |needed: usize| match report.tracking {
                Tracking::Tracked { inliers } => inliers >= needed,
                Tracking::Started | Tracking::Known | Tracking::Relocalised { .. } => true,
                Tracking::Weak { .. } | Tracking::Lost(_) => false,
            };
            let fix = frame.predicted_body.map(|predicted_body| VehicleFix {
                node: n,
                node_from_camera: r.reference_from_camera,
                predicted_body,
                stamp: frame.stamp,
            });
            if placed_on(self.config.keyframe_min_inliers) {
                r.trusted = fix;
            }
            if placed_on(self.config.vehicle_check_inliers) {
                r.checked = fix;
            }
            r.track.push((frame.stamp, n, r.reference_from_camera));
        }
        self.schedule();
        Ok(report)
    }

    /// A robot's frame registered on its previous frame: how its body moved in between, if
    /// the two share enough and the motion is one a frame allows.
    fn frame_odometry(&self, k: usize, stamp: f64, observation: &Observation) -> Option<Odometry> {
        let r = &self.robots[k];
        // Lost from a map it has; one that never started has nothing to fly back to.
        r.reference?;
        let (since, previous, _) = r.last_frame.as_ref()?;
        let gap = stamp - since;
        if !(gap > 0.0 && gap <= self.config.odometry_max_gap) {
            return None;
        }
        // Matched without a guess: matching near where a guess puts each feature finds a wall's
        // repeated pattern one block off as readily as the same spot, and a guess of no motion
        // then measures none (seen in SITL: a drone drifting at 0.8 m/s "held still" for 6 s).
        let body_from_camera = r.setup.body_from_camera;
        let seed = r.frames as u64 ^ ((k as u64) << 40) ^ 0x0d0;
        let reg = register(previous, observation, None, &self.config.frontend, seed).ok()?;
        let motion = reg.reference_from_frame;
        let plausible = reg.inliers >= self.config.odometry_min_inliers
            && motion.translation.vector.norm() <= self.config.max_frame_translation
            && motion.rotation.angle() <= self.config.max_frame_rotation;
        plausible.then(|| Odometry {
            since: *since,
            previous_from_body: body_from_camera * motion * body_from_camera.inverse(),
            inliers: reg.inliers,
        })
    }

    /// Waits for the background optimiser and the map rebuild to catch up (end of a run).
    pub fn finish(&mut self) {
        for _ in 0..20 {
            self.schedule();
            if !self.in_flight {
                break;
            }
            if let Some(w) = &self.worker
                && let Ok(done) = w.done.recv()
            {
                self.in_flight = false;
                self.apply(done);
            } else {
                self.in_flight = false;
            }
        }
        loop {
            let nodes = &self.nodes;
            let status = self.map.finish(|n| node_cloud(nodes, n));
            if status != RebuildStatus::SwappedStale {
                break;
            }
            self.rebuild_map();
        }
    }

    /// Whether `a_from_b` is within `scale` times the keyframe spacing.
    fn near_view(&self, a_from_b: &Isometry3<f64>, scale: f64) -> bool {
        a_from_b.translation.vector.norm() <= scale * self.config.keyframe_translation
            && a_from_b.rotation.angle() <= scale * self.config.keyframe_rotation
    }

    /// The cell of the known-pose keyframe index a camera position falls in (cells as wide as
    /// the reach of [`KNOWN_VIEW_REUSE`]).
    fn view_cell(&self, pose: &Isometry3<f64>) -> [i64; 3] {
        let size = (KNOWN_VIEW_REUSE * self.config.keyframe_translation).max(1e-3);
        let v = pose.translation.vector / size;
        [v.x, v.y, v.z].map(|c| c.floor() as i64)
    }

    /// Mapping only: the frame's known pose; a keyframe when it moved far enough from its
    /// reference and no keyframe (of any robot) already holds this view (is within
    /// [`KNOWN_VIEW_REUSE`] times the spacing). Flying again through mapped space then adds
    /// nothing, so the SLAM's memory grows with the building, not with the flight time.
    fn place_known(&mut self, frame: &Frame, pose: Isometry3<f64>) -> FrameReport {
        let k = frame.robot;
        let reference = self.robots[k].reference;
        let relative = reference.map(|n| self.nodes[n].pose.inverse() * pose);
        let moved = relative.is_none_or(|d| !self.near_view(&d, 1.0));
        let mut keyframe = None;
        if moved {
            let cell = self.view_cell(&pose);
            let existing = (-1..=1)
                .flat_map(|i| (-1..=1).flat_map(move |j| (-1..=1).map(move |l| [i, j, l])))
                .filter_map(|[i, j, l]| self.views.get(&[cell[0] + i, cell[1] + j, cell[2] + l]))
                .flatten()
                .copied()
                .find(|&n| {
                    let d = self.nodes[n].pose.inverse() * pose;
                    Some(n) != reference && self.near_view(&d, KNOWN_VIEW_REUSE)
                });
            let n = match existing {
                Some(n) => n,
                None => {
                    let empty = Arc::new(Observation::empty(frame.camera));
                    let n = self.add_node(frame, empty, pose, reference);
                    self.views.entry(cell).or_default().push(n);
                    keyframe = Some(n);
                    n
                }
            };
            self.robots[k].reference = Some(n);
            self.robots[k].reference_from_camera = self.nodes[n].pose.inverse() * pose;
        } else if let Some(d) = relative {
            self.robots[k].reference_from_camera = d;
        }
        self.robots[k].state = RobotState::Tracking;
        FrameReport {
            tracking: if reference.is_none() {
                Tracking::Started
            } else {
                Tracking::Known
            },
            keyframe,
            loop_closures: 0,
            merged: None,
            odometry: None,
        }
    }

    /// The robot's first keyframe, at its start.
    fn start(&mut self, frame: &Frame, observation: Arc<Observation>) -> FrameReport {
        let k = frame.robot;
        if observation.len() < self.config.frontend.min_features {
            return lost(format!(
                "{} features with depth (at least {} needed) to start",
                observation.len(),
                self.config.frontend.min_features
            ));
        }
        let r = &self.robots[k];
        let start_body = r.setup.start.unwrap_or_else(|| {
            // An own frame: level on the floor at the origin, facing the IMU's heading.
            Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_euler_angles(0.0, 0.0, frame.heading.unwrap_or(0.0)),
            )
        });
        let pose = start_body * r.setup.body_from_camera;
        let n = self.add_node(frame, observation, pose, None);
        self.priors.push(Prior {
            node: n,
            z: pose,
            info: isotropic_info(1e-3, 1e-3),
            start: true,
            alive: true,
        });
        let r = &mut self.robots[k];
        r.state = RobotState::Tracking;
        r.reference = Some(n);
        r.reference_from_camera = Isometry3::identity();
        FrameReport {
            tracking: Tracking::Started,
            keyframe: Some(n),
            loop_closures: 0,
            merged: None,
            odometry: None,
        }
    }

    /// Why a camera pose cannot be the robot's, if it cannot: it puts the body further above or
    /// below the height the vehicle's filter predicts (or, without a prediction, its
    /// rangefinder reads) than [`SlamConfig::max_height_disagreement`], or tilts it further from
    /// the roll and pitch its IMU reads than [`SlamConfig::max_tilt_disagreement`].
    fn implausible(&self, frame: &Frame, map_from_camera: &Isometry3<f64>) -> Option<String> {
        let camera_from_body = self.robots[frame.robot].setup.body_from_camera.inverse();
        let map_from_body = map_from_camera * camera_from_body;
        let expected = frame
            .predicted_body
            .map(|b| b.translation.vector.z)
            .or(frame.height);
        if let Some(expected) = expected {
            let off = map_from_body.translation.vector.z - expected;
            if off.abs() > self.config.max_height_disagreement {
                return Some(format!("{off:+.2} m off the predicted height"));
            }
        }
        let [roll, pitch] = frame.tilt?;
        // Gravity in the body as the pose has it and as the IMU reads it (yaw plays no part).
        let up_in_body = map_from_body.rotation.inverse() * Vector3::z();
        let up_in_body_imu =
            UnitQuaternion::from_euler_angles(roll, pitch, 0.0).inverse() * Vector3::z();
        let angle = up_in_body.angle(&up_in_body_imu);
        (angle > self.config.max_tilt_disagreement)
            .then(|| format!("tilted {:.0}° from the IMU's gravity", angle.to_degrees()))
    }

    /// How far (metres, radians) from the prediction a lost robot may be relocalised: within
    /// [`SlamConfig::relocalisation_gate`], narrowed to how far it can have gone since it was
    /// last placed and to the prediction's own uncertainty.
    fn relocalisation_gate(&self, frame: &Frame) -> (f64, f64) {
        let c = &self.config;
        let (max_t, max_r) = c.relocalisation_gate;
        let since_placed = self.robots[frame.robot]
            .track
            .last()
            .map(|&(placed, _, _)| {
                c.relocalisation_gate_min_m
                    + c.relocalisation_drift_mps * (frame.stamp - placed).max(0.0)
            });
        let unsure = frame
            .predicted_sigma_m
            .filter(|s| s.is_finite() && frame.predicted_body.is_some())
            .map(|sigma| c.relocalisation_gate_sigmas * sigma);
        let reach = [since_placed, unsure]
            .into_iter()
            .flatten()
            .fold(max_t, f64::min);
        (reach.max(c.relocalisation_gate_min_m), max_r)
    }

    fn track(&mut self, frame: &Frame, observation: Arc<Observation>) -> FrameReport {
        let k = frame.robot;
        let r = &self.robots[k];
        let Some(reference) = r.reference else {
            return lost("no reference keyframe".into());
        };
        let tracking = r.state == RobotState::Tracking;
        let last_pose = self.nodes[reference].pose * r.reference_from_camera;
        let camera_from_body = r.setup.body_from_camera.inverse();
        let predicted = if tracking {
            Some(r.velocity.map_or(last_pose, |v| last_pose * v))
        } else {
            // Lost: the caller's prediction, else where the robot was last seen, turned to the
            // heading its IMU reads now, turning or not (a hovering robot turns more than it
            // moves).
            let body_from_camera = r.setup.body_from_camera;
            frame
                .predicted_body
                .map(|b| b * body_from_camera)
                .or_else(|| {
                    frame.heading.or(frame.turning_heading).map(|psi| {
                        let turn = wrap(psi - body_yaw(&last_pose, &camera_from_body));
                        let about_z = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn);
                        Isometry3::from_parts(last_pose.translation, about_z * last_pose.rotation)
                    })
                })
        };
        let frontend = &self.config.frontend;
        let seed = r.frames as u64 ^ ((k as u64) << 40);
        // 1. The reference keyframe, then the previous frame.
        let mut found: Option<(Option<usize>, Registration)> = None;
        let mut why = String::new();
        if tracking {
            let guess = predicted.map(|p| self.nodes[reference].pose.inverse() * p);
            match register(
                &self.nodes[reference].observation,
                &observation,
                guess.as_ref(),
                frontend,
                seed,
            ) {
                Ok(reg) => found = Some((Some(reference), reg)),
                Err(e) => why = format!("keyframe: {e}"),
            }
            if found.is_none()
                && let Some(p) = &r.previous
            {
                let prev_pose = self.nodes[p.reference].pose * p.reference_from_camera;
                let guess = predicted.map(|q| prev_pose.inverse() * q);
                match register(&p.observation, &observation, guess.as_ref(), frontend, seed) {
                    Ok(reg) => {
                        let via = Registration {
                            reference_from_frame: p.reference_from_camera
                                * reg.reference_from_frame,
                            ..reg
                        };
                        found = Some((None, via));
                    }
                    Err(e) => add_reason(&mut why, format!("previous frame: {e}")),
                }
            }
            if found.is_none()
                && let Some(p) = predicted
            {
                let guess = self.nodes[reference].pose.inverse() * p;
                let local = self.local_map(reference, &p).map(Arc::new);
                if let Some(local) = &local {
                    match register(local, &observation, Some(&guess), frontend, seed) {
                        Ok(reg) => found = Some((Some(reference), reg)),
                        Err(e) => add_reason(&mut why, format!("local map: {e}")),
                    }
                }
                // The map's points by projection, on pixels where the frame has no depth (a
                // wall beyond the depth camera's range or nearer than its minimum), around the
                // keyframe looking most nearly the predicted way: no keyframe is made without
                // depth, so the reference falls behind while the camera turns.
                if found.is_none() {
                    let axis = |pose: &Isometry3<f64>| pose.rotation * Vector3::z();
                    let base = self
                        .keyframes_near(
                            self.nodes[reference].frame,
                            &p,
                            self.config.local_map_radius,
                            std::f64::consts::FRAC_PI_4,
                        )
                        .into_iter()
                        .min_by(|&a, &b| {
                            let off = |n: usize| axis(&self.nodes[n].pose).angle(&axis(&p));
                            off(a).total_cmp(&off(b))
                        })
                        .unwrap_or(reference);
                    let local = if base == reference {
                        local
                    } else {
                        self.local_map(base, &p).map(Arc::new)
                    };
                    let against = local.unwrap_or_else(|| self.nodes[base].observation.clone());
                    let guess = self.nodes[base].pose.inverse() * p;
                    match track_by_projection(&against, &observation, &guess, frontend) {
                        Ok(reg) => found = Some((Some(base), reg)),
                        Err(e) => add_reason(&mut why, format!("by projection: {e}")),
                    }
                }
            }
            if let Some((_, reg)) = &found {
                let base = match found.as_ref().and_then(|(n, _)| *n) {
                    Some(n) => self.nodes[n].pose,
                    None => self.nodes[r.previous.as_ref().map_or(reference, |p| p.reference)].pose,
                };
                let motion = last_pose.inverse() * (base * reg.reference_from_frame);
                let (t, a) = (motion.translation.vector.norm(), motion.rotation.angle());
                if t > self.config.max_frame_translation || a > self.config.max_frame_rotation {
                    why = format!(
                        "implausible motion ({t:.2} m, {:.0}°) rejected",
                        a.to_degrees()
                    );
                    found = None;
                } else if let Some(off) =
                    self.implausible(frame, &(base * reg.reference_from_frame))
                {
                    why = format!("registration {off}: rejected");
                    found = None;
                }
            }
        }
        // 2. Relocalisation (or a reference slipping away): nearby and look-alike keyframes.
        let mut relocalised = None;
        if found.is_none() {
            let around = predicted.unwrap_or(last_pose);
            let wide = FrontendConfig {
                search_radius_px: self.config.relocalisation_search_px,
                ..frontend.clone()
            };
            // A vehicle with nothing to check a match against needs a stronger one.
            let needed = if predicted.is_none() && self.robots[k].has_imu {
                self.config.relocalisation_min_inliers_unpredicted
            } else {
                self.config.relocalisation_min_inliers
            };
            // Lost with a prediction: first the local map around the last reference, then
            // keyframe by keyframe.
            let local = predicted
                .filter(|_| !tracking)
                .and_then(|p| self.local_map(reference, &p))
                .map(|o| (reference, Arc::new(o)));
            let candidates = self
                .relocalisation_candidates(k, &around, &observation)
                .into_iter()
                .map(|n| (n, self.nodes[n].observation.clone()));
            for (n, against) in local.into_iter().chain(candidates) {
                let guess = predicted.map(|p| self.nodes[n].pose.inverse() * p);
                // A frame without the features with depth to register on its own is placed
                // by projection from the prediction, when there is one.
                let registered = match (
                    register(&against, &observation, guess.as_ref(), &wide, seed),
                    &guess,
                ) {
                    (Err(RegistrationError::TooFewFeatures { .. }), Some(g))
                        if observation.len() < frontend.min_features =>
                    {
                        track_by_projection(&against, &observation, g, &wide)
                    }
                    (registered, _) => registered,
                };
                match registered {
                    Ok(reg) if reg.inliers >= needed => {
                        let pose = self.nodes[n].pose * reg.reference_from_frame;
                        // A registration far from a good prediction is a wrong match. While
                        // tracking, the prediction is the last frame's motion carried on: a
                        // match implying more motion than a frame allows is as implausible
                        // here as against the reference (seen: a one-frame jump of 1 m taken
                        // from a look-alike keyframe became a keyframe and bent the walls).
                        let (max_t, max_r) = if tracking {
                            (
                                self.config.max_frame_translation,
                                self.config.max_frame_rotation,
                            )
                        } else {
                            self.relocalisation_gate(frame)
                        };
                        // How far from the prediction (metres, radians).
                        let (off_t, off_r) = predicted.map_or((0.0, 0.0), |p| {
                            let d = p.inverse() * pose;
                            (d.translation.vector.norm(), d.rotation.angle())
                        });
                        // How far from the IMU's heading, radians.
                        let off_heading =
                            frame.heading.or(frame.turning_heading).map_or(0.0, |psi| {
                                wrap(body_yaw(&pose, &camera_from_body) - psi).abs()
                            });
                        let max_heading = self.config.relocalisation_heading_gate;
                        match self.implausible(frame, &pose) {
                            None if off_heading > max_heading => add_reason(
                                &mut why,
                                format!(
                                    "keyframe {n}: facing {:.0}° from the IMU's heading \
                                     (gate {:.0}°)",
                                    off_heading.to_degrees(),
                                    max_heading.to_degrees()
                                ),
                            ),
                            None if off_t < max_t && off_r < max_r => {
                                found = Some((Some(n), reg));
                                relocalised = Some(n);
                                break;
                            }
                            None => add_reason(
                                &mut why,
                                format!(
                                    "keyframe {n}: {off_t:.2} m, {:.0}° from the prediction \
                                     (gate {max_t:.2} m, {:.0}°)",
                                    off_r.to_degrees(),
                                    max_r.to_degrees()
                                ),
                            ),
                            Some(off) => add_reason(&mut why, format!("keyframe {n}: {off}")),
                        }
                    }
                    Ok(reg) => add_reason(
                        &mut why,
                        format!("keyframe {n}: only {} inliers", reg.inliers),
                    ),
                    Err(e) => add_reason(&mut why, format!("keyframe {n}: {e}")),
                }
            }
        }
        let Some((matched, reg)) = found else {
            return lost(if why.is_empty() {
                "no keyframe to relocalise against".into()
            } else {
                why
            });
        };
        // The new pose, relative to a keyframe.
        let r = &mut self.robots[k];
        let (anchor, anchor_from_camera) = match matched {
            Some(n) => (n, reg.reference_from_frame),
            None => {
                let p = r.previous.as_ref().map_or(reference, |p| p.reference);
                (p, reg.reference_from_frame)
            }
        };
        let pose = self.nodes[anchor].pose * anchor_from_camera;
        r.projection_frames += usize::from(reg.without_depth > 0);
        // On a vehicle (a caller that predicts the body, i.e. has a filter to fly on between
        // fixes, or a robot with an IMU), a weak registration that disagrees with the motion so
        // far gives this frame its pose but nothing to build on: it becomes neither the next
        // frame's reference nor a keyframe, nor the motion the next frame is predicted with (a
        // fit on a dozen inliers can be degrees off, and a keyframe would keep that error in
        // the map for good). One that agrees carries tracking through a bare stretch. A hand-held camera moves in jerks
        // that no constant-velocity model follows; there every registration is built on. The
        // next frame is still predicted from the weak pose: tried from where the motion before
        // it carried the camera instead, drones were lost two to three times as often (stop
        // 49's batches in docs/exploration-history.md). A registration on features without
        // depth is held to the motion so far however many inliers it has, within
        // [`SlamConfig::projection_agreement`]: pixels alone hold a translation loosely, and
        // each such pose carried on as the motion predicts the next (in the synthetic test of
        // it, without this check, a pose slid 0.5 m from the truth in three frames).
        let agrees = |p: &Isometry3<f64>, (max_t, max_r): (f64, f64)| {
            let d = p.inverse() * pose;
            d.translation.vector.norm() <= max_t && d.rotation.angle() <= max_r
        };
        // How far (metres, horizontally) the body's move since the last trusted frame is from
        // the move the vehicle predicts over the same time.
        let off_from = |then: &VehicleFix| {
            frame
                .predicted_body
                .filter(|_| tracking)
                .map_or(0.0, |now| {
                    let body_then =
                        self.nodes[then.node].pose * then.node_from_camera * camera_from_body;
                    let body_now = pose * camera_from_body;
                    let slam_moved = body_now.translation.vector - body_then.translation.vector;
                    let vehicle_moved =
                        now.translation.vector - then.predicted_body.translation.vector;
                    (slam_moved - vehicle_moved).xy().norm()
                })
        };
        let off_vehicle = r.trusted.as_ref().map_or(0.0, off_from);
        // The same from the last frame on enough inliers to check others by, while it is
        // recent, less the drift the vehicle's prediction may have gathered since.
        let off_checked = r
            .checked
            .filter(|c| frame.stamp - c.stamp <= self.config.vehicle_check_s)
            .as_ref()
            .map_or(0.0, |c| {
                off_from(c) - self.config.vehicle_drift_mps * (frame.stamp - c.stamp).max(0.0)
            });
        // A robot with an IMU is a vehicle even when its filter has given up predicting it
        // (too long without a pose to fly on): then nothing can check a registration on few
        // inliers against the vehicle's move, and it is weak whatever the motion so far says.
        // Built on as a hand-held camera's, such registrations slid a drone's pose 1.8 m in
        // 0.8 s in a look around on 12–20 inliers, and the keyframes they made held it 1.3 m
        // off for the rest of its mission (SITL, stop 73): its filter, without fixes through
        // the weak stretch before, had just given up.
        let vehicle = frame.predicted_body.is_some() || r.has_imu;
        let weak = vehicle
            && if reg.without_depth > 0 {
                !predicted.is_some_and(|p| agrees(&p, self.config.projection_agreement))
            } else if reg.inliers < self.config.keyframe_min_inliers {
                !(frame.predicted_body.is_some()
                    && predicted.is_some_and(|p| agrees(&p, self.config.weak_agreement))
                    && off_vehicle <= self.config.vehicle_agreement_m)
            } else {
                reg.inliers < self.config.vehicle_check_inliers
                    && off_checked > self.config.vehicle_agreement_m
            };
        r.weak_frames += usize::from(weak);
        if weak {
            // Which rule held it back: a stretch of these starves the vehicle's filter of fixes
            // even while they are right.
            tracing::debug!(
                robot = k,
                stamp = frame.stamp,
                inliers = reg.inliers,
                without_depth = reg.without_depth,
                off_vehicle_m = off_vehicle,
                off_checked_beyond_drift_m = off_checked,
                since_checked_s = r.checked.map(|c| frame.stamp - c.stamp),
                "weak registration: its frame is placed, nothing is built on it"
            );
        }
        let was_lost = r.state != RobotState::Tracking;
        if !weak {
            r.velocity = (!was_lost).then(|| last_pose.inverse() * pose);
        }
        r.state = RobotState::Tracking;
        r.reference = Some(anchor);
        r.reference_from_camera = anchor_from_camera;
        if !weak {
            r.previous = Some(Previous {
                observation: observation.clone(),
                reference: anchor,
                reference_from_camera: anchor_from_camera,
            });
        }
        let moved = anchor_from_camera.translation.vector.norm() > self.config.keyframe_translation
            || anchor_from_camera.rotation.angle() > self.config.keyframe_rotation;
        let slipping = matched.is_none() || matched != Some(reference);
        let tracking_report = match relocalised {
            _ if weak => Tracking::Weak {
                inliers: reg.inliers,
            },
            Some(n) => Tracking::Relocalised { keyframe: n },
            None => Tracking::Tracked {
                inliers: reg.inliers,
            },
        };
        // A keyframe is the next frames' reference and the map's: it needs features with depth.
        let anchors = observation.len() >= self.config.frontend.min_features;
        if weak || !(moved || slipping) || !anchors {
            return FrameReport {
                tracking: tracking_report,
                keyframe: None,
                loop_closures: 0,
                merged: None,
                odometry: None,
            };
        }
        // A new keyframe, linked to the keyframe it was registered against.
        let n = self.add_node(frame, observation, pose, Some(anchor));
        self.link(
            anchor,
            n,
            &Registration {
                reference_from_frame: anchor_from_camera,
                ..reg
            },
            LinkKind::Odometry,
        );
        let r = &mut self.robots[k];
        r.reference = Some(n);
        r.reference_from_camera = Isometry3::identity();
        if let Some(p) = &mut r.previous {
            p.reference = n;
            p.reference_from_camera = Isometry3::identity();
        }
        self.link_recent(k, n, anchor);
        let loops = self.close_loops(n);
        let merged = self.anchor_frames(n);
        self.add_priors(n, frame);
        if loops > 0 || merged.is_some() {
            self.frames[self.nodes[n].frame].1 = true;
        }
        FrameReport {
            tracking: tracking_report,
            keyframe: Some(n),
            loop_closures: loops,
            merged,
            odometry: None,
        }
    }

    fn add_node(
        &mut self,
        frame: &Frame,
        observation: Arc<Observation>,
        pose: Isometry3<f64>,
        parent: Option<usize>,
    ) -> usize {
        let k = frame.robot;
        let (w, h) = frame.grey.dimensions();
        let cloud = Arc::new(depth_cloud(
            &DepthImage {
                width: w as usize,
                height: h as usize,
                depth: &frame.depth,
                depth_scale: frame.depth_scale,
                intrinsics: [
                    frame.camera.fx,
                    frame.camera.fy,
                    frame.camera.cx,
                    frame.camera.cy,
                ],
            },
            self.config.occupancy.pixel_step,
            self.config.occupancy.max_range,
        ));
        let n = self.nodes.len();
        self.place.add(n, &observation.descriptors);
        let frame_id = self.robots[k].frame;
        let mut kept = cloud.clone();
        if frame_id == 0 {
            self.map.insert(&NodeCloud {
                node: n,
                map_from_camera: pose,
                cloud,
            });
            if self.config.known_poses {
                // Known poses never move: the map never casts this cloud again.
                kept = Arc::default();
            }
        }
        self.nodes.push(Node {
            robot: k,
            stamp: frame.stamp,
            frame: frame_id,
            pose: rigid(pose),
            parent,
            heading: frame.heading,
            observation,
            cloud: kept,
        });
        self.robots[k].nodes.push(n);
        n
    }

    fn link(&mut self, a: usize, b: usize, reg: &Registration, kind: LinkKind) {
        let mut info = match reg
            .information
            .filter(|_| self.config.link_information_scale > 0.0)
        {
            Some(h) => (h * self.config.link_information_scale)
                .transpose()
                .as_slice()
                .to_vec(),
            None => {
                let scale = (100.0 / reg.inliers.max(1) as f64).sqrt().clamp(1.0, 3.0);
                let (st, sr) = self.config.link_sigma;
                isotropic_info(st * scale, sr * scale)
            }
        };
        let (st, sr) = self.config.link_max_sigma;
        for (k, floor) in isotropic_info(st, sr).into_iter().enumerate() {
            info[k] += floor;
        }
        self.links.push(Link {
            a,
            b,
            a_from_b: reg.reference_from_frame,
            info,
            kind,
            alive: true,
        });
    }

    /// Links a new keyframe to the robot's keyframes before its anchor (local constraints).
    fn link_recent(&mut self, k: usize, n: usize, anchor: usize) {
        let recent: Vec<usize> = self.robots[k]
            .nodes
            .iter()
            .rev()
            .copied()
            .filter(|&m| m != n && m != anchor)
            .take(self.config.recent_links)
            .collect();
        for m in recent {
            let guess = self.nodes[m].pose.inverse() * self.nodes[n].pose;
            if let Ok(reg) = register(
                &self.nodes[m].observation,
                &self.nodes[n].observation,
                Some(&guess),
                &self.config.frontend,
                n as u64,
            ) {
                let d = guess.inverse() * reg.reference_from_frame;
                if d.translation.vector.norm() < 0.1 && d.rotation.angle() < 0.1 {
                    self.link(m, n, &reg, LinkKind::Odometry);
                }
            }
        }
    }

    /// Loop closures from keyframe `n` to keyframes of its frame near it; returns how many.
    fn close_loops(&mut self, n: usize) -> usize {
        let node = &self.nodes[n];
        let robot = &self.robots[node.robot];
        let skip: Vec<usize> = robot
            .nodes
            .iter()
            .rev()
            .take(self.config.loop_skip_recent + 1)
            .copied()
            .collect();
        let mut near: Vec<(f64, usize)> = self
            .nodes
            .iter()
            .enumerate()
            .filter(|(m, o)| o.frame == node.frame && !skip.contains(m))
            .filter_map(|(m, o)| {
                loop_candidate_rank(&self.config, &node.pose, &o.pose).map(|rank| (rank, m))
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        let linked: Vec<usize> = self
            .links
            .iter()
            .filter(|l| l.b == n)
            .map(|l| l.a)
            .collect();
        let chosen: Vec<usize> = near
            .into_iter()
            .map(|(_, m)| m)
            .filter(|m| !linked.contains(m))
            .take(self.config.loop_candidates)
            .collect();
        let mut added = 0;
        for m in chosen {
            let estimate = self.nodes[m].pose.inverse() * self.nodes[n].pose;
            let Some(reg) = self.verify(m, n, Some(&estimate)) else {
                continue;
            };
            let correction = estimate.inverse() * reg.reference_from_frame;
            let heading = self.heading_disagreement(m, n, &reg.reference_from_frame);
            match heading {
                HeadingCheck::Disagrees(off) => {
                    tracing::debug!(
                        from = m,
                        to = n,
                        "loop closure rejected: it turns {:.1}° more than the IMU headings",
                        off.to_degrees()
                    );
                    continue;
                }
                HeadingCheck::Missing if reg.inliers < self.config.loop_min_inliers_unchecked => {
                    tracing::debug!(
                        from = m,
                        to = n,
                        inliers = reg.inliers,
                        "loop closure rejected: no IMU headings to check it, too few inliers"
                    );
                    continue;
                }
                _ => {}
            }
            if correction.translation.vector.norm() > self.config.loop_max_correction
                || correction.rotation.angle() > self.config.loop_max_correction_angle
            {
                tracing::debug!(
                    from = m,
                    to = n,
                    "loop closure rejected: it would move the keyframe {:.2} m",
                    correction.translation.vector.norm()
                );
                continue;
            }
            tracing::debug!(
                robots = ?(self.nodes[m].robot, self.nodes[n].robot),
                stamps = ?(self.nodes[m].stamp, self.nodes[n].stamp),
                inliers = reg.inliers,
                ?heading,
                correction_m = correction.translation.vector.norm(),
                correction_deg = correction.rotation.angle().to_degrees(),
                measured = ?(
                    reg.reference_from_frame.translation.vector.as_slice(),
                    reg.reference_from_frame.rotation.scaled_axis().as_slice()
                ),
                "loop closure"
            );
            self.link(m, n, &reg, LinkKind::Loop);
            added += 1;
        }
        added
    }

    /// Whether the body turns between keyframes `m` and `n` by the measured `m_from_n` as
    /// their IMU headings say ([`SlamConfig::loop_max_heading_disagreement`]).
    fn heading_disagreement(&self, m: usize, n: usize, m_from_n: &Isometry3<f64>) -> HeadingCheck {
        let (a, b) = (&self.nodes[m], &self.nodes[n]);
        let Some(gate) = self.config.loop_max_heading_disagreement else {
            return HeadingCheck::Unavailable;
        };
        let (Some(ha), Some(hb)) = (a.heading, b.heading) else {
            let imu = self.robots[a.robot].has_imu && self.robots[b.robot].has_imu;
            return if imu {
                HeadingCheck::Missing
            } else {
                HeadingCheck::Unavailable
            };
        };
        let camera_from_body =
            |node: &Node| self.robots[node.robot].setup.body_from_camera.inverse();
        let measured = body_yaw(&(a.pose * m_from_n), &camera_from_body(b))
            - body_yaw(&a.pose, &camera_from_body(a));
        let off = wrap(measured - (hb - ha));
        if off.abs() > gate {
            HeadingCheck::Disagrees(off)
        } else {
            HeadingCheck::Agrees
        }
    }

    /// Keyframe `n` registered against keyframe `m` (guided by `guess`, m ← n), when the match
    /// has enough inliers for a loop closure or a merge.
    fn verify(&self, m: usize, n: usize, guess: Option<&Isometry3<f64>>) -> Option<Registration> {
        register(
            &self.nodes[m].observation,
            &self.nodes[n].observation,
            guess,
            &self.config.frontend,
            (n as u64) << 20 | m as u64,
        )
        .ok()
        .filter(|reg| reg.inliers >= self.config.loop_min_inliers)
    }

    /// Verifies look-alike keyframes of other coordinate frames; merges two frames once two
    /// matches agree on how they relate. Returns (kept, absorbed) after a merge.
    fn anchor_frames(&mut self, n: usize) -> Option<(usize, usize)> {
        let frame = self.nodes[n].frame;
        let others = self.nodes.iter().any(|o| o.frame != frame);
        if !others || self.config.place_candidates == 0 {
            return None;
        }
        let nodes = &self.nodes;
        let candidates = self.place.query(
            &nodes[n].observation.descriptors,
            self.config.place_candidates,
            |m| nodes[m].frame != frame,
        );
        for (m, _) in candidates {
            let Some(reg) = self.verify(m, n, None) else {
                continue;
            };
            // How the two frames relate, from the match m ← n: F_m ← F_n.
            let m_from_n = reg.reference_from_frame;
            if let HeadingCheck::Disagrees(_) = self.heading_disagreement(m, n, &m_from_n) {
                continue;
            }
            let fm_from_fn = self.nodes[m].pose * m_from_n * self.nodes[n].pose.inverse();
            let fm = self.nodes[m].frame;
            let (kept, absorbed, kept_from_absorbed) = if fm < frame {
                (fm, frame, fm_from_fn)
            } else {
                (frame, fm, fm_from_fn.inverse())
            };
            // Both frames are level with the floor at z = 0: the relation is a turn about z and
            // a horizontal shift; anything else is a wrong match.
            let tilt = (kept_from_absorbed.rotation * Vector3::z()).angle(&Vector3::z());
            if tilt > 10f64.to_radians() || kept_from_absorbed.translation.vector.z.abs() > 0.3 {
                continue;
            }
            let (agree_t, agree_r) = self.config.merge_agreement;
            let votes = self.merge_votes.entry((kept, absorbed)).or_default();
            let agrees = votes.iter().any(|v| {
                let d = v.inverse() * kept_from_absorbed;
                d.translation.vector.norm() < agree_t && d.rotation.angle() < agree_r
            });
            votes.push(kept_from_absorbed);
            if agrees {
                self.merge(kept, absorbed, &kept_from_absorbed);
                self.link(m, n, &reg, LinkKind::Loop);
                return Some((kept, absorbed));
            }
        }
        None
    }

    /// Moves everything of frame `absorbed` into frame `kept`.
    fn merge(&mut self, kept: usize, absorbed: usize, kept_from_absorbed: &Isometry3<f64>) {
        tracing::info!(
            kept,
            absorbed,
            "coordinate frames merged by a verified inter-robot match"
        );
        for node in self.nodes.iter_mut().filter(|n| n.frame == absorbed) {
            node.pose = rigid(kept_from_absorbed * node.pose);
            node.frame = kept;
        }
        let absorbed_robots: Vec<usize> = (0..self.robots.len())
            .filter(|&k| self.robots[k].frame == absorbed)
            .collect();
        for &k in &absorbed_robots {
            self.robots[k].frame = kept;
        }
        for p in self
            .priors
            .iter_mut()
            .filter(|p| p.start && absorbed_robots.contains(&self.nodes[p.node].robot))
        {
            p.alive = false;
        }
        for p in self.priors.iter_mut().filter(|p| !p.start) {
            if self.nodes[p.node].frame == kept
                && absorbed_robots.contains(&self.nodes[p.node].robot)
            {
                // Heading and height priors stay valid (both frames share gravity and heading
                // reference); only their reference pose moves with the node.
                p.z = kept_from_absorbed * p.z;
            }
        }
        for f in [kept, absorbed] {
            self.frames[f].0 += 1;
        }
        self.frames[kept].1 = true;
        self.merge_votes
            .retain(|&(a, b), _| a != absorbed && b != absorbed);
        self.stats.merges += 1;
        if kept == 0 {
            let moved: Vec<NodeCloud> = (0..self.nodes.len())
                .filter(|&n| self.nodes[n].frame == 0)
                .filter_map(|n| node_cloud(&self.nodes, n))
                .collect();
            self.map.rebuild(moved);
        }
    }

    /// The local map of keyframe `reference` for a camera predicted at `predicted`: the
    /// reference's features with those of up to [`SlamConfig::local_map_keyframes`] keyframes
    /// of its map frame (any robot's) whose cameras lie within
    /// [`SlamConfig::local_map_radius`] of the prediction and look within 45° of its way, each
    /// point moved into the reference's camera (its keypoint the point's projection there).
    /// `None` when no other keyframe qualifies.
    fn local_map(&self, reference: usize, predicted: &Isometry3<f64>) -> Option<Observation> {
        if self.config.local_map_keyframes == 0 {
            return None;
        }
        let base = &self.nodes[reference];
        let near: Vec<usize> = self
            .keyframes_near(
                base.frame,
                predicted,
                self.config.local_map_radius,
                std::f64::consts::FRAC_PI_4,
            )
            .into_iter()
            .filter(|&m| m != reference)
            .take(self.config.local_map_keyframes)
            .collect();
        if near.is_empty() {
            return None;
        }
        let mut local = (*base.observation).clone();
        let camera = local.camera;
        let base_from_map = base.pose.inverse();
        for m in near {
            let o = &self.nodes[m].observation;
            let base_from_m = base_from_map * self.nodes[m].pose;
            for ((k, d), p) in o.keypoints.iter().zip(&o.descriptors).zip(&o.points) {
                let q = base_from_m * p;
                if q.z < 0.1 {
                    continue;
                }
                local.keypoints.push(Keypoint {
                    x: (camera.fx * q.x / q.z + camera.cx) as f32,
                    y: (camera.fy * q.y / q.z + camera.cy) as f32,
                    ..*k
                });
                local.descriptors.push(*d);
                local.points.push(q);
            }
        }
        Some(local)
    }

    /// Keyframes of map frame `frame` whose cameras lie within `radius` metres of `camera` and
    /// look within `max_angle` radians of its way, nearest first.
    fn keyframes_near(
        &self,
        frame: usize,
        camera: &Isometry3<f64>,
        radius: f64,
        max_angle: f64,
    ) -> Vec<usize> {
        let here = camera.translation.vector;
        let axis = camera.rotation * Vector3::z();
        let mut near: Vec<(f64, usize)> = self
            .nodes
            .iter()
            .enumerate()
            .filter(|(_, o)| {
                o.frame == frame && (o.pose.rotation * Vector3::z()).angle(&axis) < max_angle
            })
            .map(|(m, o)| ((o.pose.translation.vector - here).norm(), m))
            .filter(|&(d, _)| d < radius)
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        near.into_iter().map(|(_, m)| m).collect()
    }

    /// Candidates to relocalise robot `k` against: its recent keyframes, keyframes of its frame
    /// near `around`, and look-alike keyframes of its frame.
    fn relocalisation_candidates(
        &self,
        k: usize,
        around: &Isometry3<f64>,
        observation: &Observation,
    ) -> Vec<usize> {
        let r = &self.robots[k];
        let limit = self.config.relocalisation_candidates;
        let mut out: Vec<usize> = vec![];
        let push = |n: usize, out: &mut Vec<usize>| {
            if out.len() < limit && !out.contains(&n) {
                out.push(n);
            }
        };
        for &n in r.nodes.iter().rev().take(limit / 3 + 1) {
            push(n, &mut out);
        }
        for n in self
            .keyframes_near(r.frame, around, 3.0, 1.0)
            .into_iter()
            .take(limit / 3 + 1)
        {
            push(n, &mut out);
        }
        let nodes = &self.nodes;
        for (n, _) in self.place.query(&observation.descriptors, limit, |m| {
            nodes[m].frame == r.frame
        }) {
            push(n, &mut out);
        }
        out
    }

    /// Heading, gravity and height priors on a new keyframe, when its vehicle measured them and
    /// they agree with the visual estimate (a yaw spike or a table under the sonar does not).
    fn add_priors(&mut self, n: usize, frame: &Frame) {
        let node = &self.nodes[n];
        let r = &self.robots[node.robot];
        let camera_from_body = r.setup.body_from_camera.inverse();
        let pose = node.pose;
        let up_in_z = |z: &Isometry3<f64>| z.rotation.inverse() * Vector3::z();
        let mut z = pose;
        let mut info = vec![0.0; 36];
        let mut any = false;
        if let (Some(psi), Some(sigma), true) = (
            frame.heading,
            self.config.heading_sigma,
            frame.heading_steady,
        ) {
            let estimate = body_yaw(&pose, &camera_from_body);
            let d = wrap(psi - estimate);
            if d.abs() < self.config.heading_gate {
                z = Isometry3::from_parts(
                    z.translation,
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), d) * z.rotation,
                );
                let a = up_in_z(&z);
                let w = 1.0 / (sigma * sigma);
                for i in 0..3 {
                    for j in 0..3 {
                        info[(3 + i) * 6 + 3 + j] = w * a[i] * a[j];
                    }
                }
                any = true;
            }
        }
        if let (Some([roll, pitch]), Some(sigma)) = (frame.tilt, self.config.tilt_sigma) {
            // The body turned about a level axis until it leans as the IMU reads: the up
            // direction the pose has in the body onto the one the IMU has, yaw kept.
            let map_from_body = z * camera_from_body;
            let up_in_body = map_from_body.rotation.inverse() * Vector3::z();
            let up_in_body_imu =
                UnitQuaternion::from_euler_angles(roll, pitch, 0.0).inverse() * Vector3::z();
            if let Some(lean) = UnitQuaternion::rotation_between(&up_in_body_imu, &up_in_body)
                && lean.angle() < self.config.max_tilt_disagreement
            {
                let body_from_camera = camera_from_body.inverse();
                z.rotation = map_from_body.rotation * lean * body_from_camera.rotation;
                // Information about every turn but the one about the vertical.
                let a = up_in_z(&z);
                let w = 1.0 / (sigma * sigma);
                for i in 0..3 {
                    for j in 0..3 {
                        let level = f64::from(u8::from(i == j)) - a[i] * a[j];
                        info[(3 + i) * 6 + 3 + j] += w * level;
                    }
                }
                any = true;
            }
        }
        if let (Some(height), Some(sigma)) = (frame.height, self.config.height_sigma) {
            // The body's height, as the camera's: z_camera = height − (R · t_camera→body).z.
            let camera_z = height - (pose.rotation * camera_from_body.translation.vector).z;
            if (camera_z - pose.translation.vector.z).abs() < self.config.height_gate {
                z.translation.vector.z = camera_z;
                let a = up_in_z(&z);
                let w = 1.0 / (sigma * sigma);
                for i in 0..3 {
                    for j in 0..3 {
                        info[i * 6 + j] = w * a[i] * a[j];
                    }
                }
                any = true;
            }
        }
        if any {
            self.priors.push(Prior {
                node: n,
                z,
                info,
                start: false,
                alive: true,
            });
            let f = self.nodes[n].frame;
            self.since_optimised[f] += 1;
            if self.since_optimised[f] >= self.config.optimise_every {
                self.frames[f].1 = true;
            }
        }
    }

    /// The optimisation problem of one coordinate frame.
    fn build_job(&self, frame: usize) -> Job {
        let nodes: Vec<usize> = (0..self.nodes.len())
            .filter(|&n| self.nodes[n].frame == frame)
            .collect();
        let mut index = HashMap::with_capacity(nodes.len());
        let mut graph = Graph {
            ids: vec![0],
            poses: vec![Isometry3::identity()],
            edges: vec![],
        };
        for (i, &n) in nodes.iter().enumerate() {
            index.insert(n, i + 1);
            let node = &self.nodes[n];
            let robot = node.robot as u8;
            graph.ids.push(vertex_id(b'a' + robot, (i + 1) as u64));
            graph.poses.push(node.pose);
        }
        let mut loops = vec![];
        for (id, l) in self.links.iter().enumerate() {
            if let (true, Some(&i), Some(&j)) = (l.alive, index.get(&l.a), index.get(&l.b)) {
                if l.kind == LinkKind::Loop {
                    loops.push((graph.edges.len(), id));
                }
                graph.edges.push(Edge {
                    i,
                    j,
                    z: l.a_from_b,
                    info: l.info.clone(),
                });
            }
        }
        for p in self.priors.iter().filter(|p| p.alive) {
            if let Some(&j) = index.get(&p.node) {
                graph.edges.push(Edge {
                    i: 0,
                    j,
                    z: p.z,
                    info: p.info.clone(),
                });
            }
        }
        Job {
            frame,
            epoch: self.frames[frame].0,
            nodes,
            graph,
            loops,
        }
    }

    /// Starts an optimisation of a frame that needs one (inline when not in the background).
    fn schedule(&mut self) {
        if self.in_flight {
            return;
        }
        let Some(f) = (0..self.frames.len()).find(|&f| self.frames[f].1) else {
            return;
        };
        self.frames[f].1 = false;
        self.since_optimised[f] = 0;
        let job = self.build_job(f);
        if job.graph.edges.is_empty() {
            return;
        }
        match &self.worker {
            Some(w) => {
                if w.jobs.send(job).is_ok() {
                    self.in_flight = true;
                }
            }
            None => {
                let done = run_job(job, &self.config.optimiser, self.config.loop_reject_chi2);
                self.apply(done);
            }
        }
    }

    /// Takes a finished optimisation and a finished map rebuild, if any.
    fn poll(&mut self) {
        if let Some(w) = &self.worker {
            match w.done.try_recv() {
                Ok(done) => {
                    self.in_flight = false;
                    self.apply(done);
                }
                Err(TryRecvError::Empty) => {}
                Err(TryRecvError::Disconnected) => self.in_flight = false,
            }
        }
        let nodes = &self.nodes;
        if self.map.poll(|n| node_cloud(nodes, n)) == RebuildStatus::SwappedStale {
            self.rebuild_map();
        }
    }

    /// Applies an optimisation: the optimised keyframes take their new poses, keyframes added
    /// since follow their parents' corrections.
    fn apply(&mut self, done: Done) {
        let (poses, report) = match done.result {
            Ok(r) => r,
            Err(e) => {
                tracing::warn!(frame = done.frame, "pose-graph optimisation failed: {e}");
                return;
            }
        };
        if done.epoch != self.frames[done.frame].0 {
            // A merge changed the frame meanwhile: optimise it again.
            self.frames[done.frame].1 = true;
            return;
        }
        if !done.rejected.is_empty() {
            tracing::info!(
                count = done.rejected.len(),
                "loop closures switched off: they disagree with the rest of the graph"
            );
            for &l in &done.rejected {
                self.links[l].alive = false;
            }
            self.stats.rejected_loop_closures += done.rejected.len();
            self.frames[done.frame].1 = true;
        }
        let mut correction: HashMap<usize, Isometry3<f64>> = HashMap::new();
        let mut largest = (0.0f64, 0.0f64);
        for (i, &n) in done.nodes.iter().enumerate() {
            let new = rigid(poses[i + 1]);
            let c = rigid(new * self.nodes[n].pose.inverse());
            let d = self.nodes[n].pose.inverse() * new;
            largest.0 = largest.0.max(d.translation.vector.norm());
            largest.1 = largest.1.max(d.rotation.angle());
            correction.insert(n, c);
            self.nodes[n].pose = new;
        }
        let first_new = done.nodes.last().map_or(0, |&n| n + 1);
        for n in first_new..self.nodes.len() {
            if self.nodes[n].frame != done.frame {
                continue;
            }
            let c = self.nodes[n]
                .parent
                .and_then(|p| correction.get(&p).copied())
                .unwrap_or_else(Isometry3::identity);
            self.nodes[n].pose = rigid(c * self.nodes[n].pose);
            correction.insert(n, c);
        }
        self.stats.optimisations += 1;
        self.stats.last_optimisation_s = report.time_s;
        tracing::debug!(
            frame = done.frame,
            keyframes = done.nodes.len(),
            cost = ?(report.initial_cost, report.final_cost),
            iterations = report.iterations,
            moved_m = largest.0,
            turned_deg = largest.1.to_degrees(),
            "optimisation applied"
        );
        if done.frame == 0
            && (largest.0 > self.config.rebuild_translation
                || largest.1 > self.config.rebuild_rotation)
        {
            self.rebuild_map();
        }
    }

    fn rebuild_map(&mut self) {
        let nodes: Vec<NodeCloud> = (0..self.nodes.len())
            .filter(|&n| self.nodes[n].frame == 0)
            .filter_map(|n| node_cloud(&self.nodes, n))
            .collect();
        self.map.rebuild(nodes);
    }
}

fn node_cloud(nodes: &[Node], n: usize) -> Option<NodeCloud> {
    nodes
        .get(n)
        .filter(|node| node.frame == 0)
        .map(|node| NodeCloud {
            node: n,
            map_from_camera: node.pose,
            cloud: node.cloud.clone(),
        })
}

/// Appends one more reason a frame could not be placed.
fn add_reason(why: &mut String, reason: String) {
    if !why.is_empty() {
        why.push_str("; ");
    }
    why.push_str(&reason);
}

fn lost(why: String) -> FrameReport {
    FrameReport {
        tracking: Tracking::Lost(why),
        keyframe: None,
        loop_closures: 0,
        merged: None,
        odometry: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::Descriptor;
    use nalgebra::{Matrix6, Point3, Translation3};

    #[test]
    fn loop_closure_candidates_looking_the_same_way_come_before_nearer_ones_looking_away() {
        // A drone turning on the spot: its keyframes all lie within centimetres of each
        // other, and those whose view overlaps the new one's are the ones to try first.
        let config = SlamConfig::default();
        // Cameras look along their z axis; turning about the camera's y axis turns the view.
        let looking = |x: f64, degrees: f64| {
            Isometry3::new(
                Vector3::new(x, 0.0, 0.0),
                Vector3::y() * degrees.to_radians(),
            )
        };
        let new = looking(0.0, 0.0);
        let rank = |x, degrees| loop_candidate_rank(&config, &new, &looking(x, degrees));
        let within = |x, degrees| rank(x, degrees).expect("within reach");
        let same_way = within(0.3, 2.0);
        let turned_away = within(0.02, 40.0);
        assert!(same_way < turned_away, "{same_way} against {turned_away}");
        assert!(within(0.05, 10.0) < within(0.05, 20.0));
        assert!(within(0.1, 0.0) < within(1.0, 0.0));
        assert_eq!(rank(0.0, 55.0), None, "looks too far away");
        assert_eq!(rank(2.5, 0.0), None, "too far away");
    }

    #[test]
    fn a_link_from_a_degenerate_registration_still_holds_every_direction() {
        // A registration whose Hessian is singular (a bare wall: nothing along it): the link
        // is still at least as certain as `link_max_sigma` in every direction.
        let config = SlamConfig::default();
        let (st, sr) = config.link_max_sigma;
        let mut slam = Slam::new(
            config,
            vec![RobotSetup {
                body_from_camera: Isometry3::identity(),
                start: None,
            }],
        );
        let degenerate = Registration {
            reference_from_frame: Isometry3::identity(),
            inliers: 30,
            rms_px: 0.5,
            information: Some(Matrix6::zeros()),
            without_depth: 0,
        };
        slam.link(0, 1, &degenerate, LinkKind::Odometry);
        let info = Matrix6::from_row_slice(&slam.links[0].info);
        let weakest = info.symmetric_eigenvalues().min();
        assert!(weakest >= st.powi(-2).min(sr.powi(-2)) * 0.999, "{info}");
    }

    #[test]
    fn keyframes_added_while_optimisations_run_keep_rigid_poses() {
        // A robot adds a keyframe while each optimisation runs; the optimisation moves the
        // keyframes it had a little, and the new one follows its parent's correction. That
        // correction (new · old⁻¹) once carried its parent's rounding error of the rotation's
        // norm three times over into the new keyframe: after a few dozen in a row (SITL, two
        // drones) the "rotations" stretched vectors by 20 % and keyframes jumped metres.
        let mut slam = Slam::new(
            SlamConfig {
                background: false,
                ..SlamConfig::default()
            },
            vec![RobotSetup {
                body_from_camera: Isometry3::identity(),
                start: None,
            }],
        );
        let observation = Arc::new(Observation::empty(crate::dataset::Pinhole::TUM_FR1));
        let node = |pose, parent| Node {
            robot: 0,
            stamp: 0.0,
            frame: 0,
            pose,
            parent,
            heading: None,
            observation: observation.clone(),
            cloud: Arc::default(),
        };
        let step = Isometry3::new(
            Vector3::new(0.15, 0.01, 0.02),
            Vector3::new(0.01, 0.02, 0.2),
        );
        let nudge = Isometry3::new(
            Vector3::new(0.003, -0.002, 0.001),
            Vector3::new(0.001, -0.002, 0.003),
        );
        slam.nodes.push(node(
            Isometry3::new(Vector3::new(12.0, 4.0, 1.0), Vector3::new(1.2, -1.1, 1.3)),
            None,
        ));
        for k in 1..60 {
            slam.nodes
                .push(node(slam.nodes[k - 1].pose * step, Some(k - 1)));
            let nodes: Vec<usize> = (0..k).collect();
            let mut poses = vec![Isometry3::identity()];
            poses.extend(nodes.iter().map(|&n| slam.nodes[n].pose * nudge));
            let report = Report {
                initial_cost: 1.0,
                final_cost: 1.0,
                rejected_edges: 0,
                iterations: 1,
                time_s: 0.0,
            };
            slam.apply(Done {
                frame: 0,
                epoch: slam.frames[0].0,
                nodes,
                result: Ok((poses, report)),
                rejected: vec![],
            });
        }
        for (k, n) in slam.nodes.iter().enumerate() {
            let norm = n.pose.rotation.quaternion().norm();
            assert!((norm - 1.0).abs() < 1e-9, "keyframe {k}: |q| = {norm}");
        }
        for k in 1..slam.nodes.len() {
            let gap = (slam.nodes[k].pose.translation.vector
                - slam.nodes[k - 1].pose.translation.vector)
                .norm();
            assert!(
                gap < 0.3,
                "keyframes {} and {k} are {gap:.2} m apart",
                k - 1
            );
        }
    }

    #[test]
    fn a_keyframe_is_held_level_by_the_gravity_its_imu_reads() {
        // A camera looking along the body's x (optical z forward, image y down), the keyframe
        // leaning 4° nose-down where the IMU reads the body level: the prior puts it level,
        // keeps its yaw, and says nothing about the turn about the vertical. 10° off is past
        // the check of `max_tilt_disagreement`: no prior.
        let body_from_camera = Isometry3::from_parts(
            Translation3::new(0.1, 0.0, 0.0),
            UnitQuaternion::from_basis_unchecked(&[-Vector3::y(), -Vector3::z(), Vector3::x()]),
        );
        let config = SlamConfig::default();
        let sigma = config.tilt_sigma.expect("a gravity prior by default");
        let mut slam = Slam::new(
            config,
            vec![RobotSetup {
                body_from_camera,
                start: None,
            }],
        );
        let frame = Frame {
            tilt: Some([0.0, 0.0]),
            ..bare_frame(0.0)
        };
        let observation = Arc::new(Observation::empty(crate::dataset::Pinhole::TUM_FR1));
        let yaw = 0.7;
        let leaning = |degrees: f64| {
            let map_from_body = Isometry3::from_parts(
                Translation3::new(2.0, 3.0, 1.0),
                UnitQuaternion::from_euler_angles(0.0, degrees.to_radians(), yaw),
            );
            map_from_body * body_from_camera
        };
        for (n, degrees) in [4.0, 10.0].into_iter().enumerate() {
            slam.nodes.push(Node {
                robot: 0,
                stamp: 0.0,
                frame: 0,
                pose: leaning(degrees),
                parent: None,
                heading: None,
                observation: observation.clone(),
                cloud: Arc::default(),
            });
            slam.add_priors(n, &frame);
        }
        assert_eq!(slam.priors.len(), 1, "10° off the IMU is no prior");
        let prior = &slam.priors[0];
        assert_eq!(prior.node, 0);
        let map_from_body = prior.z * body_from_camera.inverse();
        let (roll, pitch, prior_yaw) = map_from_body.rotation.euler_angles();
        assert!(roll.abs() < 1e-9 && pitch.abs() < 1e-9, "{roll} {pitch}");
        assert!((prior_yaw - yaw).abs() < 1e-9, "{prior_yaw}");
        // The information in the camera's frame: none about the vertical, 1/σ² about the two
        // level axes.
        let info = Matrix6::from_row_slice(&prior.info);
        let rotation = info.fixed_view::<3, 3>(3, 3);
        let up = prior.z.rotation.inverse() * Vector3::z();
        let level = up.cross(&Vector3::x()).normalize();
        let w = sigma.powi(-2);
        assert!((rotation * up).norm() < 1e-9 * w, "{rotation}");
        assert!(
            (level.dot(&(rotation * level)) - w).abs() < 1e-9 * w,
            "{rotation}"
        );
        assert!(
            info.fixed_view::<3, 3>(0, 0).norm() == 0.0,
            "no height measured"
        );
    }

    /// A deterministic stream of random 64-bit words (Knuth's MMIX LCG) from `seed`, for
    /// descriptors.
    fn random_bits(mut seed: u64) -> impl FnMut() -> u64 {
        move || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            seed
        }
    }

    /// A frame of robot 0 at `stamp` with nothing measured: the tests that call the tracker
    /// directly give it what they need (its observation comes separately).
    fn bare_frame(stamp: f64) -> Frame {
        Frame::images_only(
            0,
            stamp,
            image::GrayImage::new(1, 1),
            vec![0],
            0.001,
            crate::dataset::Pinhole::TUM_FR1,
        )
    }

    /// A vehicle's camera 10 cm ahead of and 5 cm above its body's centre, looking along the
    /// body's x (optical z forward, x right, y down).
    fn forward_camera() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.1, 0.0, 0.05),
            UnitQuaternion::from_matrix(&nalgebra::Matrix3::new(
                0.0, 0.0, 1.0, //
                -1.0, 0.0, 0.0, //
                0.0, -1.0, 0.0,
            )),
        )
    }

    /// `n` textured points (rows of ten) on a wall 2–2.3 m ahead along x, from 1 m left to
    /// 0.8 m right, from 0.3 m up, each with a random descriptor drawn from `bits`.
    fn textured_wall(n: u32, bits: &mut impl FnMut() -> u64) -> Vec<(Point3<f64>, Descriptor)> {
        (0..n)
            .map(|i| {
                let (row, col) = (f64::from(i / 10), f64::from(i % 10));
                (
                    Point3::new(2.0 + 0.1 * (col % 4.0), 1.0 - 0.2 * col, 0.3 + 0.15 * row),
                    [bits(), bits(), bits(), bits()],
                )
            })
            .collect()
    }

    /// What a camera at `map_from_camera` sees of `scene` (map points with their
    /// descriptors): each point in its optical frame, its keypoint the point's projection.
    fn seen(scene: &[(Point3<f64>, Descriptor)], map_from_camera: &Isometry3<f64>) -> Observation {
        let camera = crate::dataset::Pinhole::TUM_FR1;
        let mut o = Observation::empty(camera);
        for (p, d) in scene {
            let q = map_from_camera.inverse_transform_point(p);
            let (u, v) = (
                camera.fx * q.x / q.z + camera.cx,
                camera.fy * q.y / q.z + camera.cy,
            );
            if q.z < 0.3 || !(20.0..620.0).contains(&u) || !(20.0..460.0).contains(&v) {
                continue;
            }
            o.keypoints.push(Keypoint {
                x: u as f32,
                y: v as f32,
                angle: 0.0,
                score: 1.0,
            });
            o.descriptors.push(*d);
            o.points.push(q);
        }
        o
    }

    #[test]
    fn a_frame_that_shares_too_little_with_its_reference_registers_on_the_local_map() {
        // Two walls of features 2 m ahead: keyframe A sees the left one, B (1 m to its right,
        // looking the same way) the right one. A frame between them sees 10 points of each:
        // too few to register on A alone, enough on A's local map, which holds B's points
        // moved into A's camera. Keyframes looking back, in another map frame or far away are
        // left out.
        let mut bits = random_bits(7);
        // Camera optical axes along the map's x (looking "ahead"), y to the right is -y map.
        let look = |x: f64, y: f64| {
            Isometry3::from_parts(
                Translation3::new(x, y, 1.0),
                UnitQuaternion::from_matrix(&nalgebra::Matrix3::new(
                    0.0, 0.0, 1.0, //
                    -1.0, 0.0, 0.0, //
                    0.0, -1.0, 0.0,
                )),
            )
        };
        let wall = |y0: f64, bits: &mut dyn FnMut() -> u64| -> Vec<(Point3<f64>, Descriptor)> {
            (0..40)
                .map(|i| {
                    let (row, col) = (f64::from(i / 8), f64::from(i % 8));
                    (
                        Point3::new(3.0 + 0.1 * (col % 3.0), y0 - 0.08 * col, 0.6 + 0.15 * row),
                        [bits(), bits(), bits(), bits()],
                    )
                })
                .collect()
        };
        let left = wall(0.9, &mut bits);
        let right = wall(-0.4, &mut bits);
        let (a, b) = (look(0.0, 0.0), look(0.0, -1.0));
        let observation_a = Arc::new(seen(&left, &a));
        let observation_b = Arc::new(seen(&right, &b));
        assert!(observation_a.len() >= 30 && observation_b.len() >= 30);
        let mut slam = Slam::new(
            SlamConfig::default(),
            vec![RobotSetup {
                body_from_camera: Isometry3::identity(),
                start: None,
            }],
        );
        let node = |pose, frame, observation: &Arc<Observation>| Node {
            robot: 0,
            stamp: 0.0,
            frame,
            pose,
            parent: None,
            heading: None,
            observation: observation.clone(),
            cloud: Arc::default(),
        };
        let back = a * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
        slam.nodes.push(node(a, 0, &observation_a));
        slam.nodes.push(node(b, 0, &observation_b));
        slam.nodes.push(node(back, 0, &observation_b));
        slam.nodes.push(node(b, 1, &observation_b));
        slam.nodes.push(node(look(6.0, -1.0), 0, &observation_b));
        // The frame: 10 points of each wall, and 15 it alone sees.
        let f = look(0.1, -0.5);
        let mut scene: Vec<_> = left[..10].to_vec();
        scene.extend_from_slice(&right[..10]);
        scene.extend(wall(0.2, &mut bits).into_iter().take(15));
        let frame = seen(&scene, &f);
        assert!(frame.len() >= 30, "{}", frame.len());
        let guess = a.inverse() * f;
        let config = FrontendConfig::default();
        assert!(register(&observation_a, &frame, Some(&guess), &config, 1).is_err());
        let local = slam.local_map(0, &f).expect("a local map");
        // A's own points and B's once: not those of the keyframe looking back, in the other
        // map frame or 6 m away.
        assert_eq!(local.len(), observation_a.len() + observation_b.len());
        for (p, k) in local.points.iter().zip(&local.keypoints) {
            let u = local.camera.fx * p.x / p.z + local.camera.cx;
            assert!((f64::from(k.x) - u).abs() < 1e-3);
        }
        let reg = register(&local, &frame, Some(&guess), &config, 1).expect("registers");
        assert!(reg.inliers >= 20, "{} inliers", reg.inliers);
        let err = guess.inverse() * reg.reference_from_frame;
        assert!(err.translation.vector.norm() < 0.01, "{err}");
        // Off, there is no local map.
        slam.config.local_map_keyframes = 0;
        assert!(slam.local_map(0, &f).is_none());
    }

    #[test]
    fn a_robot_facing_walls_without_depth_is_tracked_on_the_map_by_projection() {
        // A vehicle's camera looking along its body's x at a textured wall 2–2.3 m ahead. It
        // starts there, flies 10 cm forward (tracked as usual), then 10 cm more into a view
        // where no feature has depth (as a wall beyond the depth camera's range gives). The
        // map's points, seen from where they had depth, place that frame on its pixels alone;
        // it becomes no keyframe (a keyframe is the next frames' reference and needs depth).
        let wall = textured_wall(80, &mut random_bits(5));
        let body_from_camera = forward_camera();
        let start = Isometry3::new(Vector3::new(0.0, 0.0, 0.9), Vector3::zeros());
        let ahead = |m: f64| start * Isometry3::translation(m, 0.0, 0.0);
        let view = |body: &Isometry3<f64>| Arc::new(seen(&wall, &(body * body_from_camera)));
        let mut slam = Slam::new(
            SlamConfig::default(),
            vec![RobotSetup {
                body_from_camera,
                start: Some(start),
            }],
        );
        assert_eq!(
            slam.start(&bare_frame(0.0), view(&start)).tracking,
            Tracking::Started
        );
        let report = slam.track(&bare_frame(0.1), view(&ahead(0.1)));
        assert!(
            matches!(report.tracking, Tracking::Tracked { .. }),
            "{report:?}"
        );
        let mut flat = (*view(&ahead(0.2))).clone();
        flat.without_depth = flat
            .keypoints
            .drain(..)
            .zip(flat.descriptors.drain(..))
            .collect();
        flat.points.clear();
        assert!(flat.is_empty() && flat.without_depth.len() >= 60);
        let report = slam.track(&bare_frame(0.2), Arc::new(flat));
        let Tracking::Tracked { inliers } = report.tracking else {
            panic!("not tracked: {report:?}");
        };
        assert!(inliers >= 60, "{inliers} inliers");
        assert_eq!(report.keyframe, None);
        assert_eq!(slam.stats().keyframes, 1);
        let body = slam
            .estimate(0)
            .and_then(|e| e.map_from_body())
            .expect("a pose");
        let off = ahead(0.2).inverse() * body;
        assert!(off.translation.vector.norm() < 0.002, "{off}");
        assert!(off.rotation.angle() < 0.1f64.to_radians(), "{off}");
    }

    #[test]
    fn a_lost_robot_is_relocalised_no_further_than_it_can_have_gone() {
        let mut slam = Slam::new(
            SlamConfig::default(),
            vec![RobotSetup {
                body_from_camera: Isometry3::identity(),
                start: None,
            }],
        );
        // Last placed at 10 s.
        slam.robots[0].track.push((10.0, 0, Isometry3::identity()));
        let frame = |stamp: f64, sigma: Option<f64>| Frame {
            heading: Some(0.0),
            predicted_body: sigma.map(|_| Isometry3::identity()),
            predicted_sigma_m: sigma,
            ..bare_frame(stamp)
        };
        let gate = |slam: &Slam, stamp, sigma| slam.relocalisation_gate(&frame(stamp, sigma)).0;
        let near = |a: f64, b: f64| (a - b).abs() < 1e-9;
        // Where it was last placed: as far as 0.3 m/s takes it since, on top of 0.3 m, at most
        // 1 m.
        assert!(near(gate(&slam, 10.5, None), 0.45));
        assert!(near(gate(&slam, 11.0, None), 0.6));
        assert!(near(gate(&slam, 20.0, None), 1.0));
        // The filter's prediction: no more than three of its standard deviations either, but
        // never under 0.3 m.
        assert!(near(gate(&slam, 11.0, Some(0.1)), 0.3));
        assert!(near(gate(&slam, 11.0, Some(0.15)), 0.45));
        assert!(near(gate(&slam, 11.0, Some(0.3)), 0.6));
        assert!(near(gate(&slam, 20.0, Some(0.5)), 1.0));
        // Never placed: the widest gate, or what the prediction's uncertainty allows.
        slam.robots[0].track.clear();
        assert!(near(gate(&slam, 10.3, None), 1.0));
        assert!(near(gate(&slam, 10.3, Some(0.2)), 0.6));
        // The rotation gate stays.
        assert!(near(
            slam.relocalisation_gate(&frame(10.3, Some(0.05))).1,
            0.6
        ));
    }

    #[test]
    fn a_robot_lost_while_turning_is_looked_for_facing_its_turning_heading() {
        // A vehicle's camera facing a textured wall; its filter has no pose to predict with,
        // and the SLAM has lost it. It hovers, turning fast (its heading comes only as a
        // turning one). The wall gives a match on fewer inliers than a match with nothing to
        // check it against needs: refused without the turning heading, taken with it.
        let wall = textured_wall(50, &mut random_bits(3));
        let body_from_camera = forward_camera();
        let start = Isometry3::new(Vector3::new(0.0, 0.0, 0.9), Vector3::zeros());
        let now = start * Isometry3::new(Vector3::new(0.03, 0.02, 0.0), Vector3::z() * 0.1);
        let view = |body: &Isometry3<f64>| Arc::new(seen(&wall, &(body * body_from_camera)));
        let run = |turning_heading: Option<f64>| {
            let mut slam = Slam::new(
                SlamConfig::default(),
                vec![RobotSetup {
                    body_from_camera,
                    start: Some(start),
                }],
            );
            let first = Frame {
                heading: Some(0.0),
                ..bare_frame(0.0)
            };
            assert_eq!(slam.start(&first, view(&start)).tracking, Tracking::Started);
            // What `process` does with a frame with a heading, and with a lost one.
            slam.robots[0].has_imu = true;
            slam.robots[0].track.push((0.0, 0, Isometry3::identity()));
            slam.robots[0].state = RobotState::Lost;
            let turning = Frame {
                turning_heading,
                ..bare_frame(0.5)
            };
            let report = slam.track(&turning, view(&now));
            (report, slam.estimate(0).and_then(|e| e.frame_from_body))
        };
        let inliers = view(&now).len();
        assert!(inliers < SlamConfig::default().relocalisation_min_inliers_unpredicted);
        let Tracking::Lost(why) = run(None).0.tracking else {
            panic!("found with nothing to check the match against");
        };
        assert!(why.contains("inliers"), "{why}");
        let (found, body) = run(Some(0.1));
        assert_eq!(found.tracking, Tracking::Relocalised { keyframe: 0 });
        let off = now.inverse() * body.expect("a pose");
        assert!(off.translation.vector.norm() < 0.005, "{off}");
    }

    #[test]
    fn a_robot_measures_its_motion_between_consecutive_frames() {
        // A vehicle's camera looking along its body's x at a textured wall 2–3 m ahead; it is
        // lost (the map cannot place it). Between two frames 0.1 s apart its body moved 4 cm
        // forward and 3 cm left and turned 3° anticlockwise.
        let mut bits = random_bits(11);
        let body_from_camera = forward_camera();
        let wall = textured_wall(80, &mut bits);
        let map_from_body_then = Isometry3::new(Vector3::new(0.0, 0.0, 0.9), Vector3::zeros());
        let then_from_now = Isometry3::new(Vector3::new(0.04, 0.03, 0.0), Vector3::z() * 0.05);
        let map_from_body_now = map_from_body_then * then_from_now;
        let then = Arc::new(seen(&wall, &(map_from_body_then * body_from_camera)));
        let now = seen(&wall, &(map_from_body_now * body_from_camera));
        assert!(then.len() >= 40 && now.len() >= 40);
        let mut slam = Slam::new(
            SlamConfig::default(),
            vec![RobotSetup {
                body_from_camera,
                start: None,
            }],
        );
        // No odometry before the robot has a map to be lost from, nor without a frame before.
        slam.robots[0].last_frame = Some((0.0, then.clone(), false));
        assert!(slam.frame_odometry(0, 0.1, &now).is_none());
        slam.robots[0].reference = Some(0);
        let odometry = slam
            .frame_odometry(0, 0.1, &now)
            .expect("consecutive frames register");
        assert_eq!(odometry.since, 0.0);
        assert!(odometry.inliers >= 40, "{} inliers", odometry.inliers);
        let err = then_from_now.inverse() * odometry.previous_from_body;
        assert!(err.translation.vector.norm() < 0.005, "{err}");
        assert!(err.rotation.angle() < 0.2f64.to_radians(), "{err}");
        // Frames too far apart, or sharing nothing, measure nothing.
        assert!(slam.frame_odometry(0, 0.7, &now).is_none());
        let elsewhere: Vec<(Point3<f64>, Descriptor)> = wall
            .iter()
            .map(|(p, _)| (*p, [bits(), bits(), bits(), bits()]))
            .collect();
        let other = seen(&elsewhere, &(map_from_body_now * body_from_camera));
        assert!(slam.frame_odometry(0, 0.1, &other).is_none());
    }
}
