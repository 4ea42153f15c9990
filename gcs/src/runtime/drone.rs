//! One drone in the mission: its link, its pose filter, what it is doing, and the control loop
//! that turns a goal into sticks (thesis §4.4: height PI, yaw P, x/y position from the filter —
//! the position hold the thesis lacked).

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::Duration;

use link::{Command, CommandError, FlightMode, LinkState, Sticks, Telemetry, VehicleLink};
use nalgebra::Isometry3;
use nav::Grid;
use nav::avoid::{KeepClear, brake_to_speed, brake_toward_walls, keep_clear, limit_approach};
use nav::control::{PidGains, Pose3, PositionController, PositionGains};
use nav::local::{Follow, FollowerConfig, PathFollower, Pose2, wrap_angle};
use nav::mission::SAME_FRONTIER_M;
use nav::proximity::{Proximity, ProximityConfig};
use nav::sweep::{self, View};
use slam::depth_odometry::DepthOdometry;
use slam::ekf::{Ekf, EkfConfig, Input, Update};

use super::battery;
use super::perception::SlamFix;

/// Bearings a look around checks for the unknown (5° apart).
const SWEEP_BEARINGS: usize = 72;

/// What a drone is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phase {
    /// On the ground, waiting for the mission.
    Idle,
    /// Arming and starting its motors.
    Arming,
    /// Climbing to its altitude band.
    TakingOff,
    /// Flying to frontiers.
    Exploring,
    /// Holding a position and the operator's goal height and yaw.
    Holding,
    /// Flying back to its start to land there (low battery, or the operator).
    Returning,
    /// Landing where it is.
    Landing,
    /// On the ground, disarmed.
    Landed,
    /// The link is lost: the vehicle's own failsafe lands it.
    LinkLost,
}

impl Phase {
    /// Lower-case name for displays and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Idle => "idle",
            Phase::Arming => "arming",
            Phase::TakingOff => "taking off",
            Phase::Exploring => "exploring",
            Phase::Holding => "holding",
            Phase::Returning => "returning",
            Phase::Landing => "landing",
            Phase::Landed => "landed",
            Phase::LinkLost => "link lost",
        }
    }

    /// Whether the drone is (or may be) in the air under the station's control.
    pub fn flying(self) -> bool {
        matches!(
            self,
            Phase::TakingOff | Phase::Exploring | Phase::Holding | Phase::Returning
        )
    }
}

/// How the station starts a vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartSequence {
    /// A MAVLink autopilot: ALT_HOLD, throttle low, arm.
    Mavlink,
    /// The thesis's shield: arm the outputs, then the Naza's start-motors stick combination.
    Shield,
}

impl StartSequence {
    /// Whether the vehicle's own land mode holds its position as it descends: an autopilot's
    /// LAND is left to it (it holds where it has a position of its own, as the simulated one
    /// always does, and takes roll and pitch only as a pilot's repositioning); the shield's
    /// land only centres the sticks (the Naza in ATTI drifts with whatever speed and draught
    /// it has), but lets the station's roll and pitch through ([`DroneConfig::steer_landing`]).
    pub fn land_holds_position(self) -> bool {
        match self {
            StartSequence::Mavlink => true,
            StartSequence::Shield => false,
        }
    }
}

/// One vehicle of the fleet as the mission runtime gets it.
pub struct DroneSpec {
    /// A name for displays ("drone 1").
    pub name: String,
    /// The connected link.
    pub link: Arc<dyn VehicleLink>,
    /// How to start it.
    pub start_sequence: StartSequence,
    /// Its altitude band, metres above the floor.
    pub altitude: f64,
    /// Where it starts in the map (x, y, yaw), when known.
    pub start: Option<[f64; 3]>,
}

/// A goal given again this soon after the planner last gave it is still the one the stuck clock
/// runs for, seconds (two plans at 1 Hz).
const GOAL_GAP_S: f64 = 2.5;

/// A lost drone within this of its last keyframe's heading faces it, radians
/// ([`DroneConfig::blind_face_s`]).
pub const FACING_RAD: f64 = 0.1;

/// How far back a lost drone's turn before the loss is read, seconds
/// ([`DroneConfig::blind_sweep_back_rad`]).
pub const TURN_WINDOW_S: f64 = 1.5;

/// How the IMU heading turned over the last [`TURN_WINDOW_S`]: which way a drone was turning
/// when the SLAM lost it.
#[derive(Debug, Clone, Default)]
struct RecentTurn {
    /// (time, heading) readings, oldest first, back to the first before the window.
    readings: VecDeque<(f64, f64)>,
}

impl RecentTurn {
    /// Takes the heading (radians) read at `now` (seconds).
    fn observe(&mut self, now: f64, heading: f64) {
        if !(now.is_finite() && heading.is_finite()) {
            return;
        }
        // A reading from before a gap (a loss) says nothing of the turn now.
        if self
            .readings
            .back()
            .is_some_and(|&(t, _)| now < t || now - t > TURN_WINDOW_S)
        {
            self.readings.clear();
        }
        self.readings.push_back((now, heading));
        while self
            .readings
            .get(1)
            .is_some_and(|&(t, _)| now - t >= TURN_WINDOW_S)
        {
            self.readings.pop_front();
        }
    }

    /// The turn over the window, radians (counter-clockwise positive).
    fn turned(&self) -> f64 {
        self.readings
            .iter()
            .zip(self.readings.iter().skip(1))
            .map(|(a, b)| wrap_angle(b.1 - a.1))
            .sum()
    }
}

/// Timing and behaviour settings of every drone.
#[derive(Debug, Clone)]
pub struct DroneConfig {
    /// Position controller gains.
    pub gains: PositionGains,
    /// Path follower.
    pub follower: FollowerConfig,
    /// Pursuing a carrot, the roll and pitch sticks lean this much per m/s of the speed the
    /// follower allows there, toward the carrot: what carries the drone against the air's drag
    /// (in SITL, drag of 0.6 per second against a lean of 20° at full stick: 0.175), so the x/y
    /// integrals need not, and they are frozen meanwhile. 0: no feed-forward, and the
    /// integrals integrate the follower's lead as they do any error.
    pub cruise_ff: f64,
    /// Pursuing a carrot, the roll and pitch sticks lean this much per m/s that the filter's
    /// velocity is off the one the drone should fly (toward the carrot at the speed the
    /// follower allows): the speed loop that holds the follower's limits, above them and
    /// below ([`DroneConfig::SPEED_LOOP_GAIN`] by default). 0: no speed loop, but the
    /// position loop, whose lean toward a carrot 0.4 m ahead comes on top of the
    /// feed-forward, with only overspeed braked: the simulated drone cruises at 0.8–0.9 m/s
    /// under a 0.7 m/s limit, and takes the 0.3 m/s bends at about 0.45.
    pub speed_gain: f64,
    /// The speed loop leans the drone at most this much (stick, the length of roll and
    /// pitch together; the x/y output limit caps it too): a gentler way up to speed. At the
    /// output limit's 0.5, drones leaned more than 0.3 stick 2.3 times as long as under the
    /// position loop, and more of the SLAM's losses began just after such a lean.
    pub speed_lean_max: f64,
    /// Pose filter.
    pub ekf: EkfConfig,
    /// Holding still (a look around, a turn, a hover), an error under this is not flown: the
    /// roll and pitch sticks stay centred instead of chasing the pose estimate's noise, metres.
    /// (ALT_HOLD, the mode flown, has no position hold of its own: a real drift this small
    /// goes unbraked until it passes the band.)
    pub hold_band_m: f64,
    /// The position setpoint never leads toward a wall of the map nearer than the clearance to
    /// the drone's centre, leads back out to it, and leads less far near walls
    /// ([`nav::avoid::keep_clear`]).
    pub keep_clear: KeepClear,
    /// Holding a spot (a look around, a turn, lost), the setpoint leads back out to this much
    /// room from the walls, not just [`KeepClear::clearance_m`], metres: the depth camera
    /// (0.1 m ahead of the centre, ranging from 0.4 m) then measures every wall it turns to.
    pub hold_clearance_m: f64,
    /// The mission planner plans from a drone's position while its uncertainty (1 σ) is at most
    /// this, metres: more than flying tolerates ([`EkfConfig::max_position_sigma`]), since a
    /// frontier and a path are chosen as well from a position known to a metre. A drone whose
    /// SLAM fixes came late for a moment (a slow machine, a big map) keeps its goal, and only
    /// hovers until they come (on building 31 in a debug build, the fixes lagged past the
    /// 0.35 m bound at every other plan: each plan gave both drones their goals and the next
    /// took them back, and the drones hovered for 18 minutes of mission time).
    pub plan_position_sigma_m: f64,
    /// Seconds without 0.3 m of progress toward a goal before it is given up.
    pub stuck_s: f64,
    /// A whole look around on the spot takes this long, seconds.
    pub scan_s: f64,
    /// A look around turns the short way to what the map shows unknown around the drone, and
    /// only as far as that ([`nav::sweep`]; the field of view is each drone's camera's once
    /// its frames have told it); `None`: a whole turn every time.
    pub sweep: Option<View>,
    /// A look around turns first the way that shows the most of what the map has unknown
    /// soonest ([`nav::sweep::direction_most_unknown_first`]: a room through a door before a
    /// jamb's shadow, so a drone waiting for a frontier gets one sooner), not the way that ends
    /// it soonest ([`nav::sweep::direction`]).
    pub look_most_unknown_first: bool,
    /// ... but lasts at least this long, seconds (the map lags the camera by up to a second).
    pub scan_min_s: f64,
    /// Drones whose starts lie within this distance of one another take off to one shared look
    /// around, each turning the way that, with the others', sees every side soonest
    /// ([`nav::sweep::shared_turns`]), metres; 0: each turns its own way (every bearing is
    /// unknown at the start, so all turned counter-clockwise, and the four drones of the
    /// apartment's hall, facing within 90° of one another, looked at the same walls for 7 s).
    /// Their parts end once every side has been in one of their cameras' views
    /// ([`nav::sweep::SharedLook`]).
    pub look_together_m: f64,
    /// A look around the SLAM loses the drone in goes on once it is found again, from the
    /// bearing where it was lost, while its losses add up to no more than this, seconds; a
    /// longer loss cuts it short ([`DroneEvent::LookCut`]). (In SITL, looks at the apartment's
    /// door were cut by losses of 0.1–0.8 s, three times in 4 s, and the mission ended at 41 %
    /// coverage with the rest of the apartment behind that door.)
    pub look_lost_s: f64,
    /// A look around turns at half its rate while the SLAM's last registration of the drone had
    /// fewer inliers than this (0: never): past a bare wall the views share fewer and fewer
    /// matches until a registration fails or jumps. In SITL a tenth of the registrations in
    /// turns on the spot had 48 matches or fewer (flying straight: 79), and drones turning on
    /// the spot were lost six times as often as flying straight.
    pub look_slow_inliers: usize,
    /// Yaw stick while the SLAM has lost the drone and the turn back found nothing (a slow turn
    /// so the camera finds known views): clockwise, unless…
    pub blind_yaw: f32,
    /// …the drone was turning clockwise by more than this (radians) over the last
    /// [`TURN_WINDOW_S`] before the loss: then it sweeps back counter-clockwise, over the
    /// views it turned from, which the map knows. Swept on clockwise, the camera turned on
    /// into what it had not seen: in the 72 main-command missions of stop 72, 9 of the 26
    /// drones lost for 4 s or more while turning clockwise were found again only on the
    /// other side, 14–23 s after the loss, most of a turn later; the 18 lost turning
    /// counter-clockwise and found again were found within 4–8 s.
    pub blind_sweep_back_rad: f64,
    /// A drone the SLAM loses goes back to where its last keyframe was taken, facing the way it
    /// faced then, if that is within this distance (the camera sees what the keyframe saw;
    /// where it was lost it may be too near a wall, or see only what is beyond the depth's
    /// range), else it stops where it was lost, metres.
    pub lost_back_m: f64,
    /// Lost by the SLAM, turn back to the heading of the last SLAM keyframe for this long
    /// first, seconds…
    pub blind_turn_back_s: f64,
    /// …but no longer than this once it faces that heading (within [`FACING_RAD`]), seconds:
    /// a view that has not found the map by then will not (in SITL, drones lost facing a bare
    /// wall hovered before it for the whole turn back, drifting up to 0.9 m, out of where the
    /// SLAM looks for them, before their sweep began).
    pub blind_face_s: f64,
    /// Land after this long lost by the SLAM (on visual odometry, or blind), seconds.
    pub blind_land_s: f64,
    /// With no pose but a velocity visual odometry still measures, the drift is braked (as
    /// ArduPilot's FlowHold holds a drone on its optical-flow sensor): this much stick per m/s
    /// against it, …
    pub blind_brake_gain: f64,
    /// … at most this much stick, …
    pub blind_brake_max: f64,
    /// … and nothing below this speed, m/s (the measurement's noise). A brake alone leaves the
    /// drone drifting at the speed where it balances the air's drag (in SITL 0.03–0.06 m/s in a
    /// 0.1 m/s gust: 0.44 m on average over a blind stretch of 8 s), so…
    pub blind_brake_band: f64,
    /// …the measured velocity can also be integrated, and the drone flown back toward where it
    /// went blind at this much m/s per metre it has drifted, 1/s (1 holds it within centimetres
    /// in a steady draught); 0, the default: braked only. Off because in SITL the two batches
    /// flown with it (1 m/s per metre) lost drones for good in 4 of 48 missions against 1 of 28
    /// without, and collided more (13 in 48 against 1 in 28), though none of those collisions
    /// came in the blind flight it changes: whether holding a drone where its view failed keeps
    /// it lost longer is open (`docs/exploration-history.md`, stop 56)…
    pub blind_hold_gain: f64,
    /// …at most this fast, m/s.
    pub blind_hold_max_mps: f64,
    /// A drone the SLAM lost while it flew slower than this (by its filter), m/s, holds its
    /// spot until found again with roll and pitch of at most…
    pub lost_still_mps: f64,
    /// …this much stick, while the filter carries its pose on visual odometry or its model.
    /// Holding a spot takes little (braking a 0.3 m/s drift within a second, about 0.1 of the
    /// 20° lean), while a filter that visual odometry on a few features had thrown 0.3 m off,
    /// with a phantom 0.4 m/s, drew 0.46 from the hold's derivative term and flew a hovering
    /// drone into a wall at 0.5 m/s (main command, seed 368, stop 82). One lost while flying
    /// faster brakes as hard as it must (seeds 374, 376: lost at 0.7 m/s, braked with 0.36).
    pub lost_stick_max: f64,
    /// A weakly placed drone ([`SlamFix::weak`]) flies on the visual odometry of its frames
    /// registered on at least this many inliers. Against the simulator's truth, its steps on
    /// 15–29 were more than 0.2 m/s off one time in four (on 30–39, one in ten), and a run of
    /// them on 25–28 threw a turning drone's filter 0.4 m off and into a wall (main command,
    /// seed 918, stop 92); a lost drone, holding its spot with little stick, takes every step.
    pub weak_odometry_min_inliers: usize,
    /// With no pose, the drone leans away from walls its depth camera ranged near lately, or
    /// the map had round it when it went blind ([`nav::proximity`]).
    pub proximity: ProximityConfig,
    /// When its battery is low (return to the start and land there) and when charged.
    pub battery: battery::Limits,
    /// Landed for a low battery, wait there for a charged one and rejoin the exploration;
    /// `None`: stay down.
    pub battery_swap: Option<BatterySwap>,
    /// An exploring drone whose camera has sent nothing for this long cannot map: it returns to
    /// its start and lands, and its goal goes to the others, seconds.
    pub camera_timeout_s: f64,
    /// A goal reached within this distance, metres (returning home).
    pub home_reach_m: f64,
    /// Told to land while moving, a drone with a pose first brakes to a stop on its position
    /// controller, for at most this long, and only then sends LAND: a vehicle's land mode with
    /// no position of its own (the shield's Naza in ATTI, an autopilot indoors) descends while
    /// it coasts on, into whatever wall lies ahead. Seconds.
    pub land_brake_s: f64,
    /// Slower than this, m/s, it is stopped: LAND goes out.
    pub land_still_mps: f64,
    /// While a vehicle whose land mode holds no position
    /// ([`StartSequence::land_holds_position`]) descends, the station holds the spot on its
    /// pose with roll and pitch.
    pub steer_landing: bool,
    /// Send LAND again if the vehicle is still armed this long after it, seconds.
    pub land_retry_s: f64,
    /// A flying drone whose vehicle reports itself disarmed this long has landed on its own (its
    /// battery failsafe, its pilot), seconds.
    pub disarmed_landed_s: f64,
}

impl DroneConfig {
    /// [`DroneConfig::speed_gain`] with the speed loop on (the default; `gcs explore
    /// --speed-loop false` turns it off): the damping of a hold (the x/y derivative gain),
    /// back to the speed in about 0.4 s. With its approach to walls cut to what can stop short
    /// of them and its lean to 0.35 stick, at 0.8 m/s, it took four drones on true poses
    /// 65.9 s against the position loop's 71.2 s under 0.7, with no collision
    /// (`docs/benchmarks.md`, stop 87).
    pub const SPEED_LOOP_GAIN: f64 = 0.6;
}

impl Default for DroneConfig {
    fn default() -> Self {
        let xy = PidGains {
            kp: 0.3,
            ki: 0.02,
            kd: 0.6,
            output_limit: 0.5,
            integral_limit: 0.3,
        };
        Self {
            gains: PositionGains {
                x: xy,
                y: xy,
                z: PidGains {
                    kp: 1.0,
                    ki: 0.05,
                    kd: 0.0,
                    output_limit: 1.0,
                    integral_limit: 0.3,
                },
                // At most 36°/s of turn: the camera must keep enough overlap between frames.
                yaw: PidGains {
                    output_limit: 0.4,
                    ..PidGains::p(1.5)
                },
            },
            follower: FollowerConfig {
                lookahead_m: 0.4,
                // Paths lie in known free space, so a bend of up to 90° is flown while the
                // drone turns to it; only a sharper one is turned to on the spot first, and
                // that turn's last 60° are flown as a bend is (paired: one drone on true
                // poses 8.6 s shorter over 48 seeds, the main command on SLAM poses 12.5 s
                // over 24 with fewer collisions; `docs/benchmarks.md`, stop 72).
                turn_threshold_rad: 90f64.to_radians(),
                resume_threshold_rad: 60f64.to_radians(),
                view_m: 1.0,
                // Held by the speed loop: what the drones had cruised at under the position
                // loop's 0.7 (`DroneConfig::SPEED_LOOP_GAIN`).
                max_speed_mps: 0.8,
                ..FollowerConfig::default()
            },
            cruise_ff: 0.175,
            speed_gain: Self::SPEED_LOOP_GAIN,
            speed_lean_max: 0.35,
            ekf: EkfConfig::default(),
            hold_band_m: 0.1,
            keep_clear: KeepClear::default(),
            hold_clearance_m: 0.55,
            plan_position_sigma_m: 1.0,
            stuck_s: 15.0,
            scan_s: 10.0,
            sweep: Some(View::default()),
            look_most_unknown_first: false,
            scan_min_s: 2.0,
            look_together_m: 2.0,
            look_lost_s: 1.5,
            look_slow_inliers: 60,
            blind_yaw: 0.2,
            blind_sweep_back_rad: 15f64.to_radians(),
            lost_back_m: 1.0,
            blind_turn_back_s: 10.0,
            blind_face_s: 2.0,
            blind_land_s: 30.0,
            blind_brake_gain: 0.5,
            blind_brake_max: 0.15,
            blind_brake_band: 0.03,
            blind_hold_gain: 0.0,
            blind_hold_max_mps: 0.1,
            lost_still_mps: 0.25,
            lost_stick_max: 0.15,
            weak_odometry_min_inliers: 30,
            proximity: ProximityConfig::default(),
            battery: battery::Limits {
                // The simulated vehicle's battery failsafe lands it at 10 %.
                reserve_pct: 15,
                // Fitted to 30 returns (the apartment and building 31, 1 to 4 drones, true and
                // SLAM poses, stop 69): 0.76 m/s and 7.2 s; the slowest took 0.92 times what
                // this says, so the 1.5 margin below is all to spare.
                home_pace_mps: 0.6,
                turn_and_land_s: 10.0,
                home_margin: 1.5,
                drain_after_pct: 5,
                // Over the shield: a pack's voltage the median of 4 s of readings, its sag in
                // the air the step from rest to 2–4 s into each flight (the simulated drone is
                // up in about 1.5 s), 0.05 V a cell until then (less than most packs sag, so
                // the charge reads low rather than high).
                voltage_window_s: 4.0,
                sag_window_s: [2.0, 4.0],
                sag_cell_v: 0.05,
                charged_pct: 90,
                charged_cell_v: 4.1,
            },
            battery_swap: None,
            camera_timeout_s: 5.0,
            home_reach_m: 0.3,
            // From 0.8 m/s, the hold stops a drone in about a second.
            land_brake_s: 3.0,
            land_still_mps: 0.15,
            steer_landing: true,
            land_retry_s: 20.0,
            disarmed_landed_s: 2.0,
        }
    }
}

/// How a drone home for a low battery gets back into the mission once a charged battery is in
/// (an operator swapping it while the flight controller stays on, or the simulator's
/// `--battery-swap`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatterySwap {
    /// The drone takes off this long after it reads a charged battery
    /// ([`battery::Limits::charged_pct`]; hands clear of the propellers), seconds.
    pub takeoff_delay_s: f64,
}

impl Default for BatterySwap {
    fn default() -> Self {
        Self {
            takeoff_delay_s: 5.0,
        }
    }
}

/// Whose landing a drone's is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum LandingBy {
    /// The station's, still braking to a stop before it sends LAND
    /// ([`DroneConfig::land_brake_s`]), since when (mission time, from its first tick).
    Braking(Option<f64>),
    /// The station's, on the LAND it sent.
    Station,
    /// The vehicle's own (its land mode, its failsafe).
    Vehicle,
}

impl LandingBy {
    /// Whether it still brakes before LAND.
    fn braking(self) -> bool {
        matches!(self, LandingBy::Braking(_))
    }
}

/// What the position controller flies to: the carrot of one of the drone's paths (counted),
/// or a spot held.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Target {
    Path(u64),
    Hold([f64; 2]),
}

/// The velocity (map frame, m/s) toward a carrot `ahead` of a drone (the steer point's lead,
/// map frame, metres) at `speed_mps`; none for no lead.
fn carrot_velocity(ahead: [f64; 2], speed_mps: f64) -> [f64; 2] {
    let lead = ahead[0].hypot(ahead[1]);
    if lead > 1e-9 {
        [ahead[0] * speed_mps / lead, ahead[1] * speed_mps / lead]
    } else {
        [0.0; 2]
    }
}

