//! The mission runtime: per drone, camera frames and telemetry → SLAM → mission planner (1 Hz)
//! → path → path follower and position controllers (10 Hz) → RC overrides through the link.
//!
//! Threads: the SLAM ([`perception`]) works through camera frames; the planner (`planning`)
//! projects the map and plans once a second; the mission loop (this module) runs the drones'
//! filters, state machines and controllers on the mission clock without waiting for either,
//! obeys the operator's commands and publishes a [`Snapshot`] every tick, which displays read
//! without ever waiting on SLAM, planning or I/O.
//!
//! Safety: a drone whose link is lost drops out (its goal goes to the others; the vehicle's own
//! failsafe lands it) and rejoins if the link comes back while it still flies; a drone without a
//! valid pose hovers level at its altitude and lands if that lasts; a low battery sends it home;
//! `land all` always works.

pub mod battery;
pub mod drone;
pub mod perception;
mod planning;
pub mod stall;
pub mod trail;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use link::{LinkStatus, Sticks, Telemetry};
use nav::blacklist::Blacklist;
use nav::clearance::Comfort;
use nav::grid::Grid;
use nav::mission::{PlannerConfig, Strategy, centring_comfort};
use slam::system::{RobotState, Slam};

use crate::clock::Clock;
use crate::record::{PlannedGoal, Record, Recorder};
use drone::{Drone, DroneConfig, DroneEvent, DroneSpec, Phase};
use perception::{CameraFrame, Perception, PerceptionResult, SensorLog, SensorSample, SlamView};
use planning::{Ask, Cadence, Planner, PlannerStopped};
use stall::{STALL_S, Stall};
use trail::Trail;

/// Mission settings.
#[derive(Debug, Clone)]
pub struct RuntimeConfig {
    /// How frontiers are assigned.
    pub strategy: Strategy,
    /// Plan with obstacles grown by the first of these radii that still leaves a reachable
    /// frontier (a margin for tracking errors first, narrower gaps later), metres.
    pub planner_radii: Vec<f64>,
    /// Frontiers within this distance of each other, in sight, are one region, and drones are
    /// spread one to a region first ([`PlannerConfig::region_radius_m`]), metres; 0: off.
    pub region_radius_m: f64,
    /// A drone keeps the frontier it flies to unless another is cheaper by more than this
    /// ([`PlannerConfig::hold_margin_m`]), metres of path.
    pub hold_margin_m: f64,
    /// A frontier onto an enclosed pocket of unknown no bigger than this is ignored
    /// ([`PlannerConfig::max_pocket_m2`]), m²; 0: none is.
    pub max_pocket_m2: f64,
    /// What turning on the spot to face a path costs a drone in the assignment
    /// ([`PlannerConfig::turn_m_per_rad`]), metres of path per radian; 0: paths alone.
    pub turn_m_per_rad: f64,
    /// A drone left without a frontier waits this far short of another drone's
    /// ([`PlannerConfig::stage_back_m`]), metres of path; 0: it hovers where it is.
    pub stage_back_m: f64,
    /// Paths planned at a thinner radius than the widest keep, where they can, the widest
    /// one's distance from the walls ([`nav::mission::centring_comfort`]): through the middle
    /// of a door, not along its jamb. On by default (off from stop 66 for a hang that turned
    /// out to be the planner's, not this: see [`stall`]).
    pub centre_paths: bool,
    /// Paths keep this far from the unknown where they can, at every radius
    /// ([`PlannerConfig::unknown_comfort_m`]), metres: a wall not seen yet may begin at its
    /// edge. 0: no more than [`RuntimeConfig::centre_paths`] keeps.
    pub unknown_comfort_m: f64,
    /// Control period, seconds (mission clock).
    pub control_period: f64,
    /// Mission-planner period, seconds.
    pub plan_period: f64,
    /// A drone that ends its look around with nowhere to go asks the planner at once, not at
    /// its next step ([`planning::Cadence`]), as soon as the SLAM has processed its frames to
    /// the look's end ([`Drone::awaits_plan`]). Off by default (`gcs explore
    /// --plan-when-looked true`): on true poses, over 48 seeds side by side, four drones
    /// finished 4.6 s and one drone 5.7 s sooner with no collision, but on SLAM poses the main
    /// command, over 79 seeds side by side, was 3.8 s a mission sooner and had 6 collisions of
    /// drones the SLAM had lost or nearly lost, against 1 (`docs/benchmarks.md`, stops 84
    /// and 85).
    pub plan_when_looked: bool,
    /// Every drone's controllers and behaviour.
    pub drone: DroneConfig,
    /// Start the mission at once (headless), or wait for the operator.
    pub auto_start: bool,
    /// Give up and land this long after the start, seconds.
    pub timeout: Option<f64>,
    /// Exploration is not declared complete before this long after the start, seconds.
    pub min_mission_s: f64,
    /// With frontiers left out of reach, the end waits this long, the drones hovering, and
    /// lands only if a plan after it still reaches none, seconds. A SLAM pose half a metre
    /// off draws walls where there are none, which can close a door on the map until a loop
    /// closure moves them back: in SITL (stop 73) a mission ended at 77.7 % coverage with 11
    /// frontiers out of reach while a drone's pose was 0.5 m off, and the SLAM corrected it
    /// 1 s after the drones turned to land. Ends with nothing out of reach do not wait.
    pub settle_before_end_s: f64,
    /// End the runtime when every drone is down after the mission (headless).
    pub exit_when_done: bool,
    /// After a shutdown, end this long after it even if a drone has not reported landing,
    /// seconds (its own failsafe takes over once the station is gone).
    pub shutdown_wait_s: f64,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            strategy: Strategy::Hungarian,
            planner_radii: vec![0.45, 0.35, 0.25],
            region_radius_m: PlannerConfig::default().region_radius_m,
            hold_margin_m: PlannerConfig::default().hold_margin_m,
            max_pocket_m2: PlannerConfig::default().max_pocket_m2,
            turn_m_per_rad: PlannerConfig::default().turn_m_per_rad,
            stage_back_m: PlannerConfig::default().stage_back_m,
            centre_paths: true,
            unknown_comfort_m: 0.45,
            control_period: 0.1,
            plan_period: 1.0,
            plan_when_looked: false,
            drone: DroneConfig::default(),
            auto_start: true,
            timeout: None,
            min_mission_s: 10.0,
            settle_before_end_s: 5.0,
            exit_when_done: true,
            shutdown_wait_s: 60.0,
        }
    }
}