/// The speed loop of a drone pursuing a carrot: the lean (map frame, stick) that flies it at
/// `want` (m/s; [`carrot_velocity`], its approach to near walls cut by
/// [`nav::avoid::limit_approach`]) from `velocity`: the drag's feed-forward for `want` and
/// [`DroneConfig::speed_gain`] per m/s it is off, at most [`DroneConfig::speed_lean_max`]
/// long. (Not slower where `keep_clear` shortens the lead near a wall: that halved the speed
/// within 0.6 m of any wall, through every door and along every room's walls, and
/// main-command missions took 13.6 s longer over 10 pairs.)
fn speed_loop(want: [f64; 2], velocity: [f64; 2], config: &DroneConfig) -> [f64; 2] {
    let (kf, kv) = (config.cruise_ff, config.speed_gain);
    let lean = [
        kf * want[0] + kv * (want[0] - velocity[0]),
        kf * want[1] + kv * (want[1] - velocity[1]),
    ];
    let length = lean[0].hypot(lean[1]);
    let limit = config.gains.x.output_limit.min(config.speed_lean_max);
    if length > limit {
        [lean[0] * limit / length, lean[1] * limit / length]
    } else {
        lean
    }
}

/// Roll and pitch sticks that brake a drone moving at `velocity` (map frame, m/s) while it
/// heads `yaw` (radians): proportional, limited, and none for a speed within the band.
fn brake(velocity: [f64; 2], yaw: f64, config: &DroneConfig) -> [f32; 2] {
    let [vx, vy] = velocity;
    if vx.hypot(vy) < config.blind_brake_band {
        return [0.0; 2];
    }
    let (s, c) = yaw.sin_cos();
    let (forward, left) = (c * vx + s * vy, -s * vx + c * vy);
    let limit = config.blind_brake_max;
    // + roll banks right (accelerates right, against a drift left); + pitch noses down.
    let roll = (config.blind_brake_gain * left).clamp(-limit, limit);
    let pitch = (-config.blind_brake_gain * forward).clamp(-limit, limit);
    [roll as f32, pitch as f32]
}

/// How far a drone without a pose has drifted since it went blind, as visual odometry measures
/// it: the sum of its camera's frame-to-frame displacements that the filter took. (Not the
/// filter's velocity: its model knows the lean, not the air, so in a draught it reads a drone
/// leaning against the drift as still while it drifts on.) A frame the camera could not
/// register on its previous one adds nothing, and the spot held moves by what it missed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Drift {
    /// Metres, map frame.
    moved: [f64; 2],
}

impl Drift {
    /// A displacement measured between two frames, `forward` and `left` of the body heading
    /// `yaw` (radians) at the first.
    fn add(&mut self, forward: f64, left: f64, yaw: f64) {
        let (s, c) = yaw.sin_cos();
        self.moved[0] += c * forward - s * left;
        self.moved[1] += s * forward + c * left;
    }
}

/// Roll and pitch sticks that hold a drone without a pose where it went blind: back toward
/// that spot (`drift` from it, metres) at a speed proportional to the distance, and braked
/// against `velocity` (m/s, map frame) relative to that ([`brake`]).
fn hold_blind(drift: [f64; 2], velocity: [f64; 2], yaw: f64, config: &DroneConfig) -> [f32; 2] {
    let gain = config.blind_hold_gain;
    let mut back = [-gain * drift[0], -gain * drift[1]];
    let speed = back[0].hypot(back[1]);
    if speed > config.blind_hold_max_mps {
        let scale = config.blind_hold_max_mps / speed;
        back = [back[0] * scale, back[1] * scale];
    }
    brake([velocity[0] - back[0], velocity[1] - back[1]], yaw, config)
}

/// A look around on the spot.
#[derive(Debug, Clone, Copy)]
struct Scan {
    since: f64,
    yaw0: f64,
    /// +1: counter-clockwise, −1: clockwise.
    direction: f64,
    /// The goal to give up after it (reached while its frontier stayed).
    give_up: Option<[f64; 2]>,
    /// The SLAM lost the drone during it for longer than [`DroneConfig::look_lost_s`] in all:
    /// turning on would lose it again where it did (a door close ahead, the room behind
    /// beyond the depth's range), so it ends once found.
    cut: bool,
    /// Lost by the SLAM since this frame's stamp, seconds.
    lost_since: Option<f64>,
    /// How long the SLAM lost the drone during it so far, seconds.
    lost_s: f64,
    /// [`DroneConfig::look_lost_s`].
    lost_max_s: f64,
    /// Its part of a look around shared with the drones it took off beside
    /// ([`Drone::share_first_look`]).
    shared: bool,
    /// ... and every side has been seen by one of them ([`Drone::shared_look_seen`]).
    seen_by_all: bool,
}

impl Scan {
    /// A look around starting at `since` from heading `yaw0`, counter-clockwise, giving up
    /// `give_up` after it.
    fn new(since: f64, yaw0: f64, give_up: Option<[f64; 2]>, config: &DroneConfig) -> Self {
        Self {
            since,
            yaw0,
            direction: 1.0,
            give_up,
            cut: false,
            lost_since: None,
            lost_s: 0.0,
            lost_max_s: config.look_lost_s,
            shared: false,
            seen_by_all: false,
        }
    }

    /// The SLAM lost the drone at the frame stamped `stamp`.
    fn lost(&mut self, stamp: f64) {
        self.lost_since.get_or_insert(stamp);
    }

    /// The SLAM found the drone again at the frame stamped `stamp`: the turn resumes from the
    /// bearing where it was lost (the time lost does not count), unless its losses add up to
    /// more than [`DroneConfig::look_lost_s`], which cuts it short. Returns how long it was
    /// lost, if it was.
    fn found(&mut self, stamp: f64) -> Option<f64> {
        let since = self.lost_since.take()?;
        let lost = (stamp - since).max(0.0);
        self.lost_s += lost;
        self.since += lost;
        self.cut |= self.lost_s > self.lost_max_s;
        Some(lost)
    }
}

/// A drone in the mission.
pub struct Drone {
    /// Index in the fleet.
    pub id: usize,
    /// Display name.
    pub name: String,
    /// The link.
    pub link: Arc<dyn VehicleLink>,
    start_sequence: StartSequence,
    /// Its altitude band, metres.
    pub altitude: f64,
    /// Inliers of its last frame the SLAM tracked (`None`: relocalised or lost).
    pub inliers: Option<usize>,
    /// Where it started (x, y, yaw), if known.
    pub start: Option<[f64; 3]>,
    /// What it is doing.
    pub phase: Phase,
    /// The pose filter.
    pub ekf: Ekf,
    follower: PathFollower,
    controller: PositionController,
    /// The frontier (or home) it flies to.
    pub goal: Option<[f64; 2]>,
    /// The way its look around at `goal` must turn (+1 counter-clockwise, −1 clockwise), set by
    /// the mission; `None`: the short way to the unknown.
    look_turn: Option<f64>,
    /// The way its look around at take-off turns, shared with the drones that take off beside
    /// it ([`Drone::share_first_look`]); `None`: the short way to the unknown.
    first_look_turn: Option<f64>,
    /// Since when it has had nothing to fly to: its look around (or its goal) ended and no plan
    /// has come since ([`Drone::awaits_plan`]).
    awaits_plan: Option<f64>,
    /// The capture time of the newest of its camera frames the SLAM has processed (and cast
    /// into the map, if it became a keyframe).
    mapped_until: f64,
    /// The stuck clock: since when, and from where, it has not moved 0.3 m.
    progress: (f64, [f64; 2]),
    /// The frontier goal the stuck clock runs for, and when the planner last gave it.
    clocked_goal: Option<([f64; 2], f64)>,
    scan: Option<Scan>,
    hold: [f64; 2],
    /// Pursuing a carrot along a path this tick (not holding still)…
    tracking: bool,
    /// …at most this fast, m/s (the path's next sharp bend).
    speed_limit: f64,
    /// Paths given to the follower so far…
    paths: u64,
    /// …and what the position controller flew to last tick.
    flown: Option<Target>,
    /// Turning on the spot toward the path (holding where the turn began).
    turning: bool,
    /// Where the position controller pulled it last: `hold` kept off the walls.
    setpoint: [f64; 2],
    /// The latest occupancy map, whose walls it keeps off.
    map: Option<Arc<Grid>>,
    /// Heading held, radians.
    pub yaw_goal: f64,
    /// Height held, metres.
    pub height_goal: f64,
    /// A command running on its own thread (commands wait for the vehicle's answer).
    pending: Option<(Command, Receiver<Result<(), CommandError>>)>,
    /// The phase the link was lost in.
    lost_in: Option<Phase>,
    blind_since: Option<f64>,
    /// Blind: how far its camera has measured it drift since it went blind.
    blind_drift: Drift,
    /// Lost, since when it has faced its last keyframe's heading ([`DroneConfig::blind_face_s`]).
    faced_since: Option<f64>,
    /// How it was turning while the SLAM placed it…
    recent_turn: RecentTurn,
    /// …and so, lost, whether it sweeps counter-clockwise ([`DroneConfig::blind_sweep_back_rad`]).
    sweep_back: bool,
    /// The IMU heading at its last SLAM keyframe, radians: where the camera last saw enough
    /// to build the map on…
    keyframe_heading: Option<f64>,
    /// …its heading in the map…
    keyframe_yaw: Option<f64>,
    /// …and where it was taken (x, y, map frame).
    keyframe_at: Option<[f64; 2]>,
    /// Where the filter had the drone when the SLAM lost it (while the filter still carries
    /// the pose).
    lost_at: Option<[f64; 2]>,
    /// Since when (the frame's time) the SLAM has not placed it.
    lost_since: Option<f64>,
    /// It was flying when the SLAM lost it ([`DroneConfig::lost_still_mps`]): it may brake hard.
    lost_moving: bool,
    /// Since when the vehicle has reported itself disarmed while the station flew it.
    disarmed_since: Option<f64>,
    /// Mission time of its last camera frame (none yet: no camera is watched).
    last_frame: Option<f64>,
    /// Half its camera's horizontal field of view, radians, from the last frame's intrinsics
    /// (none yet: the look around assumes [`DroneConfig::sweep`]'s).
    camera_half_fov: Option<f64>,
    /// Whose landing it is, while landing.
    landing_by: LandingBy,
    /// When the last LAND was sent (mission time), while landing.
    landing_since: Option<f64>,
    last_tick: Option<f64>,
    /// Arrival time of the heading the filter took last (the link's stamp, mission clock).
    heading_taken: Option<Duration>,
    /// The sticks sent last.
    pub sticks: Option<Sticks>,
    /// The filter's path: (time, x, y, z, yaw).
    pub trajectory: Vec<(f64, [f64; 4])>,
    /// Distance flown according to the filter, metres.
    pub path_length: f64,
    /// Messages for the operator since the last call of [`Drone::take_messages`].
    messages: Vec<String>,
    /// Why it left the mission before the end (its battery, its camera, its link, the SLAM,
    /// its vehicle's own failsafe, the operator): the first reason of this flight; `None`
    /// while it explores, and for a drone that flew until the mission ended.
    pub left_mission: Option<String>,
    /// Landed (or on its way home) for a low battery, it waits for a charged one to rejoin
    /// ([`DroneConfig::battery_swap`]).
    pub awaits_battery: bool,
    /// Since when it has read a charged battery while it waits, mission time.
    charged_since: Option<f64>,
    /// Its battery as read so far.
    gauge: battery::Gauge,
    /// The length of its way home on the last map planned on, metres.
    way_home_m: Option<f64>,
    /// The walls round it, as its camera ranged them lately and the map had them while it had
    /// a pose.
    proximity: Proximity,
    /// Leaning off a wall while blind (the trace says so once each time it starts).
    pushed_off: bool,
    /// Charged batteries it took off again on.
    pub battery_swaps: u32,
}

/// Something the drone's tick wants the mission to know.
#[derive(Debug, Clone, PartialEq)]
pub enum DroneEvent {
    /// Give this frontier goal up for good (reached while its frontier stayed, or no progress).
    GiveUp([f64; 2]),
    /// The look around at this frontier goal lost the map before it was over: set the goal
    /// aside, but it was not looked at ([`nav::blacklist::Blacklist::look_cut`]). With the way
    /// it turned (+1 counter-clockwise, −1 clockwise).
    LookCut([f64; 2], f64),
}

impl Drone {
    /// A drone on the ground at mission time `t`.
    pub fn new(id: usize, spec: DroneSpec, config: &DroneConfig, t: f64) -> Self {
        let [x, y, yaw] = spec.start.unwrap_or([0.0, 0.0, 0.0]);
        let mut ekf = Ekf::new(config.ekf.clone(), t, [x, y, 0.0], yaw);
        if spec.start.is_some() {
            // A known start is a fix.
            ekf.update_slam(t, [x, y, 0.0], yaw);
        }
        Self {
            id,
            name: spec.name,
            link: spec.link,
            start_sequence: spec.start_sequence,
            inliers: None,
            altitude: spec.altitude,
            start: spec.start,
            phase: Phase::Idle,
            ekf,
            follower: PathFollower::new(config.follower.clone()),
            controller: PositionController::new(config.gains),
            goal: None,
            look_turn: None,
            first_look_turn: None,
            awaits_plan: None,
            mapped_until: f64::NEG_INFINITY,
            progress: (t, [x, y]),
            clocked_goal: None,
            scan: None,
            hold: [x, y],
            tracking: false,
            speed_limit: f64::INFINITY,
            paths: 0,
            flown: None,
            turning: false,
            setpoint: [x, y],
            map: None,
            yaw_goal: yaw,
            height_goal: spec.altitude,
            pending: None,
            lost_in: None,
            blind_since: None,
            blind_drift: Drift::default(),
            faced_since: None,
            keyframe_heading: None,
            recent_turn: RecentTurn::default(),
            sweep_back: false,
            keyframe_yaw: None,
            keyframe_at: None,
            lost_at: None,
            lost_since: None,
            lost_moving: false,
            last_frame: None,
            camera_half_fov: None,
            disarmed_since: None,
            landing_by: LandingBy::Vehicle,
            landing_since: None,
            last_tick: None,
            heading_taken: None,
            sticks: None,
            trajectory: vec![],
            path_length: 0.0,
            messages: vec![],
            left_mission: None,
            awaits_battery: false,
            charged_since: None,
            gauge: battery::Gauge::default(),
            way_home_m: None,
            proximity: Proximity::new(&config.proximity),
            pushed_off: false,
            battery_swaps: 0,
        }
    }

    /// The path it is following.
    pub fn path(&self) -> &[[f64; 2]] {
        self.follower.path()
    }

    /// Where the position controller pulls it (x, y), map frame.
    pub fn setpoint(&self) -> [f64; 2] {
        self.setpoint
    }

    /// [`Drone::setpoint`] while it flies on a pose (in the air, with a valid pose); `None`
    /// otherwise, when no setpoint is flown.
    pub fn flown_setpoint(&self) -> Option<[f64; 2]> {
        (self.phase.flying() && self.pose().is_some()).then_some(self.setpoint)
    }

    /// A new occupancy map: the walls to keep off ([`DroneConfig::keep_clear`]).
    pub fn set_map(&mut self, map: Arc<Grid>) {
        self.map = Some(map);
    }

    /// Takes the operator messages produced since the last call.
    pub fn take_messages(&mut self) -> Vec<String> {
        std::mem::take(&mut self.messages)
    }

    fn say(&mut self, text: String) {
        self.messages.push(text);
    }

    /// Keeps why it leaves the mission, unless it already left for another reason
    /// ([`Drone::left_mission`]).
    pub fn leave_mission(&mut self, why: &str) {
        self.left_mission.get_or_insert_with(|| why.to_owned());
    }

    /// Why it is out of the mission, for displays: [`Drone::left_mission`], and whether it
    /// waits for a charged battery to rejoin.
    pub fn why_away(&self) -> Option<String> {
        let why = self.left_mission.clone()?;
        Some(if self.awaits_battery {
            format!("{why} (waits for a charged battery to rejoin)")
        } else {
            why
        })
    }