/// What the operator can ask for.
#[derive(Debug, Clone, PartialEq)]
pub enum Operator {
    /// Start the mission: every drone takes off and explores.
    Start,
    /// Every flying drone holds where it is.
    Pause,
    /// Back to exploring after a pause.
    Resume,
    /// Every drone lands where it is, now.
    LandAll,
    /// One drone.
    Drone(usize, DroneCommand),
    /// End the runtime (after landing whatever flies).
    Shutdown,
}

/// A command to one drone (the thesis's control-test tab).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DroneCommand {
    /// Arm, start the motors and take off to its altitude band.
    TakeOff,
    /// Land where it is.
    Land,
    /// Disarm (only on the ground).
    Disarm,
    /// Hold position at this height (metres) and yaw (radians).
    Hold {
        /// Goal height.
        height: f64,
        /// Goal yaw.
        yaw: f64,
    },
    /// Back to exploring after a hold.
    Explore,
    /// Fly to the start and land there.
    ReturnHome,
}

/// The mission as a whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissionState {
    /// Waiting for the operator's start.
    Waiting,
    /// Drones take off and explore.
    Exploring,
    /// Every drone holds.
    Paused,
    /// The mission is over; drones are landing.
    Finishing(Outcome),
    /// Every drone is down.
    Done(Outcome),
}

impl MissionState {
    /// A short name for displays.
    pub fn name(self) -> &'static str {
        match self {
            MissionState::Waiting => "waiting for start",
            MissionState::Exploring => "exploring",
            MissionState::Paused => "paused",
            MissionState::Finishing(_) => "landing",
            MissionState::Done(_) => "done",
        }
    }
}

/// Why a drone the operator sent home or landed left the mission ([`Drone::left_mission`]).
const OPERATOR: &str = "the operator's command";

/// Why a mission ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// No reachable frontier was left.
    Completed,
    /// The timeout passed.
    TimedOut,
    /// The operator landed every drone.
    LandAll,
    /// No drone was left flying (links lost, landed by their failsafes).
    NoDroneLeft,
    /// The planner gave no drone a goal for [`STALL_S`] while it counted a frontier as
    /// reachable ([`stall`]).
    Stalled,
}

impl Outcome {
    /// A short name for displays and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Completed => "completed",
            Outcome::TimedOut => "timed out",
            Outcome::LandAll => "land all",
            Outcome::NoDroneLeft => "no drone left",
            Outcome::Stalled => "stalled",
        }
    }
}

/// One drone as displays see it.
#[derive(Debug, Clone)]
pub struct DroneView {
    /// Index in the fleet.
    pub id: usize,
    /// Display name.
    pub name: String,
    /// What it does.
    pub phase: Phase,
    /// Why it left the mission before the end ([`Drone::why_away`]).
    pub left_mission: Option<String>,
    /// Link health.
    pub link: LinkStatus,
    /// Latest telemetry.
    pub telemetry: Telemetry,
    /// The charge at which it turns home from where it is, percent (while it explores, once
    /// its pack's drain is measured).
    pub battery_home_at: Option<f64>,
    /// The charge read off its pack's voltage, percent, for a vehicle that reports only the
    /// voltage (the shield), once it has flown ([`battery::Gauge::estimate_pct`]).
    pub battery_estimate_pct: Option<f64>,
    /// The filter's pose (x, y, z, yaw), if valid.
    pub pose: Option<[f64; 4]>,
    /// Standard deviation of the filter's horizontal position, metres.
    pub pose_sigma: f64,
    /// SLAM tracking state.
    pub slam: RobotState,
    /// Its frontier (or home).
    pub goal: Option<[f64; 2]>,
    /// The path it follows.
    pub path: Vec<[f64; 2]>,
    /// Where it has been (x, y), decimated.
    pub trajectory: Trail,
    /// Where the position controller pulls it (x, y), map frame.
    pub setpoint: [f64; 2],
    /// Inliers of its last frame the SLAM tracked (`None`: relocalised or lost).
    pub inliers: Option<usize>,
    /// Goal height, metres.
    pub height_goal: f64,
    /// Goal yaw, radians.
    pub yaw_goal: f64,
    /// Sticks sent last.
    pub sticks: Option<Sticks>,
}