    /// Sends a command on its own thread; its answer is read by later ticks.
    fn send(&mut self, command: Command) {
        let (tx, rx) = channel();
        let link = self.link.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("command-{}", self.id + 1))
            .spawn(move || {
                let _ = tx.send(link.command(command));
            });
        match spawned {
            Ok(_) => self.pending = Some((command, rx)),
            Err(e) => self.say(format!("cannot send {command}: {e}")),
        }
    }

    /// The answer to the pending command, once it came.
    fn answer(&mut self) -> Option<(Command, Result<(), CommandError>)> {
        let (command, rx) = self.pending.as_ref()?;
        let command = *command;
        match rx.try_recv() {
            Ok(r) => {
                self.pending = None;
                Some((command, r))
            }
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Disconnected) => {
                self.pending = None;
                Some((command, Err(CommandError::Closed { command })))
            }
        }
    }

    /// Starts arming (the mission's start, or the operator's take-off).
    pub fn take_off(&mut self) {
        if !matches!(self.phase, Phase::Idle | Phase::Landed) {
            return;
        }
        self.phase = Phase::Arming;
        self.left_mission = None;
        self.awaits_battery = false;
        self.charged_since = None;
        match self.start_sequence {
            StartSequence::Mavlink => {
                self.link.set_sticks(Some(Sticks {
                    throttle: -1.0,
                    ..Sticks::CENTRED
                }));
                self.send(Command::SetMode(FlightMode::AltHold));
            }
            StartSequence::Shield => self.send(Command::Arm),
        }
    }

    /// Whether this drone, landed for a low battery, has now read a charged one for
    /// [`BatterySwap::takeoff_delay_s`] at mission time `now`: then it has started taking off
    /// to rejoin the exploration. The mission calls it only while it explores.
    pub fn rejoin_after_swap(&mut self, now: f64, config: &DroneConfig) -> bool {
        let battery = self.link.telemetry().battery;
        let charged = match config.battery_swap {
            Some(swap) if self.awaits_battery && self.phase == Phase::Landed => self
                .gauge
                .charged(battery.as_ref(), &config.battery)
                .map(|reading| (swap, reading)),
            _ => None,
        };
        let Some((swap, reading)) = charged else {
            self.charged_since = None;
            return false;
        };
        let since = *self.charged_since.get_or_insert_with(|| {
            self.messages.push(format!(
                "a charged battery ({reading}): taking off in {:.0} s to rejoin",
                swap.takeoff_delay_s
            ));
            now
        });
        if now - since < swap.takeoff_delay_s {
            return false;
        }
        self.battery_swaps += 1;
        self.take_off();
        true
    }

    /// Lands where it is (the vehicle lands and disarms by itself): braked to a stop first if
    /// it has a pose and is moving ([`DroneConfig::land_brake_s`]; its next tick decides),
    /// then LAND.
    pub fn land(&mut self) {
        if matches!(self.phase, Phase::Landed | Phase::Landing | Phase::Idle) {
            return;
        }
        self.set_path(vec![]);
        self.goal = None;
        self.scan = None;
        let e = self.ekf.estimate();
        self.hold = [e.position[0], e.position[1]];
        self.yaw_goal = e.attitude[2];
        self.phase = Phase::Landing;
        self.landing_since = None;
        // Without a pose it cannot brake on one: LAND at once.
        if self.pose().is_some() {
            self.landing_by = LandingBy::Braking(None);
        } else {
            self.landing_by = LandingBy::Station;
            self.set_sticks(Sticks::CENTRED);
            self.send(Command::Land);
        }
    }

    /// One tick of a landing: it brakes to a stop before its LAND goes out, then sends it
    /// again while the vehicle stays armed, and notes when it is down. Whether it is flown this
    /// tick, as a hold of the spot where it was told to land: while it brakes, and as it
    /// descends if its land mode holds no position ([`DroneConfig::steer_landing`]).
    fn landing_step(&mut self, now: f64, telemetry: &Telemetry, config: &DroneConfig) -> bool {
        if telemetry.armed == Some(false) {
            self.phase = Phase::Landed;
            self.landing_by = LandingBy::Vehicle;
            self.link.set_sticks(None);
            self.sticks = None;
            self.say(if self.awaits_battery {
                "landed: waiting for a charged battery to rejoin".into()
            } else {
                "landed".into()
            });
            return false;
        }
        if let LandingBy::Braking(since) = &mut self.landing_by {
            let since = *since.get_or_insert(now);
            // (A vehicle already in its land mode lands on its own: no stick may move it.)
            let moving = self.pose().is_some()
                && telemetry.mode.as_deref() != Some("LAND")
                && self
                    .ekf
                    .valid_velocity()
                    .is_some_and(|[vx, vy]| vx.hypot(vy) >= config.land_still_mps);
            if moving && now - since < config.land_brake_s {
                return true;
            }
            self.landing_by = LandingBy::Station;
            self.set_sticks(Sticks::CENTRED);
            self.landing_since = Some(now);
            self.send(Command::Land);
        } else if self.pending.is_none()
            && now - *self.landing_since.get_or_insert(now) > config.land_retry_s
        {
            // Still armed long after the command: it may never have arrived. Again.
            self.say(format!(
                "still armed {:.0} s after LAND: sending it again",
                config.land_retry_s
            ));
            self.landing_since = Some(now);
            self.send(Command::Land);
        }
        // Coming down: held on its pose where its land mode holds nothing (and nothing it
        // does not command: a vehicle landing on its own, by its failsafe, is left to it).
        config.steer_landing
            && !self.start_sequence.land_holds_position()
            && self.landing_by == LandingBy::Station
            && self.pose().is_some()
    }

    /// Flies home and lands there (or lands where it is if its start is unknown).
    pub fn return_home(&mut self, why: &str) {
        if !self.phase.flying() || self.phase == Phase::Returning {
            return;
        }
        self.leave_mission(why);
        match self.start {
            Some([x, y, _]) => {
                self.say(format!("{why}: returning to its start"));
                self.phase = Phase::Returning;
                self.goal = Some([x, y]);
                self.set_path(vec![]);
                self.scan = None;
            }
            None => {
                self.say(format!("{why}: landing (its start is unknown)"));
                self.land();
            }
        }
    }

    /// It is exploring with nothing to fly to since its look around ended (or it gave up its
    /// goal), no plan has come since, and the SLAM has processed its camera frames up to then:
    /// every second it waits for the planner's next step is a second it hovers (a lone drone's
    /// 13 looks around in the apartment), but a plan on a map without the look's last frames
    /// may send it past a corner the look saw.
    pub fn awaits_plan(&self) -> bool {
        self.awaits_plan
            .is_some_and(|since| self.mapped_until >= since)
            && self.phase == Phase::Exploring
            && self.scan.is_none()
    }

    /// Holds position with the operator's goal height and yaw (the thesis's control-test tab).
    pub fn hold(&mut self, height: f64, yaw: f64) {
        if !self.phase.flying() {
            return;
        }
        let e = self.ekf.estimate();
        self.hold = [e.position[0], e.position[1]];
        self.height_goal = height;
        self.yaw_goal = yaw;
        self.set_path(vec![]);
        self.goal = None;
        self.scan = None;
        self.phase = Phase::Holding;
    }

    /// Back to exploring from a hold.
    pub fn resume(&mut self) {
        if self.phase == Phase::Holding {
            self.height_goal = self.altitude;
            self.phase = Phase::Exploring;
        }
    }

    /// Disarms (refused by the caller unless on the ground).
    pub fn disarm(&mut self) {
        self.link.set_sticks(None);
        self.send(Command::Disarm);
    }

    /// The way (+1 counter-clockwise, −1 clockwise) its first look around, at take-off, turns:
    /// its part of a look around shared with the drones taking off beside it
    /// ([`nav::sweep::shared_turns`]). A later take-off (after a battery swap) looks its own way.
    pub fn share_first_look(&mut self, direction: f64) {
        self.first_look_turn = Some(direction.signum());
    }

    /// Its heading, and what its camera sees, while it turns its part of a look around shared
    /// with the drones it took off beside (the runtime adds up what their cameras have faced in
    /// a [`nav::sweep::SharedLook`]); `None` at any other time, or with sweeps off.
    pub fn shared_look_view(&self, config: &DroneConfig) -> Option<(f64, View)> {
        self.scan.filter(|s| s.shared && !s.seen_by_all)?;
        Some((self.pose()?[3], self.view(config)?))
    }

    /// Every side has been in the view of one of the drones sharing its first look around: its
    /// part ends (after [`DroneConfig::scan_min_s`], like any look), whatever the map still
    /// shows unknown from where it stands.
    pub fn shared_look_seen(&mut self) {
        if let Some(scan) = self.scan.as_mut().filter(|s| s.shared) {
            scan.seen_by_all = true;
        }
    }

    /// A new frontier goal and path from the mission planner (exploring drones only), and the
    /// way its look around there must turn (`None`: the short way to the unknown).
    pub fn set_plan(
        &mut self,
        goal: Option<[f64; 2]>,
        path: Vec<[f64; 2]>,
        look_turn: Option<f64>,
        now: f64,
    ) {
        if self.phase != Phase::Exploring || self.scan.is_some() {
            return;
        }
        self.awaits_plan = None;
        if goal != self.goal {
            tracing::debug!(drone = self.id + 1, from = ?self.goal, to = ?goal, "new goal");
        }
        if let Some(g) = goal {
            // The stuck clock starts again only for another frontier: not for the same goal
            // moved a little (the frontier's edge as the map grows), nor given back after the
            // planner had taken it for a plan or two. Else a planner that keeps doing either
            // (seen: goals given and taken back at every other plan for 18 minutes of building
            // 31) keeps the drone on a goal it cannot reach for ever.
            let same = self.clocked_goal.is_some_and(|(c, at)| {
                (c[0] - g[0]).hypot(c[1] - g[1]) <= SAME_FRONTIER_M && now - at <= GOAL_GAP_S
            });
            if !same {
                let e = self.ekf.estimate();
                self.progress = (now, [e.position[0], e.position[1]]);
            }
            let clocked = if same {
                self.clocked_goal.map_or(g, |c| c.0)
            } else {
                g
            };
            self.clocked_goal = Some((clocked, now));
        }
        self.goal = goal;
        self.look_turn = look_turn;
        self.set_path(path);
    }

    /// The charge at which it turns home from where it is, percent, while it explores
    /// ([`battery::Gauge::home_at_pct`]).
    pub fn battery_home_at(&self) -> Option<f64> {
        matches!(
            self.phase,
            Phase::Exploring | Phase::TakingOff | Phase::Holding
        )
        .then(|| self.gauge.home_at_pct())
        .flatten()
    }

    /// The charge read off its pack's voltage, percent, for a vehicle that reports only the
    /// voltage ([`battery::Gauge::estimate_pct`]).
    pub fn battery_estimate_pct(&self) -> Option<f64> {
        self.gauge.estimate_pct()
    }

    /// The length of its way home on the map just planned on, metres (`None`: no way known);
    /// what its low-battery return is sized to.
    pub fn set_way_home(&mut self, metres: Option<f64>) {
        self.way_home_m = metres;
    }

    /// A path home (returning drones only).
    pub fn set_home_path(&mut self, path: Vec<[f64; 2]>) {
        if self.phase == Phase::Returning {
            self.set_path(path);
        }
    }

    fn set_sticks(&mut self, s: Sticks) {
        self.link.set_sticks(Some(s));
        self.ekf.set_input(Input {
            roll: f64::from(s.roll),
            pitch: f64::from(s.pitch),
            yaw: f64::from(s.yaw),
            throttle: f64::from(s.throttle),
        });
        self.sticks = Some(s);
    }

    /// A camera frame of this drone, its camera seeing `half_fov_rad` either side of its axis
    /// ([`link::camera::Intrinsics::half_fov_x`]), reached the SLAM at mission time `now`.
    pub fn camera_frame(&mut self, now: f64, half_fov_rad: f64) {
        self.last_frame = Some(self.last_frame.map_or(now, |t| t.max(now)));
        self.camera_half_fov = Some(half_fov_rad);
    }

    /// The filter's pose (x, y, z, yaw) if valid.
    pub fn pose(&self) -> Option<[f64; 4]> {
        self.ekf
            .valid_estimate()
            .map(|e| [e.position[0], e.position[1], e.position[2], e.attitude[2]])
    }

    /// The horizontal standard deviation of [`Drone::pose`], metres, while it is valid.
    pub fn pose_sigma_m(&self) -> Option<f64> {
        self.ekf.valid_estimate().map(|e| e.position_sigma)
    }

    /// Where the mission planner plans this drone from (x, y): its position estimate while it
    /// is known within `config.plan_position_sigma_m`, which a pose too uncertain to fly on
    /// may still be.
    pub fn plan_position(&self, config: &DroneConfig) -> Option<[f64; 2]> {
        self.ekf
            .estimate_within(config.plan_position_sigma_m)
            .map(|e| [e.position[0], e.position[1]])
    }

    /// The heading the mission planner weighs this drone's turns from (radians, map frame):
    /// its estimate's yaw where [`Drone::plan_position`] has a position, unless it is looking
    /// around (it ends that turn facing wherever the unknown ran out, and takes no plan before).
    pub fn plan_heading(&self, config: &DroneConfig) -> Option<f64> {
        if self.scan.is_some() {
            return None;
        }
        self.ekf
            .estimate_within(config.plan_position_sigma_m)
            .map(|e| e.attitude[2])
    }

    /// What the SLAM made of one of this drone's camera frames, reaching the mission at `now`:
    /// a pose to fly on, a loss (with visual odometry, if the camera still measured the
    /// motion), or a weak registration ([`SlamFix::weak`]), which is neither: the filter
    /// carries the pose on as between frames, on the visual odometry if measured.
    pub fn take_fix(&mut self, now: f64, fix: &SlamFix, config: &DroneConfig) {
        self.camera_frame(now, fix.half_fov_rad);
        self.mapped_until = self.mapped_until.max(fix.stamp);
        if let Some(heading) = fix.heading {
            self.proximity
                .observe(fix.stamp, heading, &fix.ranges, &config.proximity);
        }
        self.inliers = fix.inliers;
        if fix.weak {
            // Not a pose to fly on, but how far the body moved since the frame before is still
            // measured: without it a stretch of weak frames leaves the filter on its model alone.
            if let Some(o) = &fix.odometry
                && o.inliers >= config.weak_odometry_min_inliers
            {
                let inliers = Some(o.inliers);
                self.odometry_step(o.since, fix.stamp, &o.previous_from_body, inliers, true);
            } else if let Some(o) = &fix.depth_odometry {
                self.depth_odometry_step(fix.stamp, o, true);
            }
            return;
        }
        match fix.map_from_body {
            Some(pose) => {
                let v = pose.translation.vector;
                let x = pose.rotation * nalgebra::Vector3::x();
                self.slam_fix(
                    fix.stamp,
                    [v.x, v.y, v.z],
                    x.y.atan2(x.x),
                    fix.inliers,
                    fix.keyframe,
                );
            }
            None => {
                self.slam_lost(fix.stamp, config);
                if let Some(o) = &fix.odometry {
                    self.slam_odometry(o.since, fix.stamp, &o.previous_from_body, Some(o.inliers));
                } else if let Some(o) = &fix.depth_odometry {
                    self.depth_odometry_step(fix.stamp, o, false);
                }
            }
        }
    }

    /// A SLAM pose of the body (position, heading) taken at `stamp`, registered on `inliers`
    /// matches if tracked (`None`: relocalised); `keyframe`: its frame became a keyframe.
    pub fn slam_fix(
        &mut self,
        stamp: f64,
        position: [f64; 3],
        yaw: f64,
        inliers: Option<usize>,
        keyframe: bool,
    ) {
        let before = self.ekf.estimate().position;
        let update = self.ekf.update_slam_on(stamp, position, yaw, inliers);
        let after = self.ekf.estimate().position;
        let moved = (after[0] - before[0]).hypot(after[1] - before[1]);
        if update == Update::Corrected || moved > 0.2 {
            // Where a drone's estimate jumps (a map correction, or a fix far off taken anyway).
            tracing::debug!(
                drone = self.id + 1,
                stamp,
                ?update,
                ?inliers,
                fix = ?position,
                moved_m = moved,
                "SLAM fix moved the estimate"
            );
        }
        let used = matches!(update, Update::Applied | Update::Corrected);
        if !used {
            let e = self.ekf.estimate();
            tracing::debug!(
                drone = self.id + 1,
                stamp,
                filter_t = self.ekf.time(),
                ?update,
                fix = ?position,
                estimate = ?e.position,
                vz = e.velocity[2],
                sigma = e.position_sigma,
                "SLAM fix not taken by the filter"
            );
        }
        if used {
            self.lost_at = None;
            self.lost_since = None;
            self.faced_since = None;
            if let Some(scan) = &mut self.scan
                && let Some(lost_s) = scan.found(stamp)
                && !scan.cut
            {
                tracing::info!(
                    drone = self.id + 1,
                    lost_s,
                    "the look around lost the map briefly: it goes on from where it was lost"
                );
            }
        }
        if used && keyframe {
            self.keyframe_yaw = Some(yaw);
            self.keyframe_at = Some([position[0], position[1]]);
            self.keyframe_heading = self.link.telemetry().yaw_rad.map(f64::from);
        }
    }

    /// The SLAM could not place this drone's frame taken at `stamp`: it goes back to where its
    /// last keyframe was taken, if that is within `config.lost_back_m`, else it stops where it
    /// is; a look around it was flying turns on once it is found again, or ends then if its
    /// losses add up to more than [`DroneConfig::look_lost_s`].
    pub fn slam_lost(&mut self, stamp: f64, config: &DroneConfig) {
        if let Some(scan) = &mut self.scan {
            scan.lost(stamp);
        }
        if self.lost_since.is_none() {
            self.lost_since = Some(stamp);
            self.choose_sweep(config);
        }
        if self.lost_at.is_some() {
            return;
        }
        self.lost_moving = self
            .ekf
            .valid_velocity()
            .is_none_or(|v| v[0].hypot(v[1]) > config.lost_still_mps);
        self.lost_at = self.pose().map(|p| match self.keyframe_at {
            Some(k) if (k[0] - p[0]).hypot(k[1] - p[1]) <= config.lost_back_m => k,
            _ => [p[0], p[1]],
        });
    }

    /// Visual odometry while lost or weakly placed: the body moved `previous_from_body`
    /// between its frames at `since` and `stamp`, registered on `inliers` matches if known
    /// (fewer count for less: [`EkfConfig::odometry_full_inliers`]). The filter flies on it
    /// (holding where the SLAM lost the drone, going back to the last keyframe) instead of on
    /// its model alone.
    pub fn slam_odometry(
        &mut self,
        since: f64,
        stamp: f64,
        previous_from_body: &Isometry3<f64>,
        inliers: Option<usize>,
    ) {
        self.odometry_step(since, stamp, previous_from_body, inliers, false);
    }

    /// [`Drone::slam_odometry`], of a frame the SLAM placed weakly if `weak`.
    fn odometry_step(
        &mut self,
        since: f64,
        stamp: f64,
        previous_from_body: &Isometry3<f64>,
        inliers: Option<usize>,
        weak: bool,
    ) {
        let d = previous_from_body.translation.vector;
        let update = self
            .ekf
            .update_odometry_on(since, stamp, [d.x, d.y], inliers);
        // Blind, what it drifted: as much as the filter believes (a step it gated out as an
        // outlier, a wrong registration, moves no spot held).
        if self.pose().is_none() && update == Update::Applied {
            self.blind_drift
                .add(d.x, d.y, self.ekf.estimate().attitude[2]);
        }
        tracing::debug!(
            drone = self.id + 1,
            since,
            stamp,
            forward = d.x,
            left = d.y,
            ?inliers,
            ?update,
            velocity = ?self.ekf.valid_velocity(),
            pose = self.pose().is_some(),
            lost = self.lost_since.is_some(),
            weak,
            "visual odometry"
        );
    }

    /// Odometry from the walls' depth of a frame taken at `stamp` (the camera saw no texture
    /// to register), of a frame the SLAM placed weakly if `weak`: the filter takes the motion
    /// along the directions the walls measure ([`Ekf::update_odometry_along`]).
    fn depth_odometry_step(&mut self, stamp: f64, odometry: &DepthOdometry, weak: bool) {
        let update = self
            .ekf
            .update_odometry_along(odometry.since, stamp, &odometry.along);
        let [forward, left] = odometry.displacement();
        // Blind, what it drifted: as far as the walls measure.
        if self.pose().is_none() && update == Update::Applied {
            self.blind_drift
                .add(forward, left, self.ekf.estimate().attitude[2]);
        }
        tracing::debug!(
            drone = self.id + 1,
            since = odometry.since,
            stamp,
            forward,
            left,
            directions = odometry.along.len(),
            matches = odometry.matches,
            ?update,
            velocity = ?self.ekf.valid_velocity(),
            pose = self.pose().is_some(),
            lost = self.lost_since.is_some(),
            weak,
            "depth odometry"
        );
    }

    /// The filter's roll and pitch (radians): the attitude the vehicle reports, else what the
    /// sticks sent make of it.
    pub fn tilt(&self) -> [f64; 2] {
        let a = self.ekf.estimate().attitude;
        [a[0], a[1]]
    }

    /// One control tick at mission time `now`.
    pub fn tick(&mut self, now: f64, config: &DroneConfig) -> Option<DroneEvent> {
        let dt = self.last_tick.map_or(0.1, |t| (now - t).clamp(0.01, 1.0));
        self.last_tick = Some(now);
        let telemetry = self.link.telemetry();
        // The filter: predict to now, then what the vehicle measured. A stamped heading and
        // attitude are taken once, at the time they arrived (a tenth of a second before this
        // tick, typically: 1–2° behind in a turn if taken as now).
        self.ekf.predict(now);
        if let Some(yaw) = telemetry.yaw_rad
            && self.lost_since.is_none()
            && self.blind_since.is_none()
        {
            self.recent_turn.observe(now, f64::from(yaw));
        }
        if let Some(heading_t) = heading_time(&telemetry, self.heading_taken, now) {
            self.heading_taken = telemetry.heading_at;
            if let Some(yaw) = telemetry.yaw_rad {
                self.ekf.update_heading(heading_t, f64::from(yaw));
            }
            if let Some(a) = telemetry.attitude {
                self.ekf
                    .update_attitude(heading_t, f64::from(a.roll), f64::from(a.pitch));
            }
        }
        let on_ground = matches!(self.phase, Phase::Idle | Phase::Arming | Phase::Landed)
            || telemetry.armed == Some(false);
        if on_ground && telemetry.armed == Some(false) {
            // At rest: what the sag of the next flight is measured against.
            self.gauge
                .at_rest(now, telemetry.battery.as_ref(), &config.battery);
        }
        if let Some(h) = telemetry.height_m {
            self.ekf.update_height(now, f64::from(h));
        }
        if on_ground {
            self.ekf.set_input(Input::default());
        }
        if let Some(p) = self.pose() {
            if let Some((_, last)) = self.trajectory.last() {
                self.path_length += (p[0] - last[0]).hypot(p[1] - last[1]);
            }
            self.trajectory.push((now, p));
        }
        // The link.
        let status = self.link.status();
        if status.state == LinkState::Lost && self.phase != Phase::Landed {
            if self.phase != Phase::LinkLost {
                self.say(
                    "link lost: its goal goes to the others; the vehicle's failsafe lands it"
                        .into(),
                );
                self.leave_mission("link lost");
                self.lost_in = Some(self.phase);
                self.phase = Phase::LinkLost;
                self.goal = None;
                self.set_path(vec![]);
            }
            return None;
        }
        if self.phase == Phase::LinkLost {
            let before = self.lost_in.take().unwrap_or(Phase::Exploring);
            let flying = telemetry.armed == Some(true) && telemetry.mode.as_deref() != Some("LAND");
            self.phase = if flying && before.flying() {
                self.say("link back: resuming".into());
                self.left_mission = None;
                Phase::Exploring
            } else if telemetry.armed == Some(true) {
                self.say("link back: the vehicle is landing by its failsafe".into());
                self.landing_by = LandingBy::Vehicle;
                Phase::Landing
            } else {
                self.say("link back: the vehicle is on the ground".into());
                Phase::Landed
            };
        }
        // Commands in flight.
        if let Some((command, result)) = self.answer() {
            self.on_answer(command, result);
        }
        // The vehicle lands on its own (ArduPilot's battery or EKF failsafe, a pilot): follow it.
        if !self.phase.flying() || telemetry.armed != Some(false) {
            self.disarmed_since = None;
        }
        if self.phase.flying() {
            if telemetry.mode.as_deref() == Some("LAND") {
                self.say(
                    "the vehicle is landing on its own (LAND mode: its failsafe or its pilot)"
                        .into(),
                );
                self.leave_mission("its vehicle landed it (LAND mode)");
                self.set_sticks(Sticks::CENTRED); // no stick may reposition it
                self.phase = Phase::Landing;
                self.landing_by = LandingBy::Vehicle;
                self.goal = None;
                self.set_path(vec![]);
                self.landing_since = Some(now);
            } else if telemetry.armed == Some(false) {
                let since = *self.disarmed_since.get_or_insert(now);
                if now - since >= config.disarmed_landed_s {
                    self.say("the vehicle disarmed on its own: landed".into());
                    self.leave_mission("its vehicle disarmed");
                    self.disarmed_since = None;
                    self.phase = Phase::Landed;
                    self.goal = None;
                    self.set_path(vec![]);
                    self.link.set_sticks(None);
                    self.sticks = None;
                    return None;
                }
            }
        }
        match self.phase {
            Phase::Idle | Phase::Landed | Phase::LinkLost => return None,
            Phase::Arming => {
                return None;
            }
            Phase::Landing => {
                if !self.landing_step(now, &telemetry, config) {
                    return None;
                }
            }
            Phase::TakingOff | Phase::Exploring | Phase::Holding | Phase::Returning => {}
        }
        // A camera gone silent: no more mapping, home.
        if let Some(last) = self.last_frame
            && self.phase == Phase::Exploring
            && now - last > config.camera_timeout_s
        {
            self.return_home(&format!("no camera frame for {:.0} s", now - last));
        }
        // Low battery, for the way home from here: home. The way on the last map, or, longer,
        // the straight line (the map's way may be a few seconds old).
        let straight_home = self
            .start
            .zip(self.plan_position(config))
            .map(|([x, y, _], p)| (p[0] - x).hypot(p[1] - y));
        let home_m = self
            .way_home_m
            .into_iter()
            .chain(straight_home)
            .reduce(f64::max);
        if let Some(low) = self
            .gauge
            .low(now, telemetry.battery.as_ref(), home_m, &config.battery)
            && matches!(
                self.phase,
                Phase::Exploring | Phase::TakingOff | Phase::Holding
            )
        {
            self.awaits_battery = config.battery_swap.is_some();
            if let Some(way) = &low.way_home {
                self.say(format!("{}: {way}", low.reading));
            }
            self.return_home(&low.reading);
        }
        let Some(pose) = self.pose() else {
            return self.fly_blind(
                now,
                config,
                telemetry.height_m,
                telemetry.yaw_rad.map(f64::from),
            );
        };
        self.blind_since = None;
        self.blind_drift = Drift::default();
        self.tracking = false;
        let here = [pose[0], pose[1]];
        // The map's walls all round, for the moment it goes blind (the camera sees only ahead).
        if let (Some(map), Some(heading)) = (&self.map, telemetry.yaw_rad) {
            let around = nav::proximity::map_readings(map, here, pose[3], &config.proximity);
            self.proximity
                .observe(now, f64::from(heading), &around, &config.proximity);
        }
        let mut event = None;
        let lost = self
            .lost_at
            .filter(|_| matches!(self.phase, Phase::Exploring | Phase::Returning));
        let lost_for = self.lost_since.map_or(0.0, |since| now - since);
        if lost.is_some() && lost_for > config.blind_land_s {
            let why = format!("lost by the SLAM for {:.0} s", config.blind_land_s);
            self.leave_mission(&why);
            self.say(format!("{why}: landing where it is"));
            self.land();
            return None;
        }
        // Past the turn back, a slow sweep round on the spot over every other view.
        let sweep = match self.lost_since.filter(|_| lost.is_some()) {
            Some(since) => {
                self.turn_back_over(now, since, telemetry.yaw_rad.map(f64::from), config)
            }
            None => false,
        };
        if let Some(at) = lost {
            // The SLAM lost it, the filter still carries the pose (on visual odometry while
            // the camera sees enough, else on its model for a few seconds): stop where that
            // happened (not on along the path, out of what the camera knew) and face where
            // the last keyframe was taken, so the camera sees the map again.
            self.hold = at;
            if let Some(yaw) = self.keyframe_yaw {
                self.yaw_goal = if sweep { pose[3] } else { yaw };
            }
            self.progress = (now, here);
        }
        match self.phase {
            _ if lost.is_some() => {}
            Phase::TakingOff => {
                if pose[2] > self.altitude - 0.1 {
                    // Airborne: look around once, so the first plan sees every side.
                    self.phase = Phase::Exploring;
                    let mut scan = self.look_around(now, pose, None, config);
                    if let Some(turn) = self.first_look_turn.take() {
                        scan.direction = turn;
                        scan.shared = true;
                    }
                    self.scan = Some(scan);
                    self.progress = (now, here);
                }
            }
            Phase::Exploring => event = self.explore_step(now, dt, pose, config),
            Phase::Returning => {
                let home = self.goal.unwrap_or(here);
                if (home[0] - here[0]).hypot(home[1] - here[1]) < config.home_reach_m {
                    self.say("home: landing".into());
                    self.land();
                    return None;
                }
                self.follow(pose);
            }
            // Braking before LAND: held where it was told to land.
            Phase::Holding | Phase::Landing => {}
            _ => return None,
        }
        self.setpoint = match &self.map {
            Some(map) if self.tracking => keep_clear(map, here, self.hold, &config.keep_clear),
            Some(map) => {
                let room = KeepClear {
                    clearance_m: config.keep_clear.clearance_m.max(config.hold_clearance_m),
                    ..config.keep_clear
                };
                keep_clear(map, here, self.hold, &room)
            }
            None => self.hold,
        };
        // Holding a spot (a look around, a turn, found again after a loss), the derivative
        // terms follow the spot, which stands still: they brake any motion, wherever
        // `keep_clear` steers (steering from the drone's position, the steer point moves with
        // it and shows nothing to brake: drones coasted on into walls at 0.4 m/s). Pursuing a
        // carrot, they follow the steer point: the carrot moves with the drone anyway, and the
        // push off a wall is not braked (following the carrot, drones flew nearer the walls).
        let moving = if self.tracking {
            self.setpoint
        } else {
            self.hold
        };
        let setpoint = Pose3 {
            x: moving[0],
            y: moving[1],
            z: self.height_goal,
            yaw: self.yaw_goal,
        };
        let estimate = Pose3 {
            x: pose[0],
            y: pose[1],
            z: pose[2],
            yaw: pose[3],
        };
        // Another path's carrot or another spot to hold: a new target, not one moving.
        let target = if self.tracking {
            Target::Path(self.paths)
        } else {
            Target::Hold(self.hold)
        };
        if self.flown.replace(target).is_some_and(|was| was != target) {
            self.controller.target_jumps();
        }
        let cruise = self.tracking && config.cruise_ff > 0.0;
        self.controller.integrate_xy(!cruise);
        let mut c = self
            .controller
            .update_steered(&setpoint, self.setpoint, &estimate, dt);
        let ahead = [self.setpoint[0] - here[0], self.setpoint[1] - here[1]];
        let lead = ahead[0].hypot(ahead[1]);
        let speed = self.speed_limit.min(config.follower.max_speed_mps);
        let velocity = self.ekf.valid_velocity();
        // Pursuing a carrot with a velocity to fly on, the speed loop flies it instead of the
        // position loop: the velocity toward the carrot (the steer point) at the speed allowed,
        // no faster toward a wall than can stop short of it.
        let flies_velocity = match velocity {
            Some(v) if cruise && speed.is_finite() && config.speed_gain > 0.0 => {
                let want = carrot_velocity(ahead, speed);
                let want = self.map.as_ref().map_or(want, |map| {
                    limit_approach(map, here, want, &config.keep_clear)
                });
                let [bx, by] = speed_loop(want, v, config);
                let (s, co) = estimate.yaw.sin_cos();
                c.pitch = co * bx + s * by;
                c.roll = s * bx - co * by;
                true
            }
            _ => false,
        };
        if cruise && !flies_velocity && lead > 1e-6 && speed.is_finite() {
            // Toward the carrot (the steer point), in the body frame.
            let push = config.cruise_ff * speed / lead;
            let (s, co) = estimate.yaw.sin_cos();
            let (bx, by) = (ahead[0] * push, ahead[1] * push);
            c.pitch = (c.pitch + co * bx + s * by).clamp(-1.0, 1.0);
            c.roll = (c.roll + s * bx - co * by).clamp(-1.0, 1.0);
        }
        // Near a wall the controller flies even a small error: its derivative term brakes; so
        // does a drone braking to land (it is still moving).
        if !self.tracking
            && !self.landing_by.braking()
            && self.setpoint == self.hold
            && (setpoint.x - estimate.x).hypot(setpoint.y - estimate.y) < config.hold_band_m
        {
            (c.roll, c.pitch) = (0.0, 0.0);
        }
        // An approach to a wall faster than can stop short of it is braked: `keep_clear`'s
        // steer point moves with the drone, so the derivative terms see no drift toward a
        // jamb while pursuing a carrot. Without the speed loop, a drone pursuing a carrot is
        // also braked to the speed the follower allows (into a sharp bend, no faster than it
        // can take it).
        if let Some(velocity) = velocity {
            let [wx, wy] = self.map.as_ref().map_or([0.0; 2], |map| {
                brake_toward_walls(map, here, velocity, &config.keep_clear)
            });
            let [sx, sy] = if self.tracking && !flies_velocity {
                brake_to_speed(velocity, self.speed_limit, &config.keep_clear)
            } else if self.landing_by.braking() {
                // Braking to land: to a stop, as hard as for a wall.
                brake_to_speed(velocity, 0.0, &config.keep_clear)
            } else {
                [0.0; 2]
            };
            let (bx, by) = (wx + sx, wy + sy);
            let (s, co) = estimate.yaw.sin_cos();
            let (forward, left) = (co * bx + s * by, -s * bx + co * by);
            c.pitch = (c.pitch + forward).clamp(-1.0, 1.0);
            c.roll = (c.roll - left).clamp(-1.0, 1.0);
        }
        if lost.is_some() && !self.lost_moving {
            let max = config.lost_stick_max;
            c.roll = c.roll.clamp(-max, max);
            c.pitch = c.pitch.clamp(-max, max);
        }
        if sweep {
            c.yaw = f64::from(self.sweep_yaw(config));
        }
        if self.landing_by == LandingBy::Station {
            // Held on its pose as it comes down: the descent is the shield's own (it keeps the
            // throttle), and the filter predicts it from the stick it holds.
            c.throttle = f64::from(link::shield::LAND_THROTTLE);
        }
        self.set_sticks(Sticks {
            roll: c.roll as f32,
            pitch: c.pitch as f32,
            yaw: c.yaw as f32,
            throttle: c.throttle as f32,
        });
        event
    }

    /// Whether the turn back of a drone lost since `since` (its IMU reading `heading` now) is
    /// over: after [`DroneConfig::blind_turn_back_s`], or once it has faced its last
    /// keyframe's heading for [`DroneConfig::blind_face_s`] without being found again.
    fn turn_back_over(
        &mut self,
        now: f64,
        since: f64,
        heading: Option<f64>,
        config: &DroneConfig,
    ) -> bool {
        let facing = self
            .keyframe_heading
            .zip(heading)
            .is_some_and(|(k, h)| wrap_angle(k - h).abs() < FACING_RAD);
        if facing {
            self.faced_since.get_or_insert(now);
        }
        now - since >= config.blind_turn_back_s
            || self
                .faced_since
                .is_some_and(|t| now - t >= config.blind_face_s)
    }

    /// No valid pose: hover level with altitude held (thesis Algorithm 7) — braking the drift
    /// while visual odometry measures it — climbing only to finish a take-off, turning back to
    /// the heading of the last keyframe, then slowly round so the camera sweeps over known
    /// views; land after too long.
    fn fly_blind(
        &mut self,
        now: f64,
        config: &DroneConfig,
        height: Option<f32>,
        heading: Option<f64>,
    ) -> Option<DroneEvent> {
        // Blind since the SLAM lost it, if it flew on visual odometry in between.
        if self.blind_since.is_none() && self.lost_since.is_none() {
            self.choose_sweep(config);
        }
        let since = *self
            .blind_since
            .get_or_insert(self.lost_since.map_or(now, |lost| lost.min(now)));
        if now - since > config.blind_land_s {
            let why = format!("no pose for {:.0} s", config.blind_land_s);
            self.leave_mission(&why);
            self.say(format!("{why}: landing where it is"));
            self.land();
            return None;
        }
        let low = height.is_some_and(|h| f64::from(h) < self.altitude - 0.1);
        let climb = if self.phase == Phase::TakingOff && low {
            0.4
        } else {
            0.0
        };
        self.controller.reset();
        // First back to the heading of the last keyframe (the camera lost the map turning away
        // from it, mostly during a look around, to a far wall beyond its depth range), then a
        // slow turn over every other view.
        let turning_back = !self.turn_back_over(now, since, heading, config);
        let yaw = match (self.keyframe_heading, heading) {
            (Some(fixed), Some(heading)) if turning_back => {
                let off = wrap_angle(fixed - heading);
                // Clockwise sticks are positive; full turn rate beyond 0.3 rad off.
                -config.blind_yaw * (off / 0.3).clamp(-1.0, 1.0) as f32
            }
            _ => self.sweep_yaw(config),
        };
        // Level, unless visual odometry still measures how the drone drifts: then against it,
        // and back to where it went blind.
        let [mut roll, mut pitch] = self.ekf.valid_velocity().map_or([0.0; 2], |v| {
            hold_blind(
                self.blind_drift.moved,
                v,
                self.ekf.estimate().attitude[2],
                config,
            )
        });
        // And off the walls round it, ranged by the camera or on the map before it went blind
        // (it drifts with the air meanwhile).
        if let Some(heading) = heading {
            let [forward, left] = self.proximity.push(now, heading, &config.proximity);
            let pushing = forward != 0.0 || left != 0.0;
            if pushing && !self.pushed_off {
                tracing::debug!(
                    drone = self.id + 1,
                    stamp = now,
                    nearest_m = self.proximity.nearest(now, &config.proximity),
                    forward,
                    left,
                    "without a pose near a wall: leaning off it"
                );
            }
            self.pushed_off = pushing;
            pitch = (f64::from(pitch) + forward).clamp(-1.0, 1.0) as f32;
            roll = (f64::from(roll) - left).clamp(-1.0, 1.0) as f32;
        }
        self.set_sticks(Sticks {
            roll,
            pitch,
            throttle: climb,
            yaw,
        });
        None
    }

    /// At a loss (or going blind), which way its sweep will turn: back counter-clockwise if it
    /// was turning clockwise ([`DroneConfig::blind_sweep_back_rad`]).
    fn choose_sweep(&mut self, config: &DroneConfig) {
        self.sweep_back = self.recent_turn.turned() < -config.blind_sweep_back_rad;
    }

    /// The yaw stick of a lost drone's slow sweep: [`DroneConfig::blind_yaw`], counter-clockwise
    /// if it was lost turning clockwise ([`DroneConfig::blind_sweep_back_rad`]).
    fn sweep_yaw(&self, config: &DroneConfig) -> f32 {
        if self.sweep_back {
            -config.blind_yaw
        } else {
            config.blind_yaw
        }
    }

    /// The nearest wall it keeps in mind at `now` (camera and map ranges by heading; what it
    /// leans off when blind), metres; `None` when none was ranged lately.
    pub fn nearest_wall(&self, now: f64, config: &DroneConfig) -> Option<f64> {
        self.proximity.nearest(now, &config.proximity)
    }

    /// A path for the follower (empty: none).
    fn set_path(&mut self, path: Vec<[f64; 2]>) {
        self.paths += 1;
        self.follower.set_path(path);
    }

    fn follow(&mut self, pose: [f64; 4]) -> Follow {
        let f = self.follower.step(Some(Pose2 {
            x: pose[0],
            y: pose[1],
            yaw: pose[3],
        }));
        match f {
            Follow::Turn { at, yaw } => {
                // Hold where the turn began: a spot that slid along the path with the drone
                // would let it coast on through the turn (into a door's jamb).
                if !self.turning {
                    self.hold = at;
                }
                self.turning = true;
                self.yaw_goal = yaw;
            }
            Follow::Track {
                carrot,
                yaw,
                speed_mps,
            } => {
                self.tracking = true;
                self.speed_limit = speed_mps;
                self.turning = false;
                self.hold = carrot;
                self.yaw_goal = yaw;
            }
            Follow::Hover | Follow::Arrived => self.turning = false,
        }
        f
    }

    /// A look around from `pose`, turning the short way to what the map shows unknown.
    fn look_around(
        &self,
        now: f64,
        pose: [f64; 4],
        give_up: Option<[f64; 2]>,
        config: &DroneConfig,
    ) -> Scan {
        let mut scan = Scan::new(now, pose[3], give_up, config);
        if let (Some(view), Some(map)) = (self.view(config), &self.map) {
            let here = [pose[0], pose[1]];
            scan.direction = if config.look_most_unknown_first {
                let cells = sweep::unknown_cells(map, here, &view, SWEEP_BEARINGS);
                sweep::direction_most_unknown_first(&cells, pose[3], &view)
            } else {
                let unknown = sweep::unknown_bearings(map, here, &view, SWEEP_BEARINGS);
                sweep::direction(&unknown, pose[3], &view)
            };
        }
        scan
    }

    /// What its camera sees for a look around: [`DroneConfig::sweep`] with the field of view
    /// of its own camera, once a frame has told it; `None` for a whole turn.
    fn view(&self, config: &DroneConfig) -> Option<View> {
        let view = config.sweep?;
        Some(self.camera_half_fov.map_or(view, |h| view.for_camera(h)))
    }

    /// Whether the look around `scan`, its heading goal `swept` radians on, has unknown
    /// bearings ahead of the camera still (always, without a map or with sweeps off).
    fn unknown_ahead(&self, here: [f64; 2], scan: &Scan, swept: f64, config: &DroneConfig) -> bool {
        let (Some(view), Some(map)) = (self.view(config), &self.map) else {
            return true;
        };
        let unknown = sweep::unknown_bearings(map, here, &view, SWEEP_BEARINGS);
        sweep::still_unknown_ahead(&unknown, scan.yaw0, scan.direction, swept, &view)
    }

    fn explore_step(
        &mut self,
        now: f64,
        dt: f64,
        pose: [f64; 4],
        config: &DroneConfig,
    ) -> Option<DroneEvent> {
        let here = [pose[0], pose[1]];
        if (here[0] - self.progress.1[0]).hypot(here[1] - self.progress.1[1]) > 0.3 {
            self.progress = (now, here);
        }
        if let Some(scan) = self.scan.as_mut()
            && self.inliers.is_some_and(|n| n < config.look_slow_inliers)
        {
            // On few matches the turn's clock runs at half speed.
            scan.since += 0.5 * dt;
        }
        if let Some(scan) = self.scan {
            // A turn on the spot (36°/s) until nothing unknown is left to look at, at most a
            // whole one, then the goal (if any) is given up.
            let t = now - scan.since;
            let swept = t * std::f64::consts::TAU / config.scan_s;
            let more = t < config.scan_min_s
                || (!scan.seen_by_all && self.unknown_ahead(here, &scan, swept, config));
            if t < config.scan_s && !scan.cut && more {
                self.yaw_goal = scan.yaw0 + scan.direction * swept;
                self.progress = (now, here);
                return None;
            }
            if scan.cut {
                tracing::info!(
                    drone = self.id + 1,
                    "the look around lost the map: it ends where the map was found again"
                );
            }
            tracing::debug!(
                drone = self.id + 1,
                seconds = t,
                turned_deg = (scan.direction * swept).to_degrees(),
                "look around over"
            );
            self.scan = None;
            self.awaits_plan = Some(now);
            return scan.give_up.map(|goal| {
                if scan.cut {
                    DroneEvent::LookCut(goal, scan.direction)
                } else {
                    DroneEvent::GiveUp(goal)
                }
            });
        }
        if let Follow::Arrived = self.follow(pose) {
            self.set_path(vec![]);
            if self.goal.is_none() {
                // Waiting behind another drone's frontier: held here, ready for the next plan
                // (a look around would keep it from one for seconds).
                self.hold = here;
                return None;
            }
            let goal = self.goal.take();
            let mut scan = self.look_around(now, pose, goal, config);
            if let Some(turn) = self.look_turn.take() {
                tracing::info!(
                    drone = self.id + 1,
                    "its last look around here lost the map: this one turns the other way"
                );
                scan.direction = turn;
            }
            self.scan = Some(scan);
            self.hold = here;
            return None;
        }
        if self.goal.is_some() && now - self.progress.0 > config.stuck_s {
            tracing::warn!(
                drone = self.id + 1,
                "no progress for {} s: giving up its goal",
                config.stuck_s
            );
            self.set_path(vec![]);
            self.progress = (now, here);
            self.awaits_plan = Some(now);
            return self.goal.take().map(DroneEvent::GiveUp);
        }
        None
    }

    fn on_answer(&mut self, command: Command, result: Result<(), CommandError>) {
        if let Err(e) = &result {
            self.say(format!("{e}"));
        }
        match (self.phase, command, result.is_ok()) {
            (Phase::Arming, Command::SetMode(_), true) => self.send(Command::Arm),
            (Phase::Arming, Command::Arm, true) => match self.start_sequence {
                StartSequence::Mavlink => self.airborne_next(),
                StartSequence::Shield => self.send(Command::StartMotors),
            },
            (Phase::Arming, Command::StartMotors, true) => self.airborne_next(),
            (Phase::Arming, _, false) => {
                self.link.set_sticks(None);
                self.phase = Phase::Idle;
            }
            (Phase::Landing, Command::Land, false) => {
                // Land refused: keep trying from the next tick.
                self.send(Command::Land);
            }
            _ => {}
        }
    }

    fn airborne_next(&mut self) {
        self.say("armed: taking off".into());
        self.phase = Phase::TakingOff;
        self.height_goal = self.altitude;
        let e = self.ekf.estimate();
        self.hold = [e.position[0], e.position[1]];
        self.yaw_goal = e.attitude[2];
        self.controller.reset();
    }
}

/// The mission time at which the filter takes the telemetry's heading and attitude, read at
/// `now`: when they arrived, if the link stamps them and they are new since the arrival `taken`
/// last (`None`: nothing new); `now` for a link that does not stamp them.
fn heading_time(telemetry: &Telemetry, taken: Option<Duration>, now: f64) -> Option<f64> {
    let new = telemetry.heading_at.is_none() || telemetry.heading_at != taken;
    new.then(|| telemetry.heading_time(now))
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use link::{LinkStatus, StatusText};

    use super::*;
    use slam::system::Odometry;

    /// A vehicle that accepts every command and stays armed whatever it is told (unless a
    /// test disarms it or changes its mode, as its own failsafe would).
    #[derive(Default)]
    struct StubbornVehicle {
        commands: Mutex<Vec<Command>>,
        disarmed: std::sync::atomic::AtomicBool,
        mode: Mutex<Option<String>>,
        yaw: Mutex<Option<f32>>,
        /// Its link reports itself lost.
        lost: std::sync::atomic::AtomicBool,
        /// Battery charge it reports, percent.
        battery_pct: Mutex<Option<u8>>,
    }

    impl VehicleLink for StubbornVehicle {
        fn name(&self) -> String {
            "stubborn".into()
        }
        fn set_sticks(&self, _sticks: Option<Sticks>) {}
        fn command(&self, command: Command) -> Result<(), CommandError> {
            self.commands
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push(command);
            Ok(())
        }
        fn telemetry(&self) -> Telemetry {
            Telemetry {
                armed: Some(!self.disarmed.load(std::sync::atomic::Ordering::Relaxed)),
                mode: self
                    .mode
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .clone(),
                height_m: Some(0.9),
                battery: self
                    .battery_pct
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .map(|pct| link::Battery {
                        voltage_v: 11.0,
                        remaining_pct: Some(pct),
                    }),
                yaw_rad: *self
                    .yaw
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner),
                ..Telemetry::default()
            }
        }
        fn status(&self) -> LinkStatus {
            LinkStatus {
                state: if self.lost.load(std::sync::atomic::Ordering::Relaxed) {
                    LinkState::Lost
                } else {
                    LinkState::Connected
                },
                last_message_age: Some(std::time::Duration::from_millis(50)),
                transport_up: true,
                connections: 1,
                frames_ok: 1,
                frames_bad: 0,
            }
        }
        fn take_status_texts(&self) -> Vec<StatusText> {
            vec![]
        }
    }

    #[test]
    fn a_stamped_heading_is_taken_once_at_its_arrival() {
        let stamped = |at: f64| Telemetry {
            yaw_rad: Some(0.3),
            heading_at: Some(Duration::from_secs_f64(at)),
            ..Telemetry::default()
        };
        // New: taken at its arrival, not at the tick that reads it (times a binary fraction
        // of a second, exact through a Duration).
        assert_eq!(heading_time(&stamped(1.875), None, 2.0), Some(1.875));
        let taken = stamped(1.875).heading_at;
        assert_eq!(heading_time(&stamped(2.0625), taken, 2.125), Some(2.0625));
        // Read again before the next one arrives: not taken twice.
        assert_eq!(heading_time(&stamped(1.875), taken, 2.125), None);
        // A stamp ahead of the reader's clock is taken as now.
        assert_eq!(heading_time(&stamped(2.5), taken, 2.125), Some(2.125));
        // A link that does not stamp: every reading, at its reading.
        let unstamped = Telemetry {
            yaw_rad: Some(0.3),
            ..Telemetry::default()
        };
        assert_eq!(heading_time(&unstamped, None, 2.1), Some(2.1));
        assert_eq!(heading_time(&unstamped, None, 2.2), Some(2.2));
    }

    fn exploring_drone(vehicle: Arc<StubbornVehicle>, config: &DroneConfig) -> Drone {
        let mut drone = Drone::new(
            0,
            DroneSpec {
                name: "drone 1".into(),
                link: vehicle,
                start_sequence: StartSequence::Mavlink,
                altitude: 0.9,
                start: Some([0.0, 0.0, 0.0]),
            },
            config,
            0.0,
        );
        drone.phase = Phase::Exploring;
        drone
    }

    #[test]
    fn a_drone_whose_fixes_come_late_for_a_moment_is_still_planned_from() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::new(StubbornVehicle::default()), &config);
        drone.slam_fix(0.0, [0.5, 0.0, 0.9], 0.0, None, true);
        drone.set_plan(Some([5.0, 0.0]), vec![[0.5, 0.0], [5.0, 0.0]], None, 0.0);
        // No fix for a moment: too uncertain to fly on, not to choose a frontier from.
        let mut t = 0.0;
        while drone.pose().is_some() {
            t += 0.1;
            drone.tick(t, &config);
            assert!(t < 5.0, "a pose without fixes must expire");
        }
        let expired = t;
        let e = drone.ekf.estimate();
        assert_eq!(
            drone.plan_position(&config),
            Some([e.position[0], e.position[1]]),
            "still planned from, where the filter has it"
        );
        assert_eq!(drone.goal, Some([5.0, 0.0]), "its goal is kept meanwhile");
        // Without fixes for longer, it is not planned from either.
        while drone.plan_position(&config).is_some() {
            t += 0.1;
            drone.tick(t, &config);
            assert!(t < 20.0, "a planning position without fixes must expire");
        }
        assert!(
            t > expired + 0.5,
            "expired at {t} s, the pose at {expired} s"
        );
    }

    #[test]
    fn a_goal_the_planner_keeps_taking_back_and_moving_is_still_given_up_when_not_reached() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::new(StubbornVehicle::default()), &config);
        // Held where it is (against a wall, say): the SLAM places it at the start every tick.
        // The planner gives its goal at one plan, a few centimetres on, and takes it back at the
        // next.
        let mut t = 0.0;
        let (mut first, mut given_up) = (None, None);
        while t < config.stuck_s + 5.0 && given_up.is_none() {
            t += 0.1;
            drone.slam_fix(t, [0.0, 0.0, 0.9], 0.0, None, false);
            let plan = (t * 10.0).round() as u32;
            if plan.is_multiple_of(10) {
                let goal = (plan / 10).is_multiple_of(2).then(|| {
                    let g = [3.0, 0.05 * f64::from(plan % 3)];
                    (g, vec![[0.0, 0.0], g])
                });
                let (goal, path) = goal.map_or((None, vec![]), |(g, p)| (Some(g), p));
                first = first.or(goal.map(|_| t));
                drone.set_plan(goal, path, None, t);
            }
            if let Some(DroneEvent::GiveUp(g)) = drone.tick(t, &config) {
                given_up = Some((t, g));
            }
        }
        let (at, goal) = given_up.expect("the goal is given up");
        assert!((goal[0] - 3.0).abs() < 1e-9, "{goal:?}");
        // At the first tick it holds the goal after the stuck time from the first plan with it.
        let first = first.expect("a goal was given");
        assert!(
            at > first + config.stuck_s && at < first + config.stuck_s + 1.5,
            "given up at {at} s, first given at {first} s"
        );
        // Another frontier restarts the clock.
        drone.set_plan(Some([0.0, 3.0]), vec![[0.0, 0.0], [0.0, 3.0]], None, t);
        for _ in 0..20 {
            t += 0.1;
            drone.slam_fix(t, [0.0, 0.0, 0.9], 0.0, None, false);
            assert_eq!(drone.tick(t, &config), None, "at {t} s");
        }
    }

    #[test]
    fn a_drone_whose_camera_falls_silent_goes_home() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        // No camera watched before its first frame.
        drone.tick(config.camera_timeout_s + 1.0, &config);
        assert_eq!(drone.phase, Phase::Exploring);
        let mut t = 10.0;
        while t < 20.0 {
            drone.camera_frame(t, 0.55);
            drone.tick(t, &config);
            t += 0.1;
        }
        assert_eq!(drone.phase, Phase::Exploring, "frames every 0.1 s");
        let last = t - 0.1;
        while t < last + config.camera_timeout_s - 0.2 {
            drone.tick(t, &config);
            t += 0.1;
        }
        assert_eq!(drone.phase, Phase::Exploring, "not yet");
        drone.tick(last + config.camera_timeout_s + 0.2, &config);
        assert_eq!(drone.phase, Phase::Returning);
        assert_eq!(drone.goal, Some([0.0, 0.0]));
        assert!(
            drone
                .take_messages()
                .iter()
                .any(|m| m.contains("no camera frame for 5 s")),
        );
        assert_eq!(
            drone.left_mission.as_deref(),
            Some("no camera frame for 5 s")
        );
        // Home, landing there keeps why it left.
        drone.land();
        assert_eq!(
            drone.left_mission.as_deref(),
            Some("no camera frame for 5 s")
        );
    }

    #[test]
    fn holding_still_an_error_within_the_band_is_not_flown_a_larger_one_is_flown_back() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        // Looking around at the start (0, 0), facing +x.
        drone.scan = Some(Scan::new(0.0, 0.0, None, &config));
        drone.hold = [0.6 * config.hold_band_m, 0.0];
        drone.tick(0.1, &config);
        let s = drone.sticks.expect("sticks");
        assert_eq!((s.roll, s.pitch), (0.0, 0.0), "{s:?}");
        drone.hold = [3.0 * config.hold_band_m, 0.0];
        drone.tick(0.2, &config);
        let s = drone.sticks.expect("sticks");
        // Mostly forward (the heading has moved a little with the look around).
        assert!(
            s.pitch > 0.0 && s.roll.abs() < 0.05 * s.pitch,
            "forward, to +x: {s:?}"
        );
    }

    #[test]
    fn a_drone_is_never_steered_toward_a_wall_of_the_map_within_its_clearance() {
        let config = DroneConfig::default();
        // Looking around at (0, 0) facing +x, its hold 0.5 m ahead; a wall's face 0.3 m ahead.
        let scanning = |map: Option<Grid>| {
            let mut drone = exploring_drone(Arc::default(), &config);
            drone.scan = Some(Scan::new(0.0, 0.0, None, &config));
            drone.hold = [0.5, 0.0];
            if let Some(map) = map {
                drone.set_map(Arc::new(map));
            }
            drone.tick(0.1, &config);
            (drone.sticks.expect("sticks"), drone.setpoint())
        };
        let (open, _) = scanning(None);
        assert!(open.pitch > 0.0, "no map: toward the hold, {open:?}");
        let mut map = Grid::new(40, 40, 0.05, [-1.0, -1.0], nav::Cell::Free);
        for y in 0..40 {
            map.set((26, y), nav::Cell::Occupied); // x = 0.30–0.35 m
        }
        let (walled, setpoint) = scanning(Some(map));
        assert!(walled.pitch < 0.0, "led back from the wall: {walled:?}");
        // Holding a spot: out to the hold's clearance, not just the path's.
        assert!(
            (setpoint[0] - (0.3 - config.hold_clearance_m)).abs() < 0.05,
            "out to {} m from the wall: {setpoint:?}",
            config.hold_clearance_m
        );
    }

    #[test]
    fn a_drone_holding_its_spot_beside_a_wall_brakes_its_drift() {
        let config = DroneConfig::default();
        // A wall's face 0.4 m north of the line the drone drifts along: `keep_clear` shortens
        // its lead there, so the steer point moves with the drone.
        let mut map = Grid::new(80, 40, 0.05, [-3.0, -1.0], nav::Cell::Free);
        for x in 0..80 {
            map.set((x, 28), nav::Cell::Occupied); // y = 0.40–0.45
        }
        let mut drone = exploring_drone(Arc::default(), &config);
        drone.set_map(Arc::new(map));
        // Looking around its hold (0, 0), facing +x, coasting west at 0.4 m/s past it.
        drone.scan = Some(Scan::new(0.0, 0.0, None, &config));
        drone.hold = [0.0, 0.0];
        let mut sticks = vec![];
        for i in 1..=6 {
            let t = 0.1 * f64::from(i);
            drone.slam_fix(t, [-0.3 - 0.4 * t, 0.0, 0.9], 0.0, None, false);
            drone.tick(t, &config);
            sticks.push(f64::from(drone.sticks.expect("sticks").pitch));
        }
        // Braked by the derivative (0.6 × 0.4 m/s) on top of the pull back to the hold.
        let kd = config.gains.x.kd;
        assert!(
            sticks[2..].iter().all(|&p| p > kd * 0.4),
            "back toward +x, against the drift: {sticks:?}"
        );
    }

    #[test]
    fn a_drone_drifting_toward_a_wall_along_its_path_is_braked() {
        // A wall's face 0.55 m north of a path east along y = 0: farther than the clearance,
        // so `keep_clear` only shortens the lead (its steer point moves with the drone).
        let mut map = Grid::new(80, 40, 0.05, [-1.0, -1.0], nav::Cell::Free);
        for x in 0..80 {
            map.set((x, 31), nav::Cell::Occupied); // y = 0.55–0.60
        }
        let map = Arc::new(map);
        // Facing east along it at 0.5 m/s, drifting north at 0.6 m/s, toward the wall: the
        // roll stick at the last of six ticks.
        let last_roll = |config: &DroneConfig| {
            let mut drone = exploring_drone(Arc::default(), config);
            drone.set_map(map.clone());
            drone.set_plan(Some([3.0, 0.0]), vec![[0.0, 0.0], [3.0, 0.0]], None, 0.0);
            for i in 1..=6 {
                let t = 0.1 * f64::from(i);
                drone.slam_fix(t, [0.5 * t, 0.6 * t - 0.26, 0.9], 0.0, None, false);
                drone.tick(t, config);
            }
            assert!(drone.tracking, "pursuing its carrot");
            f64::from(drone.sticks.expect("sticks").roll)
        };
        let config = DroneConfig::default();
        let unbraked = DroneConfig {
            keep_clear: KeepClear {
                brake_gain: 0.0,
                ..config.keep_clear
            },
            ..config.clone()
        };
        // 0.41 m from the wall at 0.39 m/s toward it (the filter's estimate), 0.14 m/s faster
        // than can stop short of it: banked right (south), away from it, by about 0.6 × 0.14
        // more.
        let (braked, not) = (last_roll(&config), last_roll(&unbraked));
        assert!(braked > not + 0.05, "braked {braked}, not {not}");
    }

    #[test]
    fn the_speed_loop_asks_for_the_speed_allowed_toward_the_carrot() {
        let config = DroneConfig::default();
        let (kf, kv) = (config.cruise_ff, config.speed_gain);
        let ahead = [0.4, 0.0];
        // At 0.7 m/s: the drag's feed-forward, no more; slower, a lean forward by 0.6 stick
        // per m/s short; faster, less than the drag takes, down to leaning back; never more
        // than the loop's lean allows (0.35 stick).
        let most = config.speed_lean_max;
        for v in [0.0, 0.3, 0.7, 1.0, 1.5] {
            let [x, y] = speed_loop(carrot_velocity(ahead, 0.7), [v, 0.0], &config);
            let lean = (kf * 0.7 + kv * (0.7 - v)).clamp(-most, most);
            assert!((x - lean).abs() < 1e-9 && y == 0.0, "at {v} m/s: {x}, {y}");
        }
        assert!(speed_loop(carrot_velocity(ahead, 0.7), [1.0, 0.0], &config)[0] < 0.0);
        // Drifting sideways at 0.2 m/s: braked across the path as well.
        let [_, y] = speed_loop(carrot_velocity(ahead, 0.7), [0.7, 0.2], &config);
        assert!((y + kv * 0.2).abs() < 1e-9, "{y}");
        // A carrot 45° off: the lean is toward it, whatever the lead's length.
        let [x, y] = speed_loop(carrot_velocity([0.1, 0.1], 0.5), [0.0; 2], &config);
        assert!((x - y).abs() < 1e-9 && x.hypot(y) > 0.3, "{x}, {y}");
        // No lead: brake to a stop.
        let [x, _] = speed_loop(carrot_velocity([0.0; 2], 0.7), [0.4, 0.0], &config);
        assert!((x + kv * 0.4).abs() < 1e-9, "{x}");
    }

    /// The settings before the speed loop: the position loop, under the 0.7 m/s it had
    /// (`gcs explore --speed-loop false --max-speed 0.7`).
    fn position_loop_config() -> DroneConfig {
        let config = DroneConfig::default();
        DroneConfig {
            speed_gain: 0.0,
            follower: FollowerConfig {
                max_speed_mps: 0.7,
                ..config.follower.clone()
            },
            ..config
        }
    }

    /// A drone cruising east along `path` on y = 0 for 1 s at `speed` m/s, facing east, the
    /// filter fed a fix every tick, to x = `x_end`: its pitch stick at the last tick and the
    /// filter's velocity then.
    fn cruising(
        config: &DroneConfig,
        path: &[[f64; 2]],
        speed: f64,
        x_end: f64,
    ) -> (f64, [f64; 2]) {
        let mut drone = exploring_drone(Arc::default(), config);
        let goal = *path.last().expect("a path");
        drone.set_plan(Some(goal), path.to_vec(), None, 0.0);
        for i in 1..=10 {
            let t = 0.1 * f64::from(i);
            drone.slam_fix(t, [x_end - speed * (1.0 - t), 0.0, 0.9], 0.0, None, false);
            drone.tick(t, config);
        }
        assert!(drone.tracking, "pursuing its carrot");
        let velocity = drone.ekf.valid_velocity().expect("a velocity");
        (f64::from(drone.sticks.expect("sticks").pitch), velocity)
    }

    #[test]
    fn pursuing_a_carrot_the_drone_flies_the_speed_loop() {
        // Down a straight path at 1 m/s, past its 0.8 m/s limit, facing along it: the pitch
        // stick is the speed loop's on the filter's velocity, toward the carrot dead ahead.
        let config = DroneConfig::default();
        let top = config.follower.max_speed_mps;
        let path = [[-4.0, 0.0], [6.0, 0.0]];
        let (pitch, velocity) = cruising(&config, &path, 1.0, 0.0);
        let [lean, _] = speed_loop(carrot_velocity([0.4, 0.0], top), velocity, &config);
        assert!((pitch - lean).abs() < 1e-3, "{pitch} against {lean}");
        assert!(velocity[0] > top, "faster than allowed: {velocity:?}");
        // The position loop, under the same limit, leans further forward: its pull toward the
        // carrot 0.4 m ahead (0.12 stick) came on top of the feed-forward and outweighed the
        // brake to the limit, and the simulated drone cruised at 0.8–0.9 m/s under 0.7.
        let position_loop = DroneConfig {
            speed_gain: 0.0,
            ..config.clone()
        };
        let (pushed, _) = cruising(&position_loop, &path, 1.0, 0.0);
        assert!(pushed > pitch + 0.05, "{pushed} against {pitch}");
    }

    #[test]
    fn the_speed_loop_flies_no_faster_toward_a_near_wall_than_can_stop_short_of_it() {
        // Hovering at the origin, facing north-east, 0.5 m south of a wall's face (y = 0.5),
        // given a path north-east toward it (a new path after a turn, its steer point near the wall): the lean north is
        // for the approach that can still stop short of the wall, 1.5 × (0.5 − 0.25) m/s, not
        // for the 0.5 m/s north in 0.7 m/s at 45°.
        let mut map = Grid::new(80, 80, 0.05, [-2.0, -2.0], nav::Cell::Free);
        for x in 0..80 {
            map.set((x, 50), nav::Cell::Occupied); // y = 0.50–0.55
        }
        let config = DroneConfig::default();
        let north_lean = |map: Option<Grid>| {
            let mut drone = exploring_drone(Arc::default(), &config);
            if let Some(map) = map {
                drone.set_map(Arc::new(map));
            }
            drone.set_plan(Some([5.0, 5.0]), vec![[0.0, 0.0], [5.0, 5.0]], None, 0.0);
            for i in 1..=10 {
                let t = 0.1 * f64::from(i);
                drone.slam_fix(t, [0.0, 0.0, 0.9], std::f64::consts::FRAC_PI_4, None, false);
                drone.tick(t, &config);
            }
            assert!(drone.tracking, "pursuing its carrot");
            let velocity = drone.ekf.valid_velocity().expect("a velocity");
            // The sticks' lean in the map frame, north.
            let sticks = drone.sticks.expect("sticks");
            let (s, c) = drone.pose().expect("a pose")[3].sin_cos();
            let north = s * f64::from(sticks.pitch) - c * f64::from(sticks.roll);
            (north, velocity)
        };
        let (walled, velocity) = north_lean(Some(map));
        let (open, _) = north_lean(None);
        let (kf, kv) = (config.cruise_ff, config.speed_gain);
        let allowed = 1.5 * (0.5 - 0.25);
        let most = kf * allowed + kv * (allowed - velocity[1]);
        assert!(walled < most + 0.01, "{walled} against at most {most}");
        assert!(walled > 0.1, "still toward the carrot: {walled}");
        assert!(open > walled + 0.05, "open {open}, walled {walled}");
    }

    #[test]
    fn a_drone_flying_fast_into_a_sharp_bend_of_its_path_is_braked() {
        // East along y = 0, then a right angle north at x = 0.7 m (a door off a corridor):
        // flying at 1 m/s, 0.3 m before the bend. Allowed 0.3 + 1.0 × 0.3 = 0.6 m/s there;
        // without the bend's limit, 1.5 m/s. The position loop (the default) brakes the
        // 0.4 m/s too fast with the wall brake's gain (0.6 stick per m/s), and its
        // feed-forward is for 0.6 m/s; the speed loop asks for 0.6 m/s toward a carrot 0.1 m
        // round the bend.
        let path = [[-4.0, 0.0], [0.7, 0.0], [0.7, 3.0]];
        for config in [position_loop_config(), DroneConfig::default()] {
            let no_bend_limit = DroneConfig {
                follower: FollowerConfig {
                    bend_rad: std::f64::consts::PI,
                    max_speed_mps: 1.5,
                    ..config.follower.clone()
                },
                ..config.clone()
            };
            let (braked, _) = cruising(&config, &path, 1.0, 0.4);
            let (not, _) = cruising(&no_bend_limit, &path, 1.0, 0.4);
            // (The feed-forward alone makes 0.16 of the difference.)
            assert!(braked < not - 0.25, "braked {braked}, not {not}");
        }
    }

    #[test]
    fn pursuing_a_carrot_the_sticks_lean_toward_it_by_the_cruise_feed_forward() {
        // East along y = 0 at 0.5 m/s, facing 60° left of the path (a bend flown while turning):
        // the sticks at the last of six ticks, with and without the feed-forward.
        let last_sticks = |config: &DroneConfig| {
            let mut drone = exploring_drone(Arc::default(), config);
            drone.set_plan(Some([5.0, 0.0]), vec![[0.0, 0.0], [5.0, 0.0]], None, 0.0);
            for i in 1..=6 {
                let t = 0.1 * f64::from(i);
                drone.slam_fix(
                    t,
                    [0.5 * t, 0.0, 0.9],
                    std::f64::consts::FRAC_PI_3,
                    None,
                    false,
                );
                drone.tick(t, config);
            }
            assert!(drone.tracking, "pursuing its carrot");
            let s = drone.sticks.expect("sticks");
            let yaw = drone.pose().expect("a pose")[3];
            (f64::from(s.pitch), f64::from(s.roll), yaw)
        };
        let config = position_loop_config();
        let off = DroneConfig {
            cruise_ff: 0.0,
            ..config.clone()
        };
        let (with, without) = (last_sticks(&config), last_sticks(&off));
        // 0.175 × 0.7 m/s (the follower's top speed on a straight path) toward the carrot, due
        // east: the cosine of the heading (the filter's, on its way to 60°) of it forward, the
        // sine to the right. (Without, the integral has wound up by less than 0.005 in 0.6 s.)
        let push = config.cruise_ff * config.follower.max_speed_mps;
        let (pitch, roll) = (with.0 - without.0, with.1 - without.1);
        let yaw = with.2;
        assert!(yaw > 0.5, "turned toward 60°: {yaw}");
        assert!((pitch - yaw.cos() * push).abs() < 0.01, "pitch {pitch}");
        assert!((roll - yaw.sin() * push).abs() < 0.01, "roll {roll}");
    }

    #[test]
    fn a_new_path_a_few_centimetres_aside_does_not_kick_the_sticks() {
        for config in [position_loop_config(), DroneConfig::default()] {
            a_new_path_a_few_centimetres_aside_leans_toward_it(&config);
        }
    }

    /// A drone cruising east along y = 0 at 0.5 m/s, given a path 8 cm to its left: the lean
    /// toward it, with `config`, is the loop's for a carrot 8 cm to the side, no more.
    fn a_new_path_a_few_centimetres_aside_leans_toward_it(config: &DroneConfig) {
        let mut drone = exploring_drone(Arc::default(), config);
        drone.set_plan(Some([5.0, 0.0]), vec![[0.0, 0.0], [5.0, 0.0]], None, 0.0);
        let mut t = 0.0;
        let mut roll = 0.0;
        for _ in 0..10 {
            t += 0.1;
            drone.slam_fix(t, [0.5 * t, 0.0, 0.9], 0.0, None, false);
            drone.tick(t, config);
            roll = drone.sticks.expect("sticks").roll;
            assert!(drone.tracking);
        }
        assert!(roll.abs() < 0.02, "{roll}");
        // The planner's next path, 8 cm to the left: differenced, the carrot's step would read
        // 0.8 m/s and roll the drone left by half a stick for a tick.
        drone.set_plan(Some([5.0, 0.08]), vec![[0.4, 0.08], [5.0, 0.08]], None, t);
        t += 0.1;
        drone.slam_fix(t, [0.5 * t, 0.0, 0.9], 0.0, None, false);
        drone.tick(t, config);
        let s = drone.sticks.expect("sticks");
        // Toward the carrot, 0.4 m ahead and 8 cm to the left. The position loop: the
        // proportional part of 8 cm, and the feed-forward's share across the path. The speed
        // loop: the feed-forward and the velocity error of that share of the speed, 0.16 m/s.
        let across = config.follower.max_speed_mps * 0.08 / 0.4;
        let p = config.gains.y.kp * 0.08 + (config.cruise_ff + config.speed_gain) * across;
        assert!(
            s.roll < 0.0 && s.roll > -(p + 0.02) as f32,
            "a lean left of about {p}: {s:?}"
        );
    }

    #[test]
    fn a_drone_turning_toward_its_path_holds_where_the_turn_began() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        // Facing 0.3 rad right of +x, the path north (107° off, more than a bend is flown
        // through): a turn on the spot.
        drone.set_plan(Some([0.0, 3.0]), vec![[0.0, 0.0], [0.0, 3.0]], None, 0.0);
        drone.slam_fix(0.1, [0.0, 0.0, 0.9], -0.3, None, false);
        drone.tick(0.1, &config);
        assert_eq!(drone.hold, [0.0, 0.0]);
        // Coasting north along the path while it turns (now 73° off, still turning until
        // within 60°): held back, not carried along.
        drone.slam_fix(0.2, [0.0, 0.3, 0.9], 0.3, None, false);
        drone.tick(0.2, &config);
        assert_eq!(
            drone.hold,
            [0.0, 0.0],
            "the turn's hold slid with the drone"
        );
        let s = drone.sticks.expect("sticks");
        // South is to the right of a drone facing 0.3 rad: roll right, and back.
        assert!(
            s.roll > 0.0 && s.pitch < 0.0,
            "back to where the turn began: {s:?}"
        );
        // Turned: on along the path, the carrot ahead of the drone.
        drone.slam_fix(
            0.3,
            [0.0, 0.3, 0.9],
            std::f64::consts::FRAC_PI_2,
            None,
            false,
        );
        drone.tick(0.3, &config);
        assert!(drone.hold[1] > 0.5, "{:?}", drone.hold);
    }

    #[test]
    fn a_drone_that_loses_its_pose_turns_back_to_where_the_slam_last_saw_then_sweeps() {
        let vehicle = Arc::new(StubbornVehicle::default());
        let config = DroneConfig::default();
        let mut drone = exploring_drone(vehicle.clone(), &config);
        let set_yaw = |yaw: f64| *vehicle.yaw.lock().unwrap() = Some(yaw as f32);
        // Keyframes facing +x, then a turn to the left (anticlockwise): fixes that make no
        // keyframe up to 0.5 rad, then none.
        let mut t = 0.0;
        for _ in 0..20 {
            t += 0.1;
            set_yaw(0.0);
            drone.slam_fix(t, [0.0, 0.0, 0.9], 0.0, None, true);
            drone.tick(t, &config);
        }
        for i in 1..=10 {
            t += 0.1;
            let yaw = 0.1 * f64::from(i);
            set_yaw(yaw);
            if i <= 5 {
                drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, false);
            }
            drone.tick(t, &config);
        }
        while drone.pose().is_some() {
            t += 0.1;
            drone.tick(t, &config);
            assert!(t < 30.0, "a pose without SLAM fixes must expire");
        }
        let blind = t;
        // 1 rad left of the keyframes' heading: back clockwise (positive) at the full blind rate…
        let s = drone.sticks.expect("sticks");
        assert_eq!((s.roll, s.pitch, s.throttle), (0.0, 0.0, 0.0));
        assert_eq!(s.yaw, config.blind_yaw, "{s:?}");
        // …slower when nearly there, and the other way once past it.
        for (yaw, clockwise) in [(0.1, true), (-0.1, false)] {
            for _ in 0..10 {
                t += 0.1;
                set_yaw(yaw);
                drone.tick(t, &config);
            }
            let s = drone.sticks.expect("sticks");
            assert!(
                s.yaw.abs() < config.blind_yaw && (s.yaw > 0.0) == clockwise,
                "at {yaw} rad: {s:?}"
            );
        }
        // It did not find the map there: the slow sweep.
        while t < blind + config.blind_turn_back_s + 0.5 {
            t += 0.1;
            drone.tick(t, &config);
        }
        assert_eq!(drone.sticks.expect("sticks").yaw, config.blind_yaw);
        assert_eq!(drone.phase, Phase::Exploring);
    }

    #[test]
    fn a_lost_drone_already_facing_its_last_keyframes_way_sweeps_once_that_view_finds_nothing() {
        // Lost while facing the way its last keyframe faced (a bare wall, say): once it has
        // faced it for `blind_face_s` without being found, the slow sweep begins, long before
        // the turn back's time is up; flying on visual odometry or blind alike.
        let config = DroneConfig::default();
        assert!(config.blind_face_s + 1.0 < config.blind_turn_back_s);
        let sweep_after = |odometry: bool| {
            let vehicle = Arc::new(StubbornVehicle::default());
            *vehicle.yaw.lock().unwrap() = Some(0.05);
            let mut drone = exploring_drone(vehicle, &config);
            drone.set_plan(Some([5.0, 0.0]), vec![[0.0, 0.0], [5.0, 0.0]], None, 0.0);
            drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.0, None, true);
            drone.tick(0.1, &config);
            // Blind: once the filter's pose expires without fixes.
            let mut t = 0.1;
            while !odometry && drone.pose().is_some() {
                t += 0.1;
                drone.tick(t, &config);
            }
            let lost = t;
            while t < lost + config.blind_turn_back_s {
                t += 0.1;
                if odometry {
                    drone.slam_lost(t, &config);
                    drone.slam_odometry(t - 0.1, t, &Isometry3::identity(), None);
                }
                drone.tick(t, &config);
                assert_eq!(drone.pose().is_some(), odometry, "at {t:.1} s");
                if drone.sticks.expect("sticks").yaw == config.blind_yaw {
                    return t - lost;
                }
            }
            panic!("no sweep within the turn back's time");
        };
        for odometry in [true, false] {
            let after = sweep_after(odometry);
            assert!(
                (config.blind_face_s..config.blind_face_s + 1.0).contains(&after),
                "odometry {odometry}: the sweep began {after:.1} s after the loss"
            );
        }
    }

    #[test]
    fn the_recent_turn_reads_the_last_moments_across_the_wrap_and_forgets_a_gap() {
        let mut turn = RecentTurn::default();
        // Clockwise at 0.5 rad/s through ±π, then still: only the last 1.5 s count.
        let mut t = 0.0;
        while t < 3.0 {
            t += 0.1;
            turn.observe(t, wrap_angle(-3.0 - 0.5 * t));
        }
        assert!(
            (turn.turned() + 0.5 * TURN_WINDOW_S).abs() < 0.06,
            "{}",
            turn.turned()
        );
        for _ in 0..20 {
            t += 0.1;
            turn.observe(t, wrap_angle(-4.5));
        }
        assert!(turn.turned().abs() < 1e-9, "{}", turn.turned());
        // Read again after a loss, half a turn on: a reading before the gap is no turn.
        turn.observe(t + 20.0, wrap_angle(-4.5 + 3.0));
        assert_eq!(turn.turned(), 0.0);
        turn.observe(t + 20.1, f64::NAN);
        assert_eq!(turn.turned(), 0.0);
    }

    #[test]
    fn a_drone_lost_turning_clockwise_sweeps_back_counter_clockwise() {
        // The views it turned from are the ones the map knows; still or turning the other
        // way, it sweeps clockwise as always.
        let config = DroneConfig::default();
        let sweep_yaw = |rate: f64| {
            let vehicle = Arc::new(StubbornVehicle::default());
            let mut drone = exploring_drone(vehicle.clone(), &config);
            drone.set_plan(Some([5.0, 0.0]), vec![[0.0, 0.0], [5.0, 0.0]], None, 0.0);
            let mut t: f64 = 0.0;
            while t < 2.0 {
                t += 0.1;
                *vehicle.yaw.lock().unwrap() = Some(wrap_angle(rate * t) as f32);
                drone.slam_fix(t, [0.0, 0.0, 0.9], wrap_angle(rate * t), None, true);
                drone.tick(t, &config);
            }
            // Lost, heading held: it faces its last keyframe's way, then sweeps.
            let lost = t;
            while t < lost + config.blind_face_s + 1.0 {
                t += 0.1;
                drone.slam_lost(t, &config);
                drone.slam_odometry(t - 0.1, t, &Isometry3::identity(), None);
                drone.tick(t, &config);
            }
            drone.sticks.expect("sticks").yaw
        };
        assert_eq!(sweep_yaw(-0.4), -config.blind_yaw, "lost turning clockwise");
        assert_eq!(
            sweep_yaw(0.4),
            config.blind_yaw,
            "lost turning counter-clockwise"
        );
        assert_eq!(sweep_yaw(0.0), config.blind_yaw, "lost flying straight");
        // A slight turn is flying straight.
        let slight = 0.5 * config.blind_sweep_back_rad / TURN_WINDOW_S;
        assert_eq!(
            sweep_yaw(-slight),
            config.blind_yaw,
            "lost turning slightly"
        );
    }

    #[test]
    fn a_lost_drone_flies_on_visual_odometry_turns_back_sweeps_then_lands() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        drone.set_plan(Some([5.0, 0.0]), vec![[0.0, 0.0], [5.0, 0.0]], None, 0.0);
        drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.5, None, true);
        drone.slam_fix(0.2, [0.05, 0.0, 0.9], 0.0, None, false);
        drone.tick(0.2, &config);
        // Lost at 0.3 s; its camera's consecutive frames say it is not moving.
        let mut t: f64 = 0.3;
        drone.slam_lost(t, &config);
        let mut turned_back = false;
        while t < 0.3 + config.blind_land_s - 0.5 {
            t += 0.1;
            drone.slam_lost(t, &config);
            drone.slam_odometry(t - 0.1, t, &Isometry3::identity(), None);
            drone.tick(t, &config);
            let pose = drone
                .pose()
                .expect("flying on odometry, the pose stays valid");
            assert!(
                pose[0].hypot(pose[1]) < 0.2,
                "held near the keyframe: {pose:?}"
            );
            assert_eq!(drone.hold, [0.0, 0.0], "back at the last keyframe");
            let s = drone.sticks.expect("sticks");
            if t < 0.3 + config.blind_turn_back_s - 0.1 {
                turned_back |= (drone.yaw_goal - 0.5).abs() < 1e-9;
            } else if t > 0.3 + config.blind_turn_back_s + 0.1 {
                assert_eq!(s.yaw, config.blind_yaw, "the slow sweep at {t:.1} s");
            }
            assert_eq!(drone.phase, Phase::Exploring);
        }
        assert!(turned_back, "first faced the last keyframe's way");
        while t < 0.3 + config.blind_land_s + 0.5 {
            t += 0.1;
            drone.slam_lost(t, &config);
            drone.slam_odometry(t - 0.1, t, &Isometry3::identity(), None);
            drone.tick(t, &config);
        }
        assert_eq!(drone.phase, Phase::Landing, "lost for too long");
        assert_eq!(
            drone.left_mission.as_deref(),
            Some("lost by the SLAM for 30 s")
        );
        // Without odometry the same loss leaves no pose within seconds.
        let mut drone = exploring_drone(Arc::default(), &config);
        drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.5, None, true);
        drone.slam_lost(0.2, &config);
        tick_until_the_pose_expires(&mut drone, 0.2, &config);
    }

    #[test]
    fn a_drone_lost_hovering_holds_its_spot_with_a_gentle_lean_one_lost_flying_brakes_hard() {
        // Tracked facing +x at `speed` m/s, then lost; visual odometry on a few features says
        // it flies forward at 0.4 m/s (in SITL the hovering drone had not moved). The hold
        // brakes that: the strongest lean over the second after the loss.
        let strongest = |config: &DroneConfig, speed: f64| {
            let mut drone = exploring_drone(Arc::default(), config);
            let mut t: f64 = 0.0;
            while t < 0.95 {
                t += 0.1;
                drone.slam_fix(t, [speed * t, 0.0, 0.9], 0.0, None, true);
                // The filter's velocity as frame-to-frame registration measures it (from the
                // fixes alone it would lag: these sticks fly nowhere).
                drone.ekf.update_odometry(t - 0.1, t, [speed * 0.1, 0.0]);
                drone.tick(t, config);
            }
            let lost = t + 0.1;
            let mut strongest = 0f32;
            while t < lost + 1.0 {
                t += 0.1;
                drone.slam_lost(t, config);
                drone.slam_odometry(t - 0.1, t, &Isometry3::translation(0.04, 0.0, 0.0), None);
                drone.tick(t, config);
                assert!(drone.pose().is_some(), "flying on odometry");
                let s = drone.sticks.expect("sticks");
                strongest = strongest.max(s.pitch.abs()).max(s.roll.abs());
            }
            strongest
        };
        let config = DroneConfig::default();
        let gentle = strongest(&config, 0.0);
        assert!(gentle > 0.05, "it still brakes: {gentle}");
        assert!(gentle <= config.lost_stick_max as f32 + 1e-6, "{gentle}");
        // Unbounded, the same filter leans it hard…
        let unbounded = DroneConfig {
            lost_stick_max: 1.0,
            ..config.clone()
        };
        assert!(strongest(&unbounded, 0.0) > 0.3);
        // …as it must a drone lost flying at 0.6 m/s, to stop it.
        let braking = strongest(&config, 0.6);
        assert!(braking > 0.3, "{braking}");
    }

    #[test]
    fn a_weak_registration_neither_moves_the_drone_nor_loses_it() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        let fix = |stamp: f64, x: f64, weak: bool| SlamFix {
            drone: 0,
            stamp,
            map_from_body: Some(Isometry3::translation(x, 0.0, 0.9)),
            keyframe: false,
            inliers: Some(if weak { 15 } else { 120 }),
            weak,
            odometry: None,
            depth_odometry: None,
            half_fov_rad: 0.5,
            ranges: vec![],
            heading: None,
        };
        let mut t = 0.1;
        drone.take_fix(t, &fix(t, 0.0, false), &config);
        drone.tick(t, &config);
        // Weak registrations 0.5 m away, frame after frame: the filter stays where it was,
        // and the drone is not taken for lost (it holds no spot to go back to).
        for _ in 0..5 {
            t += 0.1;
            drone.take_fix(t, &fix(t, 0.5, true), &config);
            drone.tick(t, &config);
            let pose = drone.pose().expect("carried on between fixes");
            assert!(pose[0].abs() < 0.05, "moved by a weak fix: {pose:?}");
            assert_eq!((drone.lost_at, drone.lost_since), (None, None));
            assert_eq!(drone.inliers, Some(15));
        }
        // The same pose, registered on enough, is flown on.
        t += 0.1;
        drone.take_fix(t, &fix(t, 0.5, false), &config);
        drone.tick(t, &config);
        let pose = drone.pose().expect("a fix");
        assert!(pose[0] > 0.2, "a strong fix moves the filter: {pose:?}");
        // No pose at all is a loss.
        t += 0.1;
        let lost = SlamFix {
            map_from_body: None,
            inliers: None,
            ..fix(t, 0.0, false)
        };
        drone.take_fix(t, &lost, &config);
        assert_eq!(drone.lost_since, Some(t));
    }

    /// A camera frame of drone 0 at `stamp` the SLAM could not place, whose body moved `step`
    /// metres forward since the frame 0.1 s before by visual odometry on `inliers` (`None`:
    /// not measured).
    fn frame_with_odometry(stamp: f64, step: Option<f64>, inliers: usize) -> SlamFix {
        SlamFix {
            drone: 0,
            stamp,
            map_from_body: None,
            keyframe: false,
            inliers: None,
            weak: false,
            odometry: step.map(|step| Odometry {
                since: stamp - 0.1,
                previous_from_body: Isometry3::translation(step, 0.0, 0.0),
                inliers,
            }),
            depth_odometry: None,
            half_fov_rad: 0.5,
            ranges: vec![],
            heading: None,
        }
    }

    #[test]
    fn a_lost_drone_weighs_its_visual_odometry_by_the_inliers() {
        // Tracked hovering, then lost and still by visual odometry on many inliers; then one
        // frame says it moved 6 cm in 0.1 s. On 15 inliers that step moves the filter's
        // velocity less than half as far as on 120.
        let config = DroneConfig::default();
        let velocity_after = |inliers: usize| {
            let mut drone = exploring_drone(Arc::default(), &config);
            let frame = |stamp: f64, step: f64, inliers: usize| {
                frame_with_odometry(stamp, Some(step), inliers)
            };
            let mut t = 0.0;
            while t < 2.0 {
                t += 0.1;
                let tracked = SlamFix {
                    map_from_body: Some(Isometry3::translation(0.0, 0.0, 0.9)),
                    inliers: Some(120),
                    odometry: None,
                    depth_odometry: None,
                    ..frame(t, 0.0, 0)
                };
                drone.take_fix(t, &tracked, &config);
                drone.tick(t, &config);
            }
            for _ in 0..5 {
                t += 0.1;
                drone.take_fix(t, &frame(t, 0.0, 120), &config);
                drone.tick(t, &config);
            }
            t += 0.1;
            drone.take_fix(t, &frame(t, 0.06, inliers), &config);
            drone.ekf.estimate().velocity[0]
        };
        let (sound, weak) = (velocity_after(120), velocity_after(15));
        assert!(sound > 0.3, "{sound}");
        assert!(weak < 0.5 * sound, "{weak} against {sound}");
    }

    #[test]
    fn a_lost_drone_facing_a_blank_wall_brakes_the_drift_its_depth_measures() {
        // Tracked hovering facing +x, then lost in front of a wall with no texture: no visual
        // odometry, but the wall's depth says the body comes 1.5 cm nearer every frame
        // (0.15 m/s, the air carrying it in). The filter learns the drift and the drone leans
        // back against it; told nothing, it hovers level and drifts on.
        let config = DroneConfig::default();
        let after_lost = |depth: bool| {
            let mut drone = exploring_drone(Arc::default(), &config);
            let mut t = 0.0;
            while t < 2.0 {
                t += 0.1;
                let tracked = SlamFix {
                    map_from_body: Some(Isometry3::translation(0.0, 0.0, 0.9)),
                    inliers: Some(120),
                    ..frame_with_odometry(t, None, 0)
                };
                drone.take_fix(t, &tracked, &config);
                drone.tick(t, &config);
            }
            for _ in 0..15 {
                t += 0.1;
                let lost = SlamFix {
                    depth_odometry: depth.then(|| DepthOdometry {
                        since: t - 0.1,
                        along: vec![slam::ekf::Along {
                            direction: [1.0, 0.0],
                            displacement: 0.015,
                            sigma: 0.003,
                        }],
                        turn_rad: 0.0,
                        matches: 800,
                    }),
                    ..frame_with_odometry(t, None, 0)
                };
                drone.take_fix(t, &lost, &config);
                drone.tick(t, &config);
            }
            assert!(
                drone.pose().is_none() || depth,
                "lost, and blind without the depth"
            );
            let velocity = drone.ekf.valid_velocity();
            (f64::from(drone.sticks.expect("sticks").pitch), velocity)
        };
        let (pitch, velocity) = after_lost(true);
        let velocity = velocity.expect("the drift toward the wall is measured");
        assert!(velocity[0] > 0.08, "{velocity:?}");
        assert!(velocity[1].abs() < 0.02, "{velocity:?}");
        assert!(pitch < -0.03, "leans back from the wall: pitch {pitch}");
        let (pitch, _) = after_lost(false);
        assert!(pitch.abs() < 0.01, "nothing to brake on: pitch {pitch}");
    }

    #[test]
    fn a_weakly_placed_drone_flies_on_its_visual_odometry() {
        // Tracked hovering for 2 s, then only weak registrations (0.5 m away): with its frames'
        // visual odometry on enough inliers the filter measures the drone's motion and keeps a
        // pose to fly on for longer than on its model alone, and a moving step moves its
        // velocity; on too few inliers the odometry is not flown on.
        let config = DroneConfig::default();
        let enough = config.weak_odometry_min_inliers;
        let weak_for = |step: Option<f64>, inliers: usize| {
            let mut drone = exploring_drone(Arc::default(), &config);
            let frame = |stamp: f64, weak: bool| SlamFix {
                map_from_body: Some(Isometry3::translation(
                    if weak { 0.5 } else { 0.0 },
                    0.0,
                    0.9,
                )),
                inliers: Some(if weak { 20 } else { 120 }),
                weak,
                ..frame_with_odometry(stamp, step.filter(|_| weak), inliers)
            };
            let mut t = 0.0;
            while t < 2.0 {
                t += 0.1;
                drone.take_fix(t, &frame(t, false), &config);
                drone.tick(t, &config);
            }
            let weak_since = t;
            let mut velocity = 0.0;
            while drone.pose().is_some() && t < weak_since + 20.0 {
                t += 0.1;
                drone.take_fix(t, &frame(t, true), &config);
                drone.tick(t, &config);
                if t < weak_since + 1.05 {
                    velocity = drone.ekf.estimate().velocity[0];
                }
                assert_eq!(drone.lost_since, None, "a weak frame is no loss");
            }
            (t - weak_since, velocity)
        };
        let (blind_s, _) = weak_for(None, enough);
        let (still_s, still_mps) = weak_for(Some(0.0), enough);
        let (_, moving_mps) = weak_for(Some(0.03), enough);
        let (few_s, few_mps) = weak_for(Some(0.03), enough - 1);
        eprintln!(
            "pose kept {blind_s:.1} s blind, {still_s:.1} s on odometry, {few_s:.1} s on too \
             few inliers; {still_mps:.3}, {moving_mps:.3} and {few_mps:.3} m/s"
        );
        assert!(
            still_s > 2.0 * blind_s,
            "a pose for {still_s} s on odometry, {blind_s} s without"
        );
        assert!(still_mps.abs() < 0.05, "{still_mps}");
        assert!(
            moving_mps > 0.15,
            "measured 0.3 m/s, the filter has {moving_mps}"
        );
        assert!(
            (few_s - blind_s).abs() < 0.15,
            "{few_s} s on too few inliers"
        );
        assert!(few_mps.abs() < 0.05, "{few_mps}");
    }

    /// Ticks a drone the SLAM has lost at `t`, with nothing to measure its motion, until its
    /// pose expires (it must, within 5 s); returns the time then.
    fn tick_until_the_pose_expires(drone: &mut Drone, mut t: f64, config: &DroneConfig) -> f64 {
        while drone.pose().is_some() {
            t += 0.1;
            drone.tick(t, config);
            assert!(t < 5.0, "a pose without fixes or odometry must expire");
        }
        t
    }

    #[test]
    fn a_drone_without_a_pose_brakes_the_drift_its_camera_measures() {
        let config = DroneConfig::default();
        // Lost with nothing to measure its drift: the pose expires, the drone hovers level for
        // a few seconds. Then its camera's consecutive frames (0.3 s late) measure the drift,
        // at `forward` and `left` m/s (it faces +x): the sticks at the first tick its velocity
        // is known again while its position is still not.
        let braking = |forward: f64, left: f64| {
            let mut drone = exploring_drone(Arc::default(), &config);
            drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.0, None, true);
            drone.slam_lost(0.2, &config);
            let mut t = tick_until_the_pose_expires(&mut drone, 0.2, &config);
            // Blind for a few seconds: the position far from known.
            let blind = t;
            while t < blind + 3.0 {
                t += 0.1;
                drone.tick(t, &config);
                let s = drone.sticks.expect("sticks");
                assert_eq!((s.roll, s.pitch), (0.0, 0.0), "level");
            }
            for _ in 0..20 {
                t += 0.1;
                drone.slam_lost(t, &config);
                let moved = Isometry3::translation(forward * 0.1, left * 0.1, 0.0);
                drone.slam_odometry(t - 0.4, t - 0.3, &moved, None);
                drone.tick(t, &config);
                if drone.pose().is_none() && drone.ekf.valid_velocity().is_some() {
                    return drone.sticks.expect("sticks");
                }
            }
            panic!("the velocity was never known without the position");
        };
        // Drifting forward and left: nose up and banked right, within the limit.
        let s = braking(0.2, 0.2);
        let max = config.blind_brake_max as f32;
        assert!(s.pitch < -0.02 && s.roll > 0.02, "{s:?}");
        assert!(s.pitch >= -max && s.roll <= max, "{s:?}");
        // Backward and right: the other way.
        let s = braking(-0.2, -0.2);
        assert!(s.pitch > 0.02 && s.roll < -0.02, "{s:?}");
        // Still: level.
        let s = braking(0.0, 0.0);
        assert_eq!((s.roll, s.pitch), (0.0, 0.0), "within the band");
    }

    #[test]
    fn a_blind_drone_given_a_hold_gain_keeps_its_spot_on_the_drift_its_camera_measures() {
        // The simulator's vehicle hovering in a steady 0.1 m/s draught, flown by the drone's
        // sticks. The SLAM loses it; after 3 s blind its camera's consecutive frames measure
        // the true motion (0.3 s late). How far the vehicle drifts from where they began to,
        // over the next 10 s.
        let drift = |config: &DroneConfig| {
            let vehicle_link = Arc::new(StubbornVehicle::default());
            *vehicle_link.yaw.lock().expect("yaw") = Some(0.0);
            let mut drone = exploring_drone(vehicle_link.clone(), config);
            let mut text = String::from("resolution 0.5\nceiling 3.0\n---\n");
            for row in 0..10 {
                let wall = row == 0 || row == 9;
                text += &format!("#{}#\n", if wall { "#" } else { "." }.repeat(18));
            }
            let world = sitl::world::World::parse_text("hall", &text).expect("a hall");
            let mut vehicle = sitl::vehicle::Vehicle::new(Default::default(), 5.0, 2.5, 0.0);
            vehicle.set_armed(true);
            vehicle.set_sticks(Sticks {
                throttle: 1.0,
                ..Sticks::CENTRED
            });
            while vehicle.state().position[2] < 0.9 {
                vehicle.step(&world, 0.01);
            }
            vehicle.set_sticks(Sticks::CENTRED);
            vehicle.set_wind([0.1, 0.0]);
            let here = |v: &sitl::vehicle::Vehicle| {
                let s = v.state();
                Isometry3::new(
                    nalgebra::Vector3::new(s.position[0] - 5.0, s.position[1] - 2.5, s.position[2]),
                    nalgebra::Vector3::z() * s.yaw,
                )
            };
            let mut poses = vec![here(&vehicle)];
            drone.slam_fix(0.0, [0.0, 0.0, 0.9], 0.0, None, true);
            drone.slam_lost(0.1, config);
            let (mut t, mut blind_at, mut worst) = (0.0, None::<(f64, Isometry3<f64>)>, 0.0_f64);
            let mut measured_at = None::<Isometry3<f64>>;
            while t < 30.0 {
                t += 0.1;
                drone.slam_lost(t, config);
                // Its frames measure nothing until it has been blind for 3 s (sooner, the filter
                // would carry its pose on them).
                if blind_at.is_some_and(|(since, _)| t > since + 3.0) {
                    let [a, b] = [poses[poses.len() - 4], poses[poses.len() - 3]];
                    drone.slam_odometry(t - 0.4, t - 0.3, &(a.inverse() * b), None);
                }
                drone.tick(t, config);
                vehicle.set_sticks(drone.sticks.expect("sticks"));
                for _ in 0..10 {
                    vehicle.step(&world, 0.01);
                }
                let pose = here(&vehicle);
                *vehicle_link.yaw.lock().expect("yaw") = Some(vehicle.state().yaw as f32);
                poses.push(pose);
                if drone.pose().is_none() {
                    let (since, _) = *blind_at.get_or_insert((t, pose));
                    if t <= since + 3.0 {
                        continue;
                    }
                    let at = *measured_at.get_or_insert(pose);
                    let moved = pose.translation.vector - at.translation.vector;
                    worst = worst.max(moved.xy().norm());
                    if t > since + 13.0 {
                        break;
                    }
                }
            }
            assert!(blind_at.is_some(), "the pose never expired");
            worst
        };
        let braked = drift(&DroneConfig::default());
        let held = drift(&DroneConfig {
            blind_hold_gain: 1.0,
            ..DroneConfig::default()
        });
        // Braked only, it balances the draught at a speed the brake's gain sets, and drifts on
        // (0.05 m/s here); held, it stops within centimetres.
        assert!(held < 0.1, "held within {held:.2} m");
        assert!(
            braked > 0.3,
            "braked only: {braked:.2} m, held: {held:.2} m"
        );
    }

    #[test]
    fn a_drone_without_a_pose_leans_off_a_wall_its_camera_saw_near() {
        let config = DroneConfig::default();
        // Lost facing +x (IMU heading 0), its frames showing a flat wall `ahead_m` away, seen
        // while it headed `seen_heading`: the sticks once the pose has expired.
        let blind_sticks = |ahead_m: f64, seen_heading: f64| {
            let vehicle = Arc::new(StubbornVehicle::default());
            *vehicle.yaw.lock().expect("yaw") = Some(0.0);
            let mut drone = exploring_drone(vehicle, &config);
            drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.0, None, true);
            let wall: Vec<_> = (-5..=5)
                .map(|i| {
                    let bearing = f64::from(i) * 0.1;
                    nav::proximity::Reading {
                        bearing_rad: bearing,
                        sight: nav::proximity::Sight::Wall(ahead_m / bearing.cos()),
                    }
                })
                .collect();
            let mut t = 0.2;
            while drone.pose().is_some() || t < 1.0 {
                let lost = SlamFix {
                    drone: 0,
                    stamp: t,
                    map_from_body: None,
                    keyframe: false,
                    inliers: None,
                    weak: false,
                    odometry: None,
                    depth_odometry: None,
                    half_fov_rad: 0.5,
                    ranges: wall.clone(),
                    heading: Some(seen_heading),
                };
                drone.take_fix(t, &lost, &config);
                drone.tick(t, &config);
                t += 0.1;
                assert!(t < 5.0, "a pose without fixes or odometry must expire");
            }
            drone.tick(t, &config);
            drone.sticks.expect("sticks")
        };
        // Far: level, as without a camera.
        let s = blind_sticks(2.0, 0.0);
        assert_eq!((s.roll, s.pitch), (0.0, 0.0), "{s:?}");
        // Near ahead: nose up (leaning back), not sideways, within the limit.
        let s = blind_sticks(0.4, 0.0);
        let max = config.proximity.max as f32;
        assert!(s.pitch < -0.02 && s.pitch >= -max, "{s:?}");
        assert!(s.roll.abs() < 0.2 * s.pitch.abs(), "{s:?}");
        // Seen near while it faced left (+y), before it turned back to +x: banked right.
        let s = blind_sticks(0.4, std::f64::consts::FRAC_PI_2);
        assert!(s.roll > 0.02 && s.pitch.abs() < 0.2 * s.roll, "{s:?}");
    }

    #[test]
    fn a_drone_holding_a_spot_keeps_room_for_its_camera_to_range_every_wall() {
        // Holding at the origin facing +x, a wall of the map 0.45 m ahead (x = 0.45–0.5 m):
        // turned to it, the camera (0.1 m ahead of the centre) would be nearer than it ranges.
        let setpoint = |hold_clearance_m: f64| {
            let config = DroneConfig {
                hold_clearance_m,
                ..DroneConfig::default()
            };
            let mut drone = exploring_drone(Arc::default(), &config);
            let mut map = Grid::new(40, 40, 0.05, [-1.0, -1.0], nav::Cell::Free);
            for y in 0..40 {
                map.set((29, y), nav::Cell::Occupied);
            }
            drone.set_map(Arc::new(map));
            drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.0, None, true);
            drone.tick(0.1, &config);
            assert!(!drone.tracking, "holding a spot");
            assert_eq!(drone.hold, [0.0, 0.0]);
            drone.setpoint
        };
        // Out to 0.55 m from the wall: 0.1 m back.
        let [x, y] = setpoint(DroneConfig::default().hold_clearance_m);
        assert!((x + 0.1).abs() < 0.02 && y.abs() < 1e-9, "{x} {y}");
        // With only the path's clearance (0.35 m), 0.45 m is room enough: held where it is.
        assert_eq!(setpoint(0.0), [0.0, 0.0]);
    }

    #[test]
    fn a_drone_that_goes_blind_with_a_wall_of_the_map_behind_it_leans_off_it() {
        let config = DroneConfig::default();
        // Facing +x at the origin, a wall of the map 0.35 m behind it (x = −0.40 to −0.35);
        // the SLAM loses it and its pose expires (no camera frames: nothing seen ahead).
        let blind_sticks = |map: Option<Grid>| {
            let vehicle = Arc::new(StubbornVehicle::default());
            *vehicle.yaw.lock().expect("yaw") = Some(0.0);
            let mut drone = exploring_drone(vehicle, &config);
            if let Some(map) = map {
                drone.set_map(Arc::new(map));
            }
            drone.slam_fix(0.1, [0.0, 0.0, 0.9], 0.0, None, true);
            drone.tick(0.1, &config);
            drone.slam_lost(0.2, &config);
            let t = tick_until_the_pose_expires(&mut drone, 0.2, &config);
            drone.tick(t + 0.1, &config);
            drone.sticks.expect("sticks")
        };
        let s = blind_sticks(None);
        assert_eq!((s.roll, s.pitch), (0.0, 0.0), "no map: level, {s:?}");
        let mut map = Grid::new(40, 40, 0.05, [-1.0, -1.0], nav::Cell::Free);
        for y in 0..40 {
            map.set((12, y), nav::Cell::Occupied);
        }
        let s = blind_sticks(Some(map));
        assert!(
            s.pitch > 0.02 && s.roll.abs() < 0.2 * s.pitch,
            "forward: {s:?}"
        );
    }

    #[test]
    fn a_drone_the_slam_loses_goes_back_to_its_last_keyframe_facing_its_way() {
        let config = DroneConfig::default();
        // Following a path east: a keyframe at `keyframe_x` facing north-east, then a fix at
        // x = 0.1 facing east; there the SLAM loses it.
        let lost_after_keyframe_at = |keyframe_x: f64| {
            let mut drone = exploring_drone(Arc::default(), &config);
            drone.set_plan(Some([5.0, 0.0]), vec![[0.0, 0.0], [5.0, 0.0]], None, 0.0);
            drone.slam_fix(0.1, [keyframe_x, 0.0, 0.9], 0.5, None, true);
            drone.slam_fix(0.2, [0.1, 0.0, 0.9], 0.0, None, false);
            drone.tick(0.2, &config);
            assert!(drone.sticks.expect("sticks").pitch > 0.0, "on its way");
            let where_lost = drone.pose().expect("pose");
            drone.slam_lost(0.2, &config);
            // The filter still carries the pose: hold, facing the last keyframe's way, the
            // goal kept.
            let mut t = 0.2;
            while t < 1.0 {
                t += 0.1;
                drone.tick(t, &config);
            }
            assert!(drone.pose().is_some(), "still a pose to fly on");
            assert_eq!(drone.yaw_goal, 0.5);
            assert_eq!(drone.goal, Some([5.0, 0.0]));
            (drone, where_lost, t)
        };
        // The keyframe 0.1 m back: back there.
        let (mut drone, where_lost, t) = lost_after_keyframe_at(0.0);
        assert_eq!(drone.hold, [0.0, 0.0]);
        // Found again: on along the path.
        drone.slam_fix(t, [0.1, 0.0, 0.9], 0.0, None, false);
        drone.tick(t + 0.1, &config);
        assert!(drone.hold[0] > where_lost[0] + 0.1, "{:?}", drone.hold);
        // The keyframe further back than `lost_back_m`: where the SLAM lost it.
        let (drone, where_lost, _) = lost_after_keyframe_at(0.1 - config.lost_back_m - 0.2);
        assert!(where_lost[0] > 0.0, "lost at the last fix: {where_lost:?}");
        assert_eq!(drone.hold, [where_lost[0], where_lost[1]]);
    }

    /// Looks around from (0, 0), facing +x, in a known 4 × 4 m room whose `unknown` cells
    /// (x range, y range, metres) are not mapped, the heading following its goal, its camera's
    /// frames (if any) telling their half field of view; returns the event that ended it,
    /// when, and the heading goal then.
    /// A walled room 4 × 4 m round (0, 0), free but for the rectangle `unknown` (x and y ranges).
    fn walled_room(unknown: Option<([f64; 2], [f64; 2])>) -> Grid {
        let mut map = Grid::new(80, 80, 0.05, [-2.0, -2.0], nav::Cell::Free);
        for i in 0..80 {
            for c in [(i, 0), (i, 79), (0, i), (79, i)] {
                map.set(c, nav::Cell::Occupied);
            }
        }
        for y in 0..80 {
            for x in 0..80 {
                let p = map.center_of((x, y));
                if unknown.is_some_and(|(xs, ys)| {
                    (xs[0]..xs[1]).contains(&p[0]) && (ys[0]..ys[1]).contains(&p[1])
                }) {
                    map.set((x, y), nav::Cell::Unknown);
                }
            }
        }
        map
    }

    #[test]
    fn a_drone_waiting_behind_another_holds_where_its_path_ends_and_looks_around_only_at_a_goal() {
        let config = DroneConfig::default();
        // Unknown to the south: a look around there would turn toward it.
        let south = Some(([-0.3, 0.3], [-1.95, -1.0]));
        let arrive = |goal: Option<[f64; 2]>| {
            let mut drone = exploring_drone(Arc::default(), &config);
            drone.set_map(Arc::new(walled_room(south)));
            drone.set_plan(goal, vec![[0.0, 0.0]], None, 0.0);
            let yaw0 = drone.yaw_goal;
            for k in 1..=20 {
                let t = f64::from(k) * 0.1;
                drone.slam_fix(t, [0.0, 0.0, 0.9], drone.yaw_goal, None, false);
                assert_eq!(drone.tick(t, &config), None);
            }
            let turned = wrap_angle(drone.yaw_goal - yaw0).abs();
            (drone, turned)
        };
        // Sent to wait (no goal): it holds at its path's end, facing as it was.
        let (mut waiting, turned) = arrive(None);
        assert!(
            waiting.scan.is_none() && turned < 1e-9,
            "turned {turned} rad"
        );
        assert!(
            waiting.hold[0].hypot(waiting.hold[1]) < 0.05,
            "{:?}",
            waiting.hold
        );
        // …and the next plan's goal is its own at once.
        waiting.set_plan(Some([1.0, 0.0]), vec![[0.0, 0.0], [1.0, 0.0]], None, 2.1);
        assert_eq!(waiting.goal, Some([1.0, 0.0]));
        // At a goal it looks around, turning toward the unknown.
        let (at_goal, turned) = arrive(Some([0.0, 0.0]));
        assert!(
            at_goal.scan.is_some() && turned > 0.3,
            "turned {turned} rad"
        );
    }

    fn look_around_in(
        unknown: Option<([f64; 2], [f64; 2])>,
        camera_half_fov: Option<f64>,
        look_turn: Option<f64>,
    ) -> (DroneEvent, f64, f64) {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        let frame = |drone: &mut Drone, t| {
            if let Some(h) = camera_half_fov {
                drone.camera_frame(t, h);
            }
        };
        frame(&mut drone, 0.0);
        drone.set_map(Arc::new(walled_room(unknown)));
        // Arrived at its goal: the look around begins with the first tick.
        drone.set_plan(Some([1.0, 0.0]), vec![[0.0, 0.0]], look_turn, 0.0);
        let mut t = 0.0;
        loop {
            t += 0.1;
            frame(&mut drone, t);
            drone.slam_fix(t, [0.0, 0.0, 0.9], drone.yaw_goal, None, false);
            if let Some(event) = drone.tick(t, &config) {
                return (event, t, drone.yaw_goal);
            }
            assert!(t < config.scan_s + 1.0, "the look around went on");
        }
    }

    #[test]
    fn a_drone_awaits_a_plan_from_the_end_of_its_look_around_until_one_comes() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        drone.set_map(Arc::new(walled_room(None)));
        drone.set_plan(Some([1.0, 0.0]), vec![[1.0, 0.0]], None, 0.0);
        let mut t = 0.0;
        // The SLAM's fixes come 0.25 s after their frames were taken.
        const LAG_S: f64 = 0.25;
        let fly = |drone: &mut Drone, t: f64| {
            let fix = SlamFix {
                drone: 0,
                stamp: t - LAG_S,
                map_from_body: Some(Isometry3::new(
                    nalgebra::Vector3::new(0.0, 0.0, 0.9),
                    nalgebra::Vector3::z() * drone.yaw_goal,
                )),
                keyframe: false,
                inliers: Some(120),
                weak: false,
                odometry: None,
                depth_odometry: None,
                half_fov_rad: 0.5,
                ranges: vec![],
                heading: None,
            };
            drone.take_fix(t, &fix, &config);
            drone.tick(t, &config)
        };
        // Flying to its goal, then looking around there: it has a plan.
        while t < 1.0 {
            t += 0.1;
            assert_eq!(fly(&mut drone, t), None);
            assert!(!drone.awaits_plan(), "on its way at {t:.1} s");
        }
        drone.set_plan(Some([1.0, 0.0]), vec![[0.0, 0.0]], None, t);
        loop {
            t += 0.1;
            let event = fly(&mut drone, t);
            if event.is_some() {
                break;
            }
            assert!(!drone.awaits_plan(), "looking around at {t:.1} s");
            assert!(t < config.scan_s + 1.0, "the look around went on");
        }
        // Its look around is over and it has no goal, but the map does not hold the look's
        // last frames yet.
        for _ in 0..2 {
            t += 0.1;
            fly(&mut drone, t);
            assert!(!drone.awaits_plan(), "frames to {:.2} s mapped", t - LAG_S);
        }
        t += 0.1;
        fly(&mut drone, t);
        assert!(drone.awaits_plan(), "the map holds the frames to the end");
        t += 0.1;
        fly(&mut drone, t);
        assert!(drone.awaits_plan(), "it hovers until a plan comes");
        // A plan, even one with nothing for it, is what it waited for.
        drone.set_plan(None, vec![], None, t);
        assert!(!drone.awaits_plan());
    }

    #[test]
    fn a_drone_flies_on_through_a_bend_and_turns_on_the_spot_only_to_turn_back() {
        let step = |bearing_deg: f64| {
            let mut follower = PathFollower::new(DroneConfig::default().follower);
            let (s, c) = bearing_deg.to_radians().sin_cos();
            follower.set_path(vec![[0.0, 0.0], [2.0 * c, 2.0 * s]]);
            follower.step(Some(Pose2 {
                x: 0.0,
                y: 0.0,
                yaw: 0.0,
            }))
        };
        // Up to 90° off its heading it flies toward the path while it turns; behind it, it
        // turns first, holding where it is.
        for (bearing_deg, tracks) in [(60.0, true), (-80.0, true), (120.0, false), (180.0, false)] {
            let follow = step(bearing_deg);
            let turns = matches!(follow, Follow::Turn { .. });
            let flies = matches!(follow, Follow::Track { .. });
            assert!(
                flies == tracks && turns != tracks,
                "{bearing_deg}°: {follow:?}"
            );
        }
    }

    #[test]
    fn a_turn_on_the_spot_to_a_path_behind_flies_on_for_its_last_sixty_degrees() {
        let mut follower = PathFollower::new(DroneConfig::default().follower);
        // The path leads west; the drone faces east: a turn on the spot.
        follower.set_path(vec![[0.0, 0.0], [-2.0, 0.0]]);
        let facing = |yaw_deg: f64| {
            Some(Pose2 {
                x: 0.0,
                y: 0.0,
                yaw: f64::to_radians(yaw_deg),
            })
        };
        assert!(matches!(follower.step(facing(0.0)), Follow::Turn { .. }));
        // 70° still to turn: it turns on; 50°: it flies, turning the rest on the way.
        let follow = follower.step(facing(110.0));
        assert!(matches!(follow, Follow::Turn { .. }), "{follow:?}");
        let follow = follower.step(facing(130.0));
        assert!(matches!(follow, Follow::Track { .. }), "{follow:?}");
    }

    #[test]
    fn a_look_around_turns_the_short_way_to_the_unknown_and_no_further() {
        let config = DroneConfig::default();
        // The unknown to the right (south): a clockwise quarter turn, not a whole one.
        let south = ([-0.3, 0.3], [-1.95, -1.0]);
        let (event, t, yaw) = look_around_in(Some(south), None, None);
        assert_eq!(event, DroneEvent::GiveUp([1.0, 0.0]));
        assert!(yaw < -1.5 && yaw > -3.0, "clockwise past south: {yaw} rad");
        assert!(t < 0.6 * config.scan_s, "ended at {t} s");
        // A Kinect's frames change nothing; a wider camera (60° each side) has seen it all
        // sooner.
        let kinect = link::camera::Intrinsics::kinect(640, 480).half_fov_x(640);
        let (_, t_kinect, _) = look_around_in(Some(south), Some(kinect), None);
        assert!((t_kinect - t).abs() < 0.15, "{t_kinect} s against {t} s");
        let (_, t_wide, yaw_wide) = look_around_in(Some(south), Some(1.05), None);
        assert!(yaw_wide < -1.5, "clockwise past south: {yaw_wide} rad");
        assert!(t_wide < t - 0.5, "{t_wide} s against {t} s");
        // Nothing unknown: it holds for the map to catch up with the camera, then goes on.
        let (_, t, _) = look_around_in(None, None, None);
        assert!(
            t >= config.scan_min_s && t < config.scan_min_s + 0.2,
            "ended at {t} s"
        );
        // The unknown on every side: the whole turn (until the view has met where it began).
        let (_, t, yaw) = look_around_in(Some(([-1.95, 1.95], [-1.95, 1.95])), None, None);
        let half_fov = View::default().half_fov_rad;
        assert!(t > 0.8 * config.scan_s, "ended at {t} s");
        assert!(
            yaw >= std::f64::consts::TAU - 2.0 * half_fov,
            "a whole turn: {yaw} rad"
        );
    }

    #[test]
    fn a_drone_taking_off_beside_others_turns_its_share_of_the_first_look_around() {
        let config = DroneConfig::default();
        // Airborne at (0, 0) facing +x where nothing is mapped yet (every side a tie), told
        // its share or not: the heading goal two seconds into the look around that begins.
        let turned_after_takeoff = |drone: &mut Drone, t0: f64| {
            drone.phase = Phase::TakingOff;
            let mut t = t0;
            while t < t0 + 2.0 {
                drone.slam_fix(t, [0.0, 0.0, 0.9], drone.yaw_goal, None, false);
                drone.tick(t, &config);
                t += 0.1;
            }
            assert_eq!(drone.phase, Phase::Exploring);
            assert!(drone.scan.is_some(), "looking around");
            drone.yaw_goal - drone.scan.map_or(0.0, |s| s.yaw0)
        };
        let mut alone = exploring_drone(Arc::default(), &config);
        assert!(
            turned_after_takeoff(&mut alone, 0.0) > 0.5,
            "counter-clockwise on a tie"
        );
        let mut beside = exploring_drone(Arc::default(), &config);
        beside.share_first_look(-1.0);
        assert!(
            turned_after_takeoff(&mut beside, 0.0) < -0.5,
            "clockwise, its share"
        );
        // Its share was of the first look around: taking off again later, it looks its own way.
        beside.scan = None;
        assert!(turned_after_takeoff(&mut beside, 10.0) > 0.5);
    }

    #[test]
    fn a_shared_first_look_ends_once_the_drones_sharing_it_have_seen_every_side() {
        let config = DroneConfig::default();
        // Airborne at (0, 0) with no map (to itself, unknown all round): it would turn on until
        // the whole turn is done. Ticks from `t0` for `seconds`; whether it still looks.
        let fly = |drone: &mut Drone, t0: f64, seconds: f64| {
            let mut t = t0;
            while t < t0 + seconds {
                drone.slam_fix(t, [0.0, 0.0, 0.9], drone.yaw_goal, None, false);
                drone.tick(t, &config);
                t += 0.1;
            }
            drone.scan.is_some()
        };
        let mut alone = exploring_drone(Arc::default(), &config);
        alone.phase = Phase::TakingOff;
        assert!(fly(&mut alone, 0.0, 0.5));
        assert_eq!(alone.shared_look_view(&config), None, "its look is its own");
        alone.shared_look_seen();
        assert!(fly(&mut alone, 0.5, config.scan_min_s + 1.0), "and goes on");

        let mut beside = exploring_drone(Arc::default(), &config);
        beside.share_first_look(1.0);
        beside.phase = Phase::TakingOff;
        assert!(fly(&mut beside, 0.0, 0.5));
        let (heading, view) = beside.shared_look_view(&config).expect("its share's view");
        assert!((heading - beside.pose().expect("a pose")[3]).abs() < 1e-9);
        assert_eq!(Some(view), beside.view(&config));
        assert!(
            fly(&mut beside, 0.5, config.scan_min_s + 1.0),
            "on while sides are unseen"
        );
        // Every side seen between them: it ends its part now, and tells no more headings.
        beside.shared_look_seen();
        assert_eq!(beside.shared_look_view(&config), None);
        assert!(!fly(&mut beside, 3.5, 0.2), "over");
        // Told so before its minimum was up, it still turns for the minimum.
        let mut early = exploring_drone(Arc::default(), &config);
        early.share_first_look(1.0);
        early.phase = Phase::TakingOff;
        assert!(fly(&mut early, 0.0, 0.5));
        early.shared_look_seen();
        assert!(
            fly(&mut early, 0.5, config.scan_min_s - 1.0),
            "the map lags the camera"
        );
        assert!(!fly(&mut early, config.scan_min_s - 0.5, 1.0));
    }

    #[test]
    fn the_planner_weighs_turns_from_the_way_a_drone_faces_unless_it_is_looking_around() {
        let config = DroneConfig::default();
        let mut drone = exploring_drone(Arc::default(), &config);
        drone.slam_fix(0.1, [1.0, 2.0, 0.9], 0.0, None, false);
        let yaw = drone.pose().expect("a pose")[3];
        assert_eq!(drone.plan_heading(&config), Some(yaw), "the pose's yaw");
        // Looking around, it ends facing where the unknown ran out: no heading to weigh.
        drone.scan = Some(Scan::new(0.1, 0.8, None, &config));
        assert_eq!(drone.plan_heading(&config), None);
        drone.scan = None;
        assert_eq!(drone.plan_heading(&config), Some(yaw));
    }

    #[test]
    fn a_look_around_told_to_see_the_most_unknown_first_turns_toward_it_not_the_short_way() {
        // Facing east at (0, 0): a sliver of unknown just out of view to the right (bearings
        // −33° to −50°) and a bigger unknown behind to the left (112°–171°). Seeing both ends
        // soonest clockwise; the bigger is seen soonest counter-clockwise.
        let mut map = walled_room(Some(([-1.95, -0.8], [0.3, 1.95])));
        for y in 0..80 {
            for x in 0..80 {
                let p = map.center_of((x, y));
                if (1.0..1.4).contains(&p[0]) && (-1.2..-0.8).contains(&p[1]) {
                    map.set((x, y), nav::Cell::Unknown);
                }
            }
        }
        let map = Arc::new(map);
        let turned = |most_unknown_first: bool| {
            let config = DroneConfig {
                look_most_unknown_first: most_unknown_first,
                ..DroneConfig::default()
            };
            let mut drone = exploring_drone(Arc::default(), &config);
            drone.set_map(map.clone());
            drone.set_plan(Some([1.0, 0.0]), vec![[0.0, 0.0]], None, 0.0);
            let mut t = 0.0;
            while t < 1.0 {
                t += 0.1;
                drone.slam_fix(t, [0.0, 0.0, 0.9], drone.yaw_goal, None, false);
                assert_eq!(drone.tick(t, &config), None, "still looking at {t} s");
            }
            drone.yaw_goal - drone.scan.map_or(f64::NAN, |s| s.yaw0)
        };
        let short = turned(false);
        assert!(short < -0.3, "clockwise: {short} rad");
        let most = turned(true);
        assert!(most > 0.3, "counter-clockwise: {most} rad");
    }

    #[test]
    fn a_look_around_told_which_way_turns_that_way() {
        // The unknown to the south: the short way is clockwise, but the last look here lost
        // the map turning so; counter-clockwise, past north and west, to south.
        let south = ([-0.3, 0.3], [-1.95, -1.0]);
        let (event, _, yaw) = look_around_in(Some(south), None, Some(1.0));
        assert_eq!(event, DroneEvent::GiveUp([1.0, 0.0]));
        assert!(yaw > 3.5, "counter-clockwise to south: {yaw} rad");
        let (_, _, yaw) = look_around_in(Some(south), None, Some(-1.0));
        assert!(yaw < -1.5 && yaw > -3.0, "clockwise past south: {yaw} rad");
    }

    #[test]
    fn a_look_around_on_few_matches_turns_at_half_its_rate() {
        let config = DroneConfig::default();
        let rate = std::f64::consts::TAU / config.scan_s;
        // Two seconds of a look around, the SLAM's registrations on `inliers` matches.
        let turned = |inliers: Option<usize>| {
            let mut drone = exploring_drone(Arc::default(), &config);
            drone.scan = Some(Scan::new(0.0, 0.0, None, &config));
            drone.last_tick = Some(0.0);
            let mut t = 0.0;
            while t < 2.0 - 1e-9 {
                t += 0.1;
                drone.slam_fix(t, [0.0, 0.0, 0.9], drone.yaw_goal, inliers, false);
                drone.inliers = inliers;
                assert_eq!(drone.tick(t, &config), None);
            }
            drone.yaw_goal
        };
        let full = 2.0 * rate;
        for inliers in [Some(config.look_slow_inliers), Some(130), None] {
            let yaw = turned(inliers);
            assert!((yaw - full).abs() < 1e-6, "{inliers:?}: {yaw} rad");
        }
        let yaw = turned(Some(config.look_slow_inliers - 1));
        assert!((yaw - 0.5 * full).abs() < 1e-6, "on few matches: {yaw} rad");
    }

    /// A look around (giving up the goal (1, 0)) turned for 2 s, a keyframe now and then,
    /// then lost by the SLAM at `t` = 2 s for `lost_s`; returns the drone, `t` and its heading.
    fn look_around_lost_for(lost_s: f64, config: &DroneConfig) -> (Drone, f64, f64) {
        let mut drone = exploring_drone(Arc::default(), config);
        drone.scan = Some(Scan::new(0.0, 0.0, Some([1.0, 0.0]), config));
        let mut t = 0.0;
        let mut yaw = 0.0;
        while t < 2.0 {
            t += 0.1;
            yaw += 0.06;
            drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, true);
            assert_eq!(drone.tick(t, config), None);
        }
        assert!(drone.yaw_goal > 1.0, "turning: {}", drone.yaw_goal);
        // Lost: it turns back to the last keyframe's heading, not on with the look around.
        drone.slam_lost(t, config);
        let lost_at = t;
        while t < lost_at + lost_s - 1e-9 {
            t += 0.1;
            assert_eq!(drone.tick(t, config), None);
            assert_eq!(drone.yaw_goal, yaw);
        }
        (drone, t, yaw)
    }

    #[test]
    fn a_look_around_that_loses_the_map_for_long_ends_where_the_map_is_found_again() {
        let config = DroneConfig::default();
        let (mut drone, mut t, yaw) = look_around_lost_for(config.look_lost_s + 0.5, &config);
        // Found again, the look around is over (its goal set aside, but not as looked at),
        // long before its full turn's time.
        let mut event = None;
        while event.is_none() {
            t += 0.1;
            drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, false);
            event = drone.tick(t, &config);
            assert!(t < config.scan_s, "the look around went on");
        }
        assert_eq!(event, Some(DroneEvent::LookCut([1.0, 0.0], 1.0)));
        assert!(drone.scan.is_none());
    }

    #[test]
    fn a_look_around_lost_briefly_goes_on_from_where_it_was_lost_until_its_losses_add_up() {
        let config = DroneConfig::default();
        let rate = std::f64::consts::TAU / config.scan_s;
        // Lost for 0.6 s, then found: the turn resumes from the bearing where it was lost (the
        // time lost does not count), and the whole look is a look (the goal given up).
        let (mut drone, mut t, yaw) = look_around_lost_for(0.6, &config);
        t += 0.1;
        drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, false);
        assert_eq!(drone.tick(t, &config), None);
        let resumed = drone.yaw_goal;
        assert!(
            (resumed - 2.0 * rate).abs() < 0.1,
            "resumed at {resumed} rad, lost at {} rad",
            2.0 * rate
        );
        let mut event = None;
        while event.is_none() && t < 20.0 {
            t += 0.1;
            drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, false);
            event = drone.tick(t, &config);
        }
        assert_eq!(event, Some(DroneEvent::GiveUp([1.0, 0.0])));
        assert!(t > config.scan_s + 0.5, "its whole turn: {t} s");
        // Two losses that add up to more than `look_lost_s` cut it short.
        let (mut drone, mut t, yaw) = look_around_lost_for(0.8, &config);
        for _ in 0..5 {
            t += 0.1;
            drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, false);
            assert_eq!(drone.tick(t, &config), None, "0.8 s lost is not too long");
        }
        drone.slam_lost(t, &config);
        for _ in 0..8 {
            t += 0.1;
            assert_eq!(drone.tick(t, &config), None);
        }
        t += 0.1;
        drone.slam_fix(t, [0.0, 0.0, 0.9], yaw, None, false);
        assert_eq!(
            drone.tick(t, &config),
            Some(DroneEvent::LookCut([1.0, 0.0], 1.0))
        );
    }

    #[test]
    fn a_drone_without_a_pose_hovers_level_turning_then_lands_where_it_is() {
        let vehicle = Arc::new(StubbornVehicle::default());
        let config = DroneConfig::default();
        let mut drone = exploring_drone(vehicle.clone(), &config);
        // The start pose holds for a while; without SLAM fixes (tracking lost) it expires.
        let mut t = 0.0;
        while drone.pose().is_some() {
            t += 0.1;
            drone.tick(t, &config);
            assert!(t < 20.0, "a pose without any SLAM fix must expire");
        }
        let blind = t;
        while t < blind + config.blind_land_s - 0.5 {
            t += 0.1;
            drone.tick(t, &config);
            let s = drone.sticks.expect("sticks");
            // Level (no drift from stale tilt), altitude held by the vehicle, a slow turn.
            assert_eq!((s.roll, s.pitch, s.throttle), (0.0, 0.0, 0.0));
            assert_eq!(s.yaw, config.blind_yaw);
            assert_eq!(drone.phase, Phase::Exploring);
        }
        drone.tick(blind + config.blind_land_s + 0.5, &config);
        assert_eq!(drone.phase, Phase::Landing);
        assert_eq!(drone.left_mission.as_deref(), Some("no pose for 30 s"));
        let waited = std::time::Instant::now();
        while !vehicle
            .commands
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .contains(&Command::Land)
        {
            assert!(
                waited.elapsed() < std::time::Duration::from_secs(2),
                "no LAND sent"
            );
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }

    #[test]
    fn a_vehicle_that_lands_or_disarms_on_its_own_is_followed() {
        let config = DroneConfig::default();
        // Its failsafe switches to LAND: the station stops steering and waits for it to land.
        let vehicle = Arc::new(StubbornVehicle::default());
        let mut drone = exploring_drone(vehicle.clone(), &config);
        drone.tick(0.1, &config);
        *vehicle.mode.lock().unwrap() = Some("LAND".into());
        drone.tick(0.2, &config);
        assert_eq!(drone.phase, Phase::Landing);
        let s = drone.sticks.expect("sticks");
        assert_eq!((s.roll, s.pitch, s.yaw), (0.0, 0.0, 0.0));
        vehicle
            .disarmed
            .store(true, std::sync::atomic::Ordering::Relaxed);
        drone.tick(0.3, &config);
        assert_eq!(drone.phase, Phase::Landed);
        assert_eq!(
            drone.left_mission.as_deref(),
            Some("its vehicle landed it (LAND mode)")
        );

        // It disarms without a word (battery failsafe seen late, a pilot): landed after 2 s.
        let vehicle = Arc::new(StubbornVehicle::default());
        let mut drone = exploring_drone(vehicle.clone(), &config);
        drone.phase = Phase::Returning;
        vehicle
            .disarmed
            .store(true, std::sync::atomic::Ordering::Relaxed);
        drone.tick(10.0, &config);
        drone.tick(11.0, &config);
        assert_eq!(
            drone.phase,
            Phase::Returning,
            "a stale heartbeat is not a landing"
        );
        drone.tick(10.0 + config.disarmed_landed_s + 0.1, &config);
        assert_eq!(drone.phase, Phase::Landed);
        assert_eq!(drone.left_mission.as_deref(), Some("its vehicle disarmed"));
        // Flying again later, a first stale "disarmed" is not an old landing come back.
        drone.phase = Phase::TakingOff;
        drone.tick(12.5, &config);
        assert_eq!(drone.phase, Phase::TakingOff);
        assert!(
            drone
                .take_messages()
                .iter()
                .any(|m| m.contains("disarmed on its own"))
        );
    }

    #[test]
    fn a_drone_turns_home_when_its_charge_would_only_just_bring_it_back_from_where_it_is() {
        let config = DroneConfig::default();
        // Two drones 3 m from their starts on packs at 50 % draining as the simulator's (12
        // minutes from full), one with a way home of 60 m on the map, one with 0.5 m (the
        // straight line counts then).
        let mut turned = vec![];
        for way_home in [60.0, 0.5] {
            let vehicle = Arc::new(StubbornVehicle::default());
            let mut drone = exploring_drone(vehicle.clone(), &config);
            drone.set_way_home(Some(way_home));
            let mut t = 0.0f64;
            while drone.phase == Phase::Exploring && t < 100.0 {
                *vehicle.battery_pct.lock().unwrap() = Some((50.0 - t / 7.2).round() as u8);
                drone.slam_fix(t, [3.0, 0.0, 0.9], 0.0, None, true);
                drone.tick(t, &config);
                t += 0.1;
            }
            turned.push((
                t,
                drone.phase,
                drone.left_mission.clone(),
                drone.battery_home_at(),
            ));
            if way_home == 60.0 {
                let said = drone.take_messages();
                assert!(
                    said.iter().any(|m| m
                        == "battery at 38 %: 60 m from its start: about 24 % to get there and land, 15 % to spare"),
                    "{said:?}"
                );
            }
        }
        // 60 m out needs about 23 % (100 s at 0.6 m/s and 10 s to turn and land, times 1.5): it
        // turns on reading 38 % (from 82.8 s; the drain measured over whole percent, a little
        // high). Beside its start, it flies on.
        assert!((82.7..83.0).contains(&turned[0].0), "{turned:?}");
        assert_eq!(turned[0].1, Phase::Returning);
        assert_eq!(turned[0].2.as_deref(), Some("battery at 38 %"));
        assert_eq!(turned[1].1, Phase::Exploring, "{turned:?}");
        assert_eq!(turned[1].2, None);
        // It would turn home, from 3 m, at 15 % and the 3.1 % that needs.
        let home_at = turned[1].3.expect("shown while it explores");
        assert!((18.0..18.5).contains(&home_at), "{home_at}");
        assert_eq!(turned[0].3, None, "not shown on the way home");
    }

    #[test]
    fn a_drone_home_for_its_battery_rejoins_on_a_charged_one_only_when_told_to() {
        for swap in [Some(BatterySwap::default()), None] {
            let config = DroneConfig {
                battery_swap: swap,
                ..DroneConfig::default()
            };
            let vehicle = Arc::new(StubbornVehicle::default());
            let battery = |pct: u8| *vehicle.battery_pct.lock().unwrap() = Some(pct);
            let mut drone = exploring_drone(vehicle.clone(), &config);
            battery(14);
            drone.tick(0.1, &config);
            // Home (it is at its start already): it lands, and the vehicle disarms.
            assert_eq!(drone.phase, Phase::Landing);
            assert_eq!(drone.left_mission.as_deref(), Some("battery at 14 %"));
            assert_eq!(drone.awaits_battery, swap.is_some());
            vehicle
                .disarmed
                .store(true, std::sync::atomic::Ordering::Relaxed);
            drone.tick(1.0, &config);
            assert_eq!(drone.phase, Phase::Landed);
            let said = drone.take_messages().join("; ");
            assert_eq!(
                said.contains("waiting for a charged battery"),
                swap.is_some()
            );
            let shown = drone.why_away().expect("away");
            assert_eq!(
                shown.contains("waits for a charged battery"),
                swap.is_some()
            );
            // A battery that is not a charged one: it stays down.
            battery(60);
            assert!(!drone.rejoin_after_swap(2.0, &config));
            // A charged one: it takes off 5 s after it first read it, not before.
            battery(100);
            let rejoined: Vec<f64> = [3.0, 7.9, 8.1]
                .into_iter()
                .filter(|&t| drone.rejoin_after_swap(t, &config))
                .collect();
            if swap.is_none() {
                assert!(rejoined.is_empty());
                assert_eq!(drone.phase, Phase::Landed);
                assert_eq!(drone.left_mission.as_deref(), Some("battery at 14 %"));
                continue;
            }
            assert_eq!(rejoined, [8.1]);
            assert_eq!(drone.phase, Phase::Arming);
            assert_eq!(drone.left_mission, None);
            assert!(!drone.awaits_battery);
            assert_eq!(drone.battery_swaps, 1);
            assert!(
                drone
                    .take_messages()
                    .iter()
                    .any(|m| m.contains("a charged battery (100 %): taking off in 5 s"))
            );
            // Once in the air again, nothing more to rejoin.
            assert!(!drone.rejoin_after_swap(20.0, &config));
        }
    }

    #[test]
    fn a_drone_whose_link_comes_back_in_flight_rejoins_the_mission() {
        let config = DroneConfig::default();
        let vehicle = Arc::new(StubbornVehicle::default());
        let mut drone = exploring_drone(vehicle.clone(), &config);
        drone.tick(0.1, &config);
        assert_eq!(drone.left_mission, None);
        vehicle
            .lost
            .store(true, std::sync::atomic::Ordering::Relaxed);
        drone.tick(0.2, &config);
        assert_eq!(drone.phase, Phase::LinkLost);
        assert_eq!(drone.left_mission.as_deref(), Some("link lost"));
        // Back while still flying (armed, not in LAND): exploring again, nothing to report.
        vehicle
            .lost
            .store(false, std::sync::atomic::Ordering::Relaxed);
        drone.tick(0.3, &config);
        assert_eq!(drone.phase, Phase::Exploring);
        assert_eq!(drone.left_mission, None);
        // A later reason is the one kept; the first of a flight wins over what follows.
        drone.return_home("battery at 24 %");
        drone.return_home("no camera frame for 5 s");
        drone.land();
        assert_eq!(drone.left_mission.as_deref(), Some("battery at 24 %"));
    }

    /// The simulator's vehicle flying its path east down a corridor at its cruise speed, in a
    /// 0.15 m/s draught the same way, 1.1 m short of the corridor's end wall when it is told to
    /// land; its pose from the truth at 10 Hz. Once the station sends LAND, it descends as the
    /// shield lands a Naza: its own slow throttle, the station's roll, pitch and yaw. Its speed
    /// when told, where it touched down (metres east of where it was told) and how often it
    /// touched a wall.
    fn land_from_a_flight(config: &DroneConfig) -> (f64, f64, u32) {
        let vehicle_link = Arc::new(StubbornVehicle::default());
        // Corridor x 0.25–6.25 m, y 0.25–2.25 m (walls round it), 0.25 m cells.
        let mut text = String::from("resolution 0.25\nceiling 3.0\n---\n");
        for row in 0..10 {
            let wall = row == 0 || row == 9;
            text += &format!("#{}#\n", if wall { "#" } else { "." }.repeat(24));
        }
        let world = sitl::world::World::parse_text("corridor", &text).expect("a corridor");
        let (told_x, y) = (6.25 - 1.1, 1.25);
        let mut vehicle = sitl::vehicle::Vehicle::new(Default::default(), 1.0, y, 0.0);
        let mut drone = Drone::new(
            0,
            DroneSpec {
                name: "drone 1".into(),
                link: vehicle_link.clone(),
                start_sequence: StartSequence::Shield,
                altitude: 0.9,
                start: Some([1.0, y, 0.0]),
            },
            config,
            0.0,
        );
        drone.phase = Phase::Exploring;
        drone.set_map(Arc::new(world.to_grid()));
        vehicle.set_armed(true);
        vehicle.set_wind([0.15, 0.0]);
        let mut t = 0.0;
        // A tenth of a second: the station's tick, the vehicle flying its sticks, a fix.
        let fly = |vehicle: &mut sitl::vehicle::Vehicle, drone: &mut Drone, t: &mut f64| {
            for _ in 0..10 {
                vehicle.step(&world, 0.01);
            }
            *t += 0.1;
            let s = vehicle.state();
            *vehicle_link.yaw.lock().expect("yaw") = Some(s.yaw as f32);
            drone.slam_fix(*t, s.position, s.yaw, Some(100), false);
            drone.tick(*t, config);
        };
        // Up to its band (where the link's telemetry reads it)…
        vehicle.set_sticks(Sticks {
            throttle: 1.0,
            ..Sticks::CENTRED
        });
        while vehicle.state().position[2] < 0.9 {
            fly(&mut vehicle, &mut drone, &mut t);
        }
        // …then along its path to the far end, until it passes the spot where it is told.
        drone.set_plan(Some([5.9, y]), vec![[1.0, y], [5.9, y]], None, t);
        while vehicle.state().position[0] < told_x {
            vehicle.set_sticks(drone.sticks.expect("sticks"));
            fly(&mut vehicle, &mut drone, &mut t);
            assert!(t < 60.0, "never got there");
        }
        let speed = vehicle.state().velocity[0];
        drone.land();
        let (told, told_at) = (vehicle.state().position[0], t);
        while drone.landing_by.braking() {
            vehicle.set_sticks(drone.sticks.expect("sticks while braking"));
            fly(&mut vehicle, &mut drone, &mut t);
            assert!(t < 60.0, "LAND never sent");
        }
        // (Its braking clock starts at the tick after it was told, 0.1 s on.)
        let braked = t - told_at - 0.1;
        assert!(
            braked <= config.land_brake_s + 0.15,
            "braked for {braked:.1} s"
        );
        while !vehicle.state().landed {
            vehicle.set_sticks(Sticks {
                throttle: link::shield::LAND_THROTTLE,
                ..drone.sticks.expect("sticks")
            });
            fly(&mut vehicle, &mut drone, &mut t);
            assert!(t < 60.0, "never landed");
        }
        let s = vehicle.state();
        (speed, s.position[0] - told, s.collisions)
    }

    #[test]
    fn a_drone_told_to_land_in_flight_stops_first_and_is_held_there_as_it_comes_down() {
        let config = DroneConfig::default();
        let (speed, past, collisions) = land_from_a_flight(&config);
        assert!(speed > 0.6, "told at {speed:.2} m/s");
        assert_eq!(
            collisions, 0,
            "touched a wall, {past:.2} m past where it was told"
        );
        assert!(past < 0.3, "landed {past:.2} m past where it was told");
        // Landing at once with its sticks left centred, it coasts on down into the wall (the
        // shield's seed 6, stop 79).
        let at_once = DroneConfig {
            land_brake_s: 0.0,
            steer_landing: false,
            ..config
        };
        let (_, coasted, collisions) = land_from_a_flight(&at_once);
        assert!(
            collisions > 0 && coasted > 0.8,
            "at once: {coasted:.2} m on, {collisions} touches"
        );
    }

    #[test]
    fn land_is_sent_again_while_the_vehicle_stays_armed() {
        let vehicle = Arc::new(StubbornVehicle::default());
        let config = DroneConfig::default();
        let mut drone = exploring_drone(vehicle.clone(), &config);
        drone.land();
        let lands = || {
            vehicle
                .commands
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .iter()
                .filter(|c| **c == Command::Land)
                .count()
        };
        let mut t = 0.0;
        let mut tick_until = |end: f64, drone: &mut Drone| {
            while t < end {
                t += 0.1;
                drone.tick(t, &config);
                // Commands answer on their own threads.
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        };
        tick_until(config.land_retry_s - 1.0, &mut drone);
        assert_eq!(lands(), 1, "once, then patience");
        tick_until(config.land_retry_s + 1.0, &mut drone);
        let waited = std::time::Instant::now();
        while lands() < 2 && waited.elapsed() < std::time::Duration::from_secs(2) {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert_eq!(lands(), 2, "still armed: sent again");
        assert_eq!(drone.phase, Phase::Landing);
        assert!(
            drone
                .take_messages()
                .iter()
                .any(|m| m.contains("sending it again"))
        );
    }
}