/// The runtime's state at one moment.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// Mission clock, seconds.
    pub time: f64,
    /// Seconds since the start of the mission (0 before it).
    pub elapsed: f64,
    /// The mission.
    pub state: MissionState,
    /// Every drone.
    pub drones: Vec<DroneView>,
    /// The 2D map the planner used last.
    pub grid: Option<Arc<Grid>>,
    /// The frontiers it saw (goal points).
    pub frontiers: Vec<[f64; 2]>,
    /// The SLAM.
    pub slam: Arc<SlamView>,
    /// Recent messages for the operator: (time, text).
    pub messages: Vec<(f64, String)>,
}

/// What a finished runtime hands back.
pub struct MissionReport {
    /// How it ended (`None` if it was shut down before).
    pub outcome: Option<Outcome>,
    /// Seconds from the start to the last drone down.
    pub mission_time_s: f64,
    /// Frontiers the map still had at the last plan that no drone could reach (a mission
    /// "completed" with some left ended on what its map let it fly to).
    pub frontiers_out_of_reach: usize,
    /// Frontier goals given up (reached while the frontier stayed, or no progress) that still
    /// hid a frontier at the last plan: what the map had left behind them. A goal reached
    /// whose frontier went away is not counted.
    pub goals_given_up: usize,
    /// Of those, the ones that still hid a frontier at the end though no drone ever looked
    /// around there whole: every look lost the map ([`Blacklist::never_seen`]).
    pub goals_never_seen: usize,
    /// Per drone: name, final phase, distance flown by the filter, filter trajectory.
    pub drones: Vec<DroneReport>,
    /// The SLAM and what it saw.
    pub perception: Option<PerceptionResult>,
}

/// One drone at the end.
#[derive(Debug, Clone)]
pub struct DroneReport {
    /// Display name.
    pub name: String,
    /// Final phase.
    pub phase: Phase,
    /// Why it left the mission before the end ([`Drone::left_mission`]).
    pub left_mission: Option<String>,
    /// Distance flown according to the filter, metres.
    pub path_length_m: f64,
    /// Charged batteries it took off again on ([`DroneConfig::battery_swap`]).
    pub battery_swaps: u32,
    /// The filter's trajectory: (time, [x, y, z, yaw]).
    pub trajectory: Vec<(f64, [f64; 4])>,
}

/// A running mission.
pub struct Runtime {
    commands: Sender<Operator>,
    snapshot: Arc<Mutex<Arc<Snapshot>>>,
    done: Arc<AtomicBool>,
    thread: Option<JoinHandle<MissionReport>>,
}

impl Runtime {
    /// Starts the mission loop and the SLAM for `drones`, with camera frames from `frames`.
    pub fn start(
        config: RuntimeConfig,
        drones: Vec<DroneSpec>,
        slam: Slam,
        frames: Receiver<CameraFrame>,
        clock: Arc<dyn Clock>,
        recorder: Option<Recorder>,
    ) -> std::io::Result<Self> {
        let sensors = Arc::new(SensorLog::new(drones.len()));
        let perception = Perception::start(
            slam,
            frames,
            sensors.clone(),
            recorder.clone(),
            config.drone.proximity,
        )?;
        let planner = Planner::start(perception.map())?;
        let t0 = clock.now();
        let mut drones: Vec<Drone> = drones
            .into_iter()
            .enumerate()
            .map(|(k, spec)| Drone::new(k, spec, &config.drone, t0))
            .collect();
        let mut first_looks = vec![];
        if let Some(view) = config.drone.sweep {
            // Drones that take off beside one another share their first look around.
            let starts: Vec<Option<[f64; 3]>> = drones.iter().map(|d| d.start).collect();
            let together = config.drone.look_together_m;
            let turns = nav::sweep::shared_turns(&starts, together, &view);
            for (drone, turn) in drones.iter_mut().zip(turns) {
                if let Some(turn) = turn {
                    drone.share_first_look(turn);
                }
            }
            first_looks = nav::sweep::groups(&starts, together)
                .into_iter()
                .filter(|g| g.len() > 1)
                .map(|g| (g, nav::sweep::SharedLook::new()))
                .collect();
        }
        let (commands, rx) = channel();
        let first = Snapshot {
            time: t0,
            elapsed: 0.0,
            state: MissionState::Waiting,
            drones: vec![],
            grid: None,
            frontiers: vec![],
            slam: Arc::new(SlamView::default()),
            messages: vec![],
        };
        let snapshot = Arc::new(Mutex::new(Arc::new(first)));
        let done = Arc::new(AtomicBool::new(false));
        let mut mission = Mission {
            config,
            drones,
            perception: Some(perception),
            sensors,
            clock,
            commands: rx,
            snapshot: snapshot.clone(),
            state: MissionState::Waiting,
            started: None,
            blacklist: Blacklist::new(PlannerConfig::default().blacklist_radius_m),
            given_up_left: 0,
            never_seen: 0,
            settling_since: None,
            grid: None,
            frontiers: vec![],
            messages: vec![],
            trajectories: vec![],
            recorder,
            last_plan_record: f64::NEG_INFINITY,
            planner,
            planner_lost: false,
            stall: Stall::default(),
            first_looks,
        };
        let thread = {
            let done = done.clone();
            std::thread::Builder::new()
                .name("mission".into())
                .spawn(move || {
                    let report = mission.run();
                    done.store(true, Ordering::Relaxed);
                    report
                })?
        };
        Ok(Self {
            commands,
            snapshot,
            done,
            thread: Some(thread),
        })
    }

    /// Sends an operator command (taken at the next tick).
    pub fn send(&self, command: Operator) {
        let _ = self.commands.send(command);
    }

    /// A sender for operator commands, for other threads.
    pub fn commander(&self) -> Sender<Operator> {
        self.commands.clone()
    }

    /// Makes Ctrl-C land every drone (`who` starts the message); the mission then ends as
    /// any other does, its outputs written. Pressing it again asks the same.
    pub fn land_all_on_ctrl_c(&self, who: &'static str) {
        let commander = self.commander();
        if let Err(e) = ctrlc::set_handler(move || {
            eprintln!("{who}: Ctrl-C: landing every drone");
            let _ = commander.send(Operator::LandAll);
        }) {
            tracing::warn!("Ctrl-C will not land the drones: {e}");
        }
    }

    /// The latest snapshot, at once.
    pub fn snapshot(&self) -> Arc<Snapshot> {
        self.snapshot
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// A handle to read snapshots from other threads.
    pub fn snapshots(&self) -> Arc<Mutex<Arc<Snapshot>>> {
        self.snapshot.clone()
    }

    /// Whether the mission loop has ended.
    pub fn finished(&self) -> bool {
        self.done.load(Ordering::Relaxed)
    }

    /// Waits for the mission loop to end and takes its report.
    pub fn join(mut self) -> Option<MissionReport> {
        self.thread.take()?.join().ok()
    }
}

impl Drop for Runtime {
    fn drop(&mut self) {
        if let Some(t) = self.thread.take() {
            let _ = self.commands.send(Operator::Shutdown);
            let _ = t.join();
        }
    }
}

struct Mission {
    config: RuntimeConfig,
    drones: Vec<Drone>,
    perception: Option<Perception>,
    sensors: Arc<SensorLog>,
    clock: Arc<dyn Clock>,
    commands: Receiver<Operator>,
    snapshot: Arc<Mutex<Arc<Snapshot>>>,
    state: MissionState,
    started: Option<f64>,
    /// Goals given up (each gets a second look before the mission completes).
    blacklist: Blacklist,
    /// Goals given up that hid frontiers at the last plan (see [`MissionReport`]).
    given_up_left: usize,
    /// Goals given up that hid frontiers at the end, never looked at (see [`MissionReport`]).
    never_seen: usize,
    /// Since when no reachable frontier has been left while some are out of reach, the end
    /// waiting for the map to settle ([`RuntimeConfig::settle_before_end_s`]).
    settling_since: Option<f64>,
    grid: Option<Arc<Grid>>,
    frontiers: Vec<[f64; 2]>,
    messages: Vec<(f64, String)>,
    /// Decimated trajectories for displays.
    trajectories: Vec<Trail>,
    recorder: Option<Recorder>,
    last_plan_record: f64,
    /// Maps and plans, on their own thread.
    planner: Planner,
    /// The planner's thread stopped (and every drone was told to land).
    planner_lost: bool,
    /// Plans that give no drone a goal while something is left.
    stall: Stall,
    /// The drones taking off beside one another (indices) and what their shared first look
    /// around has seen so far.
    first_looks: Vec<(Vec<usize>, nav::sweep::SharedLook)>,
}

impl Mission {
    fn run(&mut self) -> MissionReport {
        self.trajectories = vec![Trail::default(); self.drones.len()];
        let mut next_control = self.clock.now();
        let mut cadence = Cadence::new(self.config.plan_period, next_control + 2.0);
        // When the operator (or the process) asked to end: the runtime waits for the drones to
        // come down, but not for ever (a vehicle that never reports landing must not hang it).
        let mut shutdown: Option<f64> = None;
        if self.config.auto_start {
            self.operate(Operator::Start);
        }
        loop {
            let now = self.clock.now();
            for command in self.commands.try_iter().collect::<Vec<_>>() {
                if command == Operator::Shutdown {
                    shutdown.get_or_insert(now);
                }
                self.operate(command);
            }
            if let Some(p) = &self.perception {
                for fix in p.take_fixes() {
                    let Some(d) = self.drones.get_mut(fix.drone) else {
                        continue;
                    };
                    d.take_fix(now, &fix, &self.config.drone);
                }
            }
            if now >= next_control {
                next_control = (next_control + self.config.control_period).max(now - 1.0);
                self.control(now);
                self.publish(now);
            }
            let waiting =
                self.config.plan_when_looked && self.drones.iter().any(Drone::awaits_plan);
            if cadence.due(now, waiting) {
                self.ask_plan(now);
                self.plan_home();
            }
            self.take_plan(now);
            self.check_end(now);
            if let MissionState::Done(_) = self.state
                && (self.config.exit_when_done || shutdown.is_some())
            {
                break;
            }
            if let Some(asked) = shutdown {
                let down = self
                    .drones
                    .iter()
                    .all(|d| !d.phase.flying() && d.phase != Phase::Landing);
                if down || now - asked > self.config.shutdown_wait_s {
                    if !down {
                        self.say(
                            now,
                            format!(
                                "ending {:.0} s after shutdown with drones not down",
                                self.config.shutdown_wait_s
                            ),
                        );
                    }
                    break;
                }
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        self.publish(self.clock.now());
        let end = self.clock.now();
        let outcome = match self.state {
            MissionState::Done(o) | MissionState::Finishing(o) => Some(o),
            _ => None,
        };
        for d in &self.drones {
            if d.phase != Phase::LinkLost {
                d.link.set_sticks(None);
            }
        }
        let perception = self.perception.take().and_then(Perception::finish);
        if let (Some(r), Some(p)) = (&self.recorder, &perception) {
            // The final map, after the last optimisation: the 2D grid and the 3D voxels.
            let (grid, points) = p.slam.map().with(|v| (v.project(), v.occupied()));
            if let Some(grid) = grid {
                r.send(Record::Grid {
                    t: end,
                    grid: Arc::new(grid),
                });
            }
            r.send(Record::Cloud { t: end, points });
        }
        if let Some(r) = &mut self.recorder {
            // Close the log with the mission; the recorder's owner reads (and reports) the
            // result from its own `finish`.
            let _ = r.finish();
        }
        MissionReport {
            outcome,
            mission_time_s: self.started.map_or(0.0, |s| end - s),
            frontiers_out_of_reach: self.frontiers.len(),
            goals_given_up: self.given_up_left,
            goals_never_seen: self.never_seen,
            drones: self
                .drones
                .iter()
                .map(|d| DroneReport {
                    name: d.name.clone(),
                    phase: d.phase,
                    left_mission: d.left_mission.clone(),
                    path_length_m: d.path_length,
                    battery_swaps: d.battery_swaps,
                    trajectory: d.trajectory.clone(),
                })
                .collect(),
            perception,
        }
    }

    fn say(&mut self, now: f64, text: String) {
        tracing::info!("{text}");
        self.record_text(now, false, &text);
        self.note(now, text);
    }

    /// Writes what the station tells the operator into the mission's log.
    fn record_text(&self, now: f64, warning: bool, text: &str) {
        if let Some(r) = &self.recorder {
            r.send(Record::StationText {
                t: now,
                warning,
                text: text.to_owned(),
            });
        }
    }

    /// Keeps a message for the operator (the last 50), already logged.
    fn note(&mut self, now: f64, text: String) {
        self.messages.push((now, text));
        if self.messages.len() > 50 {
            self.messages.remove(0);
        }
    }

    fn operate(&mut self, command: Operator) {
        let now = self.clock.now();
        if let Some(r) = &self.recorder {
            r.send(Record::Operator {
                t: now,
                command: format!("{command:?}"),
            });
        }
        match command {
            Operator::Start => {
                if matches!(self.state, MissionState::Waiting | MissionState::Done(_)) {
                    self.say(now, "mission started".into());
                    self.state = MissionState::Exploring;
                    self.started = Some(now);
                    self.blacklist.clear();
                    for d in &mut self.drones {
                        d.take_off();
                    }
                }
            }
            Operator::Pause => {
                if self.state == MissionState::Exploring {
                    self.state = MissionState::Paused;
                    for d in &mut self.drones {
                        if d.phase == Phase::Exploring {
                            let (h, y) = (d.altitude, d.pose().map_or(d.yaw_goal, |p| p[3]));
                            d.hold(h, y);
                        }
                    }
                    self.say(now, "mission paused: every drone holds".into());
                }
            }
            Operator::Resume => {
                if self.state == MissionState::Paused {
                    self.state = MissionState::Exploring;
                    for d in &mut self.drones {
                        d.resume();
                    }
                    self.say(now, "mission resumed".into());
                }
            }
            Operator::LandAll | Operator::Shutdown => {
                for d in &mut self.drones {
                    d.land();
                }
                if !matches!(self.state, MissionState::Done(_)) {
                    self.state = MissionState::Finishing(Outcome::LandAll);
                }
                self.say(now, "land all".into());
            }
            Operator::Drone(k, c) => {
                let Some(d) = self.drones.get_mut(k) else {
                    return;
                };
                match c {
                    DroneCommand::TakeOff => {
                        d.take_off();
                        if matches!(self.state, MissionState::Waiting | MissionState::Done(_)) {
                            self.state = MissionState::Exploring;
                            self.started.get_or_insert(now);
                        }
                    }
                    DroneCommand::Land => {
                        if d.phase.flying() {
                            d.leave_mission(OPERATOR);
                        }
                        d.land();
                    }
                    DroneCommand::Disarm => {
                        if matches!(d.phase, Phase::Idle | Phase::Landed) {
                            d.disarm();
                        }
                    }
                    DroneCommand::Hold { height, yaw } => d.hold(height.clamp(0.3, 2.4), yaw),
                    DroneCommand::Explore => d.resume(),
                    DroneCommand::ReturnHome => d.return_home(OPERATOR),
                }
            }
        }
    }

    fn control(&mut self, now: f64) {
        self.share_first_looks();
        for k in 0..self.drones.len() {
            if self.state == MissionState::Exploring
                && self.drones[k].rejoin_after_swap(now, &self.config.drone)
            {
                tracing::info!(
                    drone = k + 1,
                    "rejoins the exploration on a charged battery"
                );
            }
            let event = self.drones[k].tick(now, &self.config.drone);
            let d = &self.drones[k];
            let t = d.link.telemetry();
            let (pose, pose_sigma_m, tilt) = (d.pose(), d.pose_sigma_m(), Some(d.tilt()));
            self.sensors.push(
                k,
                SensorSample {
                    t: now,
                    heading: t.yaw_rad.map(f64::from),
                    heading_t: t.heading_time(now),
                    height: t.height_m.map(f64::from),
                    tilt,
                    body: pose,
                    body_sigma_m: pose_sigma_m,
                },
            );
            if let Some(r) = &self.recorder {
                r.send(Record::Drone {
                    t: now,
                    drone: k,
                    telemetry: t,
                    sticks: d.sticks,
                    pose,
                    pose_sigma_m,
                    tilt,
                    nearest_wall_m: d.nearest_wall(now, &self.config.drone),
                    setpoint: d.flown_setpoint(),
                    phase: d.phase.name(),
                });
            }
            match event {
                Some(DroneEvent::GiveUp(goal)) => {
                    tracing::info!(
                        drone = k + 1,
                        ?goal,
                        "frontier goal closed: reached or unreachable"
                    );
                    self.blacklist.give_up(goal);
                }
                Some(DroneEvent::LookCut(goal, turn)) => {
                    tracing::info!(
                        drone = k + 1,
                        ?goal,
                        "frontier goal set aside: its look around lost the map"
                    );
                    self.blacklist.look_cut(goal, turn);
                }
                None => {}
            }
            let messages = self.drones[k].take_messages();
            let name = self.drones[k].name.clone();
            for m in messages {
                self.say(now, format!("{name}: {m}"));
            }
            // What the vehicle itself says (ArduPilot's "PreArm: …", a failsafe, a collision in
            // the simulator), as QGroundControl and MAVProxy show it.
            for text in self.drones[k].link.take_status_texts() {
                let line = format!("{name} (vehicle): {}", text.text);
                if text.is_warning() {
                    tracing::warn!("{line}");
                } else {
                    tracing::info!("{line}");
                }
                if let Some(r) = &self.recorder {
                    r.send(Record::VehicleText {
                        t: now,
                        drone: k,
                        text,
                    });
                }
                self.note(now, line);
            }
        }
        if let Some(started) = self.started
            && let Some(limit) = self.config.timeout
            && now - started > limit
            && matches!(self.state, MissionState::Exploring | MissionState::Paused)
        {
            self.say(now, format!("timeout after {limit:.0} s: landing"));
            self.finish(Outcome::TimedOut);
        }
    }

    /// Adds what the cameras of drones sharing a first look around face now to what they have
    /// seen, and ends their parts once every side has been seen (a drone still taking off then
    /// turns only the shortest look).
    fn share_first_looks(&mut self) {
        for (members, look) in &mut self.first_looks {
            for &k in members.iter() {
                if let Some((heading, view)) = self.drones[k].shared_look_view(&self.config.drone) {
                    look.see(heading, &view);
                }
            }
            if look.complete() {
                for &k in members.iter() {
                    self.drones[k].shared_look_seen();
                }
            }
        }
    }

    fn finish(&mut self, outcome: Outcome) {
        self.state = MissionState::Finishing(outcome);
        for d in &mut self.drones {
            d.land();
        }
    }

    fn check_end(&mut self, now: f64) {
        let all_down = self
            .drones
            .iter()
            .all(|d| matches!(d.phase, Phase::Landed | Phase::LinkLost | Phase::Idle));
        match self.state {
            MissionState::Finishing(o) if all_down => {
                self.say(
                    now,
                    format!("mission over ({}): every drone is down", o.name()),
                );
                self.state = MissionState::Done(o);
            }
            MissionState::Exploring | MissionState::Paused
                if all_down
                    && !self.drones.iter().any(|d| d.awaits_battery)
                    && self
                        .drones
                        .iter()
                        .any(|d| matches!(d.phase, Phase::Landed | Phase::LinkLost)) =>
            {
                let why: Vec<String> = self
                    .drones
                    .iter()
                    .map(|d| match &d.left_mission {
                        Some(why) => format!("{}: {why}", d.name),
                        None => format!("{}: {}", d.name, d.phase.name()),
                    })
                    .collect();
                self.say(now, format!("no drone left flying ({})", why.join("; ")));
                self.state = MissionState::Done(Outcome::NoDroneLeft);
            }
            _ => {}
        }
    }

    /// Asks the planner for a step: the map, and while exploring a plan for the exploring
    /// drones. Taken by [`Mission::take_plan`] when it comes; a step still being worked on is
    /// not asked again.
    fn ask_plan(&mut self, now: f64) {
        let exploring: Vec<usize> = if matches!(self.state, MissionState::Exploring) {
            (0..self.drones.len())
                .filter(|&k| self.drones[k].phase == Phase::Exploring)
                .collect()
        } else {
            vec![]
        };
        let robots: Vec<Option<[f64; 2]>> = exploring
            .iter()
            .map(|&k| self.drones[k].plan_position(&self.config.drone))
            .collect();
        // The goals they fly to now, which each keeps unless another is cheaper by the margin.
        let held: Vec<Option<[f64; 2]>> = exploring.iter().map(|&k| self.drones[k].goal).collect();
        // The ways they face, which a path setting off behind costs a turn.
        let headings: Vec<Option<f64>> = exploring
            .iter()
            .map(|&k| self.drones[k].plan_heading(&self.config.drone))
            .collect();
        let radii = &self.config.planner_radii;
        let configs: Vec<PlannerConfig> = radii
            .iter()
            .map(|&robot_radius_m| PlannerConfig {
                comfort_m: centring_comfort(self.config.centre_paths, radii, robot_radius_m),
                unknown_comfort_m: self.config.unknown_comfort_m,
                strategy: self.config.strategy,
                robot_radius_m,
                blacklist: self.blacklist.ignored(),
                region_radius_m: self.config.region_radius_m,
                held: held.clone(),
                hold_margin_m: self.config.hold_margin_m,
                max_pocket_m2: self.config.max_pocket_m2,
                headings: headings.clone(),
                turn_m_per_rad: self.config.turn_m_per_rad,
                stage_back_m: self.config.stage_back_m,
                // The bend its path follower turns on the spot for; a smaller one it flies.
                turn_on_spot_rad: self.config.drone.follower.turn_threshold_rad,
                ..PlannerConfig::default()
            })
            .collect();
        let elapsed = self.started.map_or(0.0, |s| now - s);
        let airborne = self.drones.iter().all(|d| d.phase != Phase::TakingOff);
        let homes = exploring
            .iter()
            .map(|&k| self.drones[k].start.map(|[x, y, _]| [x, y]))
            .collect();
        let ask = Ask {
            t: now,
            drones: exploring,
            robots,
            configs,
            may_end: airborne && elapsed > self.config.min_mission_s,
            homes,
        };
        if self.planner.ask(ask).is_err() {
            self.planner_stopped(now);
        }
    }

    /// The planner's answer, if it has come: the new map to every drone, and the plan's goals
    /// to the drones still exploring.
    fn take_plan(&mut self, now: f64) {
        let answer = match self.planner.answer() {
            Ok(Some(answer)) => answer,
            Ok(None) => return,
            Err(PlannerStopped) => return self.planner_stopped(now),
        };
        tracing::debug!(
            projection_ms = answer.seconds[0] * 1e3,
            planning_ms = answer.seconds[1] * 1e3,
            drones = answer.ask.drones.len(),
            "planner step"
        );
        if let Some(grid) = &answer.grid {
            self.grid = Some(grid.clone());
            for d in &mut self.drones {
                d.set_map(grid.clone());
            }
        }
        let (Some(grid), Some(plan)) = (answer.grid, answer.plan) else {
            return;
        };
        let plan = match plan {
            Ok(plan) => plan,
            Err(e) => {
                tracing::warn!("planner: {e}");
                return;
            }
        };
        if !matches!(self.state, MissionState::Exploring) {
            return; // ended while it planned
        }
        let Ask {
            t: asked,
            drones: exploring,
            configs,
            ..
        } = answer.ask;
        // What it planned with, recorded as such (a goal may have been given up since).
        let (held, headings, given_up) = configs
            .first()
            .map(|c| (c.held.clone(), c.headings.clone(), c.blacklist.clone()))
            .unwrap_or_default();
        self.frontiers = plan
            .frontiers
            .iter()
            .map(|f| plan.inflated.center_of(f.goal))
            .collect();
        self.given_up_left = self.blacklist.hiding(&plan.ignored).len();
        for (i, &k) in exploring.iter().enumerate() {
            let way_home = answer.ways_home.get(i).copied().flatten();
            tracing::trace!(drone = k + 1, ?way_home, "its way home");
            self.drones[k].set_way_home(way_home);
            let r = &plan.robots[i];
            let look_turn = r.goal.and_then(|g| self.blacklist.look_turn(g));
            self.drones[k].set_plan(r.goal, r.path.clone(), look_turn, now);
        }
        if let Some(r) = &self.recorder
            && asked - self.last_plan_record >= 1.0
        {
            // At the time it was asked: the positions and the map are that time's.
            r.send(Record::Plan {
                t: asked,
                goals: exploring
                    .iter()
                    .enumerate()
                    .map(|(i, &k)| PlannedGoal {
                        drone: k,
                        position: answer.robots[i],
                        held: held.get(i).copied().flatten(),
                        heading: headings.get(i).copied().flatten(),
                        goal: plan.robots[i].goal,
                        path: plan.robots[i].path.clone(),
                    })
                    .collect(),
                frontiers: self.frontiers.clone(),
                given_up,
            });
            r.send(Record::Grid {
                t: asked,
                grid: grid.clone(),
            });
            self.last_plan_record = asked;
        }
        let going = plan.robots.iter().any(|r| r.goal.is_some());
        if self.stall.observe(now, !plan.complete, going) >= STALL_S {
            let why: Vec<String> = exploring
                .iter()
                .zip(&plan.robots)
                .map(|(&k, r)| {
                    let reason = r.hover_reason.unwrap_or("no goal");
                    format!("{}: {reason}", self.drones[k].name)
                })
                .collect();
            self.say(
                now,
                format!(
                    "stalled: no drone has had a goal for {STALL_S:.0} s, yet the planner counts a frontier as reachable ({}): landing",
                    why.join("; ")
                ),
            );
            self.finish(Outcome::Stalled);
            return;
        }
        if answer.ending && plan.complete {
            let elapsed = self.started.map_or(0.0, |s| now - s);
            // Goals given up once may have failed by chance: one more look before the end.
            let released = self.blacklist.second_look(&plan.ignored);
            if released > 0 {
                self.say(
                    now,
                    format!("no other frontier left: a second look at {released} given up once"),
                );
                return;
            }
            if !self.frontiers.is_empty() {
                let wait = self.config.settle_before_end_s;
                match self.settling_since {
                    None if wait > 0.0 => {
                        self.settling_since = Some(now);
                        self.say(
                            now,
                            format!(
                                "no reachable frontier left after {elapsed:.0} s, {} out of reach: hovering {wait:.0} s for the map to settle before landing",
                                self.frontiers.len()
                            ),
                        );
                        return;
                    }
                    Some(since) if now - since < wait => return,
                    _ => {}
                }
            }
            self.say(
                now,
                format!(
                    "no reachable frontier left after {elapsed:.0} s ({} out of reach, {} hidden behind goals given up): landing",
                    self.frontiers.len(),
                    self.given_up_left
                ),
            );
            let unseen = self.blacklist.never_seen(&plan.ignored);
            if !unseen.is_empty() {
                let at: Vec<String> = unseen
                    .iter()
                    .map(|g| format!("({:.1}, {:.1})", g[0], g[1]))
                    .collect();
                tracing::warn!(goals = ?unseen, "frontier goals never looked at");
                self.say(
                    now,
                    format!(
                        "the map may end short at {}: every look around there lost the map",
                        at.join(", ")
                    ),
                );
            }
            self.never_seen = unseen.len();
            self.finish(Outcome::Completed);
        } else if !plan.complete
            && let Some(since) = self.settling_since.take()
        {
            self.say(
                now,
                format!(
                    "the map settled: a frontier is within reach again after {:.1} s",
                    now - since
                ),
            );
        }
    }

    /// The planner's thread is gone (a fault): nothing can be planned, so every drone lands.
    fn planner_stopped(&mut self, now: f64) {
        if self.planner_lost {
            return;
        }
        self.planner_lost = true;
        tracing::error!("the mission planner stopped (a fault in it): landing every drone");
        let text = "the mission planner stopped: landing every drone";
        self.record_text(now, true, text);
        self.note(now, text.into());
        self.operate(Operator::LandAll);
    }

    /// Paths home for returning drones.
    fn plan_home(&mut self) {
        let Some(grid) = self.grid.clone() else {
            return;
        };
        let radii = &self.config.planner_radii;
        let radius = radii.last().copied().unwrap_or(0.25);
        let comfort = Comfort {
            blocked_m: centring_comfort(self.config.centre_paths, radii, radius),
            unknown_m: self.config.unknown_comfort_m,
        };
        for d in &mut self.drones {
            if d.phase != Phase::Returning {
                continue;
            }
            let (Some(p), Some(home)) = (d.pose(), d.goal) else {
                continue;
            };
            match nav::mission::route(&grid, [p[0], p[1]], home, radius, comfort) {
                Some(path) => d.set_home_path(path),
                None => {
                    // No known way home: land where it is.
                    d.land();
                }
            }
        }
    }

    fn publish(&mut self, now: f64) {
        let view = self
            .perception
            .as_ref()
            .map(Perception::view)
            .unwrap_or_default();
        for (k, d) in self.drones.iter().enumerate() {
            if let Some(p) = d.pose() {
                let last = self.trajectories[k].last();
                if last.is_none_or(|l| (l[0] - p[0]).hypot(l[1] - p[1]) > 0.05) {
                    self.trajectories[k].push([p[0], p[1]]);
                }
            }
        }
        let drones = self
            .drones
            .iter()
            .enumerate()
            .map(|(k, d)| DroneView {
                id: k,
                name: d.name.clone(),
                phase: d.phase,
                left_mission: d.why_away(),
                link: d.link.status(),
                telemetry: d.link.telemetry(),
                battery_home_at: d.battery_home_at(),
                battery_estimate_pct: d.battery_estimate_pct(),
                pose: d.pose(),
                pose_sigma: d.ekf.estimate().position_sigma,
                slam: view.robots.get(k).map_or(RobotState::Waiting, |r| r.state),
                goal: d.goal,
                path: d.path().to_vec(),
                trajectory: self.trajectories[k].clone(),
                setpoint: d.setpoint(),
                inliers: d.inliers,
                height_goal: d.height_goal,
                yaw_goal: d.yaw_goal,
                sticks: d.sticks,
            })
            .collect();
        let s = Snapshot {
            time: now,
            elapsed: self.started.map_or(0.0, |s| now - s),
            state: self.state,
            drones,
            grid: self.grid.clone(),
            frontiers: self.frontiers.clone(),
            slam: view,
            messages: self.messages.clone(),
        };
        *self.snapshot.lock().unwrap_or_else(PoisonError::into_inner) = Arc::new(s);
    }
}
