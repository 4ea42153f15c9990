//! `gcs explore`: cooperative exploration of a simulated building, end to end — the main job.
//!
//! The simulator runs in-process with every vehicle on its own loopback socket, reached through
//! the real link adapters (MAVLink or the shield protocol) exactly as hardware would be. The
//! mission runtime explores until no reachable frontier is left and lands every drone; the map,
//! the trajectories, the MCAP log (and `.tlog`s of MAVLink traffic) and a summary are written.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use nav::grid::Grid;
use nav::local::FollowerConfig;
use nav::mission::{PlannerConfig, Strategy};
use sitl::World;
use slam::eval::{Alignment, ate, loop_closure_errors};
use slam::system::{Slam, SlamConfig};
use slam::trajectory::Stamped;

use gcs::evaluate::{WallError, coverage, reachable_free, wall_error};
use gcs::fleet::{
    BAND_STEP_M, LOWEST_BAND_M, LinkKind, SimFleet, SimFleetConfig, altitude_band, band_limits,
    sim_body_from_camera,
};
use gcs::gui::Station;
use gcs::outputs;
use gcs::record::{Record, Recorder, Setup, SetupDrone};
use gcs::runtime::drone::{BatterySwap, DroneConfig};
use gcs::runtime::{MissionState, Operator, Outcome, Runtime, RuntimeConfig};

use crate::gui_cmd::{LogArgs, Window, WindowArgs, beside_window};

/// `--altitude`'s help, from the constants it names (so it cannot go stale).
fn altitude_help() -> String {
    let (low, high) = band_limits();
    format!(
        "Drone 1's altitude band, metres; each further drone flies {BAND_STEP_M} m higher, so \
         paths may cross. Every band must lie within the heights the map's walls are taken \
         from ({low:.2}–{high:.1} m)"
    )
}

/// The simulated fleet, as `gcs explore` and `gcs gui` take it.
#[derive(Args, Debug, Clone)]
pub struct SimArgs {
    /// A built-in world (apartment) or a world file (.txt, map_server .yaml, HouseExpo .json).
    #[arg(long, default_value = sitl::world::DEFAULT_WORLD)]
    pub world: String,
    /// Number of drones (1–8).
    #[arg(long, default_value_t = 2)]
    pub drones: usize,
    /// Drone 1's altitude band, metres; each further drone flies higher (the help text gives
    /// the step and the heights every band must lie within: [`altitude_help`]).
    #[arg(long, value_name = "METRES", default_value_t = LOWEST_BAND_M, help = altitude_help())]
    pub altitude: f64,
    /// How the station talks to the drones.
    #[arg(long, value_enum, default_value_t = LinkKind::Mavlink)]
    pub link: LinkKind,
    /// How frontiers are assigned.
    #[arg(long, value_enum, default_value_t = StrategyArg::Hungarian)]
    pub strategy: StrategyArg,
    /// Simulated seconds per real second (0.1–20).
    #[arg(long, default_value_t = 3.0)]
    pub speed: f64,
    /// Seed of the simulator's noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where the drones' poses come from: the multi-robot SLAM on their cameras (`slam`), or the
    /// simulator's ground truth (`truth`, to measure navigation alone).
    #[arg(long, value_enum, default_value_t = PoseSource::Slam)]
    pub poses: PoseSource,
    /// Each drone's flight time on one battery at hover, minutes (a drone turns home when what
    /// is left, less a 15 % reserve, would only just bring it back from where it is).
    #[arg(long, value_name = "MINUTES", default_value_t = 12.0)]
    pub flight_time: f64,
    /// Swap batteries: a drone home for a low battery gets a charged one this many simulated
    /// seconds after it lands (a simulated operator), then takes off again and rejoins the
    /// exploration. Default: it stays down.
    #[arg(long, value_name = "SECONDS")]
    pub battery_swap: Option<f64>,
    /// Frontiers within this distance of each other, in sight, are one region, and drones are
    /// spread one to a region before any region gets a second, metres; 0: off (each frontier a
    /// region of its own).
    #[arg(long, value_name = "METRES", default_value_t = PlannerConfig::default().region_radius_m)]
    pub region_radius: f64,
    /// A drone keeps the frontier it flies to unless another is cheaper by more than this,
    /// metres of path; 0: every plan assigns afresh (two drones whose costs nearly tie may then
    /// swap their goals at every plan).
    #[arg(long, value_name = "METRES", default_value_t = PlannerConfig::default().hold_margin_m)]
    pub hold_margin: f64,
    /// A frontier whose unknown side is an enclosed pocket, walled at least as much as open, of at most
    /// this area is not explored (the inside of a pillar seen from all sides but one), m²; 0:
    /// every frontier is.
    #[arg(long, value_name = "M2", default_value_t = PlannerConfig::default().max_pocket_m2)]
    pub max_pocket: f64,
    /// What turning on the spot to face a path costs a drone when frontiers are assigned, metres
    /// of path per radian: a frontier whose path sets off more than 90° from the way the drone
    /// faces costs it the turn as well; 0: paths alone are weighed.
    #[arg(long, value_name = "M_PER_RAD", default_value_t = PlannerConfig::default().turn_m_per_rad)]
    pub turn_cost: f64,
    /// A drone left without a frontier of its own (more drones than frontiers) flies toward
    /// the nearest frontier another drone has and waits this far short of it, metres of path
    /// (1 m more for each drone ahead of it there), to be near what that drone's look around
    /// opens; 0: it hovers where it is.
    #[arg(long, value_name = "METRES", default_value_t = PlannerConfig::default().stage_back_m)]
    pub stage_back: f64,
    /// Paths planned at a thinner radius than the widest (a door too narrow on the map for the
    /// wider ones) keep the widest one's distance from the walls where they can: through the
    /// middle of a door, not along its jamb; `false`: shortest paths.
    #[arg(long, value_name = "BOOL", default_value_t = RuntimeConfig::default().centre_paths, action = clap::ArgAction::Set)]
    pub centre_paths: bool,
    /// Paths keep this far from the unknown where they can, metres: a wall the cameras have
    /// not seen yet may begin at its edge, and only walls on the map are grown by the planner's
    /// radius; 0: paths at the widest radius keep nothing from it.
    #[arg(long, value_name = "METRES", default_value_t = RuntimeConfig::default().unknown_comfort_m)]
    pub unknown_comfort: f64,
    /// A drone that ends its look around with nowhere to go is planned for as soon as the map
    /// holds what the look saw, not at the planner's next once-a-second step
    /// (`RuntimeConfig::plan_when_looked`).
    #[arg(long, value_name = "BOOL", default_value_t = RuntimeConfig::default().plan_when_looked, action = clap::ArgAction::Set)]
    pub plan_when_looked: bool,
    /// The speed the path follower allows a drone anywhere, m/s (less into a sharp bend of its
    /// path). Held by the speed loop; with `--speed-loop false`, drones cruise up to 0.15 m/s
    /// over it.
    #[arg(long, value_name = "M_PER_S", default_value_t = DroneConfig::default().follower.max_speed_mps)]
    pub max_speed: f64,
    /// Flying, a drone's camera faces its path this far ahead, round the path's bends, metres
    /// (0: it faces the point it flies to, 0.4 m ahead).
    #[arg(long, value_name = "M", default_value_t = DroneConfig::default().follower.view_m)]
    pub view_ahead: f64,
    /// Pursuing its path, a drone flies a velocity (the speed allowed, toward the point it
    /// flies to, no faster toward a wall than it can stop short of it) instead of a position,
    /// so `--max-speed` holds (`DroneConfig::speed_gain`); `false`: the position loop, as
    /// before stop 87 (with `--max-speed 0.7`).
    #[arg(long, value_name = "BOOL", default_value_t = DroneConfig::default().speed_gain > 0.0, action = clap::ArgAction::Set)]
    pub speed_loop: bool,
    /// How a drone looks around at a goal: turning the short way to what the map shows
    /// unknown, no further (`sweep`); the same, but first the way that shows the most unknown
    /// soonest (`most-unknown-first`); or a whole turn every time (`whole`, as the thesis).
    #[arg(long, value_enum, default_value_t = LookAround::Sweep)]
    pub look_around: LookAround,
}

/// How a drone looks around at a goal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LookAround {
    /// Turn the short way to what the map shows unknown, and no further.
    Sweep,
    /// As `sweep`, but turn first the way that shows the most unknown soonest (a room through
    /// a door before a jamb's shadow), so drones waiting for a frontier get one sooner.
    MostUnknownFirst,
    /// A whole turn every time.
    Whole,
}

/// Arguments of `gcs explore`.
#[derive(Args, Debug, Clone)]
pub struct ExploreArgs {
    /// The simulated fleet.
    #[command(flatten)]
    pub sim: SimArgs,
    /// Give up (and land) after this many simulated seconds.
    #[arg(long, default_value_t = 900.0)]
    pub timeout: f64,
    /// Where to write the map, trajectories, log and summary.
    #[arg(long, default_value = "explore-out")]
    pub out: PathBuf,
    /// Print the summary as JSON on stdout (progress still goes to stderr).
    #[arg(long)]
    pub json: bool,
    /// The mission log.
    #[command(flatten)]
    pub log: LogArgs,
    /// Kill drone K's link (1-based) at simulated time T seconds: `K@T` (a fault for tests and
    /// demonstrations; the others must finish the map). The same as `--fault link:K@T`.
    #[arg(long, value_name = "K@T")]
    pub kill_link: Option<String>,
    /// Inject a fault into drone K (1-based) at mission time T seconds: `KIND:K@T`, KIND one of
    /// `link` (its radio dies), `camera` (its camera stops sending), `battery` (its battery
    /// drops to 20 %). Repeat for more. For tests and demonstrations.
    #[arg(long = "fault", value_name = "KIND:K@T")]
    pub faults: Vec<String>,
    /// Write every drone's true and flown pose, SLAM state and σ at 10 Hz to this CSV file
    /// (to see where and why a drone flew off its true pose).
    #[arg(long, value_name = "FILE.csv")]
    pub pose_trace: Option<PathBuf>,
    /// Show the run in the operator's window (the run goes on headless if it is closed).
    #[arg(long)]
    pub gui: bool,
    /// Scripted use of the window.
    #[command(flatten)]
    pub window: WindowArgs,
}

/// Where the runtime's poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PoseSource {
    /// The multi-robot SLAM on every drone's camera.
    Slam,
    /// The simulator's ground truth.
    Truth,
}

/// Assignment strategy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StrategyArg {
    /// Least total cost (Hungarian algorithm).
    Hungarian,
    /// Cheapest pair first.
    Greedy,
}

impl PoseSource {
    /// What the summary and the title call it.
    pub fn name(self) -> &'static str {
        match self {
            PoseSource::Slam => "SLAM",
            PoseSource::Truth => "ground truth",
        }
    }
}

impl StrategyArg {
    fn strategy(self) -> Strategy {
        match self {
            StrategyArg::Hungarian => Strategy::Hungarian,
            StrategyArg::Greedy => Strategy::Greedy,
        }
    }

    fn name(self) -> &'static str {
        match self {
            StrategyArg::Hungarian => "hungarian",
            StrategyArg::Greedy => "greedy",
        }
    }
}

/// The end of an exploration, as written to `summary.json`.
#[derive(Debug, serde::Serialize)]
pub struct Summary {
    /// No reachable frontier was left.
    pub completed: bool,
    /// How the mission ended.
    pub outcome: String,
    /// Simulated seconds from the start to the last drone down.
    pub exploration_time_s: f64,
    /// Frontiers left at the end that no drone could reach on the map.
    pub frontiers_out_of_reach: usize,
    /// Frontier goals given up that still hid a frontier when the mission ended.
    pub goals_given_up: usize,
    /// Of those, the ones still hiding a frontier at the end that no drone ever looked at
    /// (every look around there lost the map): the map may end short behind them.
    pub goals_never_seen: usize,
    /// Fraction of the free space reachable from the starts that the map knows as free.
    pub coverage: f64,
    /// How far the map's walls lie from the world's.
    pub wall_error: Option<WallError>,
    /// Wall collisions of all drones.
    pub collisions: u32,
    /// Every drone ended on the ground, disarmed (as the simulator saw it: a drone whose link
    /// was lost counts once its own failsafe has landed it).
    pub all_landed: bool,
    /// The world.
    pub world: String,
    /// The link protocol.
    pub link: &'static str,
    /// The assignment strategy.
    pub strategy: &'static str,
    /// Where poses came from.
    pub pose_source: &'static str,
    /// Loop closures in the final graph.
    pub loop_closures: usize,
    /// Loop closures switched off by the back end's consistency check.
    pub loop_closures_rejected: usize,
    /// Loop closures left in the final graph whose measurement is more than 0.2 m or 5° from
    /// the simulator's truth: look-alike places matched by mistake (`null` on ground truth).
    pub loop_closures_wrong: Option<usize>,
    /// Keyframes in the final graph.
    pub keyframes: usize,
    /// Per drone.
    pub drones: Vec<DroneSummary>,
}

/// One drone in the summary.
#[derive(Debug, serde::Serialize)]
pub struct DroneSummary {
    /// 1-based id.
    pub id: usize,
    /// Distance flown (ground truth), metres.
    pub path_length_m: f64,
    /// The SLAM's final camera trajectory against the simulator's (SE(3)-aligned), metres;
    /// `null` when flying on ground truth.
    pub ate_rmse_m: Option<f64>,
    /// The camera poses as estimated while flying (before later loop closures), metres.
    pub ate_online_rmse_m: Option<f64>,
    /// Horizontal error of the pose the drone flew on (the filter's) against the simulator,
    /// RMS over the flight, metres.
    pub flight_pose_error_m: Option<f64>,
    /// Camera frames the SLAM could not track.
    pub lost_frames: usize,
    /// Of those, frames whose motion visual odometry measured (the drone flew on it).
    pub odometry_frames: usize,
    /// Frames the SLAM placed on features without depth (walls beyond the depth camera's range
    /// or nearer than its minimum), by projecting the map's points.
    pub projection_frames: usize,
    /// Frames the SLAM registered on too few matches away from the motion so far or from the
    /// move the drone's filter predicted: given a pose the drone was not flown on.
    pub weak_frames: usize,
    /// Wall collisions.
    pub collisions: u32,
    /// Charged batteries it took off again on (`--battery-swap`).
    pub battery_swaps: u32,
    /// The charge left in its battery at the end, as the simulator knows it (whatever the
    /// vehicle reported: over the shield only a voltage), percent.
    pub battery_left_pct: u8,
    /// The phase it ended in.
    pub final_phase: &'static str,
    /// Why it left the mission before the end (its battery, its camera, its link, the SLAM,
    /// its vehicle's failsafe, the operator); `null` for a drone that flew until it ended.
    pub left_mission: Option<String>,
    /// RC override frames its vehicle received (MAVLink vehicles; `null` over the shield).
    pub rc_frames: Option<u64>,
    /// The gap between override frames that 99 % of gaps did not exceed, at the vehicle,
    /// milliseconds of simulated time (10 ms resolution: the simulator's tick).
    pub rc_gap_p99_ms: Option<u64>,
    /// The longest gap between override frames at the vehicle, milliseconds (2000: 2 s or
    /// more; it includes the time on the ground before take-off and after landing, when the
    /// station sends none).
    pub rc_gap_max_ms: Option<u64>,
}

/// Checks the arguments and returns the faults to inject.
fn validate(args: &ExploreArgs) -> anyhow::Result<Vec<Fault>> {
    args.window.validate()?;
    if !(1..=8).contains(&args.sim.drones) {
        bail!("--drones {} must be 1 to 8", args.sim.drones);
    }
    // Every band within the heights the map's walls are taken from.
    let (low, high) = band_limits();
    if !(args.sim.altitude.is_finite() && args.sim.altitude >= low) {
        bail!(
            "--altitude {} must be {low:.2} metres or more: the map's walls are taken from \
             {low:.2} to {high:.1} m",
            args.sim.altitude
        );
    }
    let highest = altitude_band(args.sim.altitude, args.sim.drones - 1);
    if highest > high {
        bail!(
            "--altitude {} puts drone {} at {highest:.2} m, above the {high:.1} m the map's walls \
             are taken up to: lower it, or fly fewer drones",
            args.sim.altitude,
            args.sim.drones
        );
    }
    if !(args.sim.speed.is_finite() && (0.1..=20.0).contains(&args.sim.speed)) {
        bail!(
            "--speed {} must be between 0.1 and 20 (simulated seconds per second)",
            args.sim.speed
        );
    }
    if !(args.sim.flight_time.is_finite() && (1.0..=600.0).contains(&args.sim.flight_time)) {
        bail!(
            "--flight-time {} must be between 1 and 600 minutes",
            args.sim.flight_time
        );
    }
    if let Some(swap) = args.sim.battery_swap
        && !(swap.is_finite() && (0.0..=3600.0).contains(&swap))
    {
        bail!("--battery-swap {swap} must be between 0 and 3600 seconds");
    }
    if !(args.sim.region_radius.is_finite() && (0.0..=50.0).contains(&args.sim.region_radius)) {
        bail!(
            "--region-radius {} must be between 0 (off) and 50 metres",
            args.sim.region_radius
        );
    }
    if !(args.sim.hold_margin.is_finite() && (0.0..=50.0).contains(&args.sim.hold_margin)) {
        bail!(
            "--hold-margin {} must be between 0 (off) and 50 metres",
            args.sim.hold_margin
        );
    }
    if !(args.sim.max_speed.is_finite() && (0.1..=10.0).contains(&args.sim.max_speed)) {
        bail!(
            "--max-speed {} must be between 0.1 and 10 m/s",
            args.sim.max_speed
        );
    }
    if !(args.sim.view_ahead.is_finite() && (0.0..=10.0).contains(&args.sim.view_ahead)) {
        bail!(
            "--view-ahead {} must be between 0 (off) and 10 metres",
            args.sim.view_ahead
        );
    }
    if !(args.sim.stage_back.is_finite() && (0.0..=50.0).contains(&args.sim.stage_back)) {
        bail!(
            "--stage-back {} must be between 0 (off) and 50 metres",
            args.sim.stage_back
        );
    }
    if !(args.sim.unknown_comfort.is_finite() && (0.0..=5.0).contains(&args.sim.unknown_comfort)) {
        bail!(
            "--unknown-comfort {} must be between 0 (off) and 5 metres",
            args.sim.unknown_comfort
        );
    }
    if !(args.sim.turn_cost.is_finite() && (0.0..=10.0).contains(&args.sim.turn_cost)) {
        bail!(
            "--turn-cost {} must be between 0 (off) and 10 metres per radian",
            args.sim.turn_cost
        );
    }
    if !(args.sim.max_pocket.is_finite() && (0.0..=100.0).contains(&args.sim.max_pocket)) {
        bail!(
            "--max-pocket {} must be between 0 (off) and 100 square metres",
            args.sim.max_pocket
        );
    }
    args.log.validate()?;
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        bail!(
            "--timeout {} must be a positive number of simulated seconds",
            args.timeout
        );
    }
    let drones = args.sim.drones;
    let drone_at = |spec: &str| {
        spec.split_once('@').and_then(|(k, t)| {
            let k: usize = k.trim().parse().ok()?;
            let t: f64 = t.trim().parse().ok()?;
            (k >= 1 && k <= drones && t.is_finite() && t >= 0.0).then_some((k - 1, t))
        })
    };
    let mut faults = vec![];
    if let Some(s) = &args.kill_link {
        let (drone, at) = drone_at(s).ok_or_else(|| {
            anyhow::anyhow!(
                "--kill-link {s:?}: expected K@T with K a drone 1 to {drones} and T simulated seconds, e.g. 2@60"
            )
        })?;
        faults.push(Fault {
            kind: FaultKind::Link,
            drone,
            at,
        });
    }
    for s in &args.faults {
        let parsed = s.split_once(':').and_then(|(kind, rest)| {
            let kind = match kind {
                "link" => FaultKind::Link,
                "camera" => FaultKind::Camera,
                "battery" => FaultKind::Battery,
                _ => return None,
            };
            let (drone, at) = drone_at(rest)?;
            Some(Fault { kind, drone, at })
        });
        faults.push(parsed.ok_or_else(|| {
            anyhow::anyhow!(
                "--fault {s:?}: expected KIND:K@T with KIND link, camera or battery, K a drone 1 to {drones} and T simulated seconds, e.g. camera:2@60"
            )
        })?);
    }
    Ok(faults)
}

/// A fault injected into the simulation (`--fault`, `--kill-link`).
#[derive(Debug, Clone, Copy)]
pub struct Fault {
    kind: FaultKind,
    drone: usize,
    at: f64,
}

/// What fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FaultKind {
    /// The radio link dies (the vehicle's failsafe must land it).
    Link,
    /// The camera stops sending.
    Camera,
    /// The battery drops to 20 %.
    Battery,
}

impl Fault {
    fn inject(&self, sitl: &sitl::Sitl, elapsed: f64) {
        let (k, name) = (self.drone, self.drone + 1);
        match self.kind {
            FaultKind::Link => {
                eprintln!("explore: killing drone {name}'s link at {elapsed:.0} s (--kill-link)");
                sitl.kill_endpoint(k);
            }
            FaultKind::Camera => {
                eprintln!("explore: killing drone {name}'s camera at {elapsed:.0} s (--fault)");
                sitl.kill_camera(k);
            }
            FaultKind::Battery => {
                eprintln!(
                    "explore: draining drone {name}'s battery to 20 % at {elapsed:.0} s (--fault)"
                );
                sitl.with_sim(|sim| sim.vehicle_mut(k).drain_battery(0.2));
            }
        }
    }
}

/// Runs `gcs explore`.
pub fn run(args: &ExploreArgs) -> anyhow::Result<()> {
    let window = args.gui.then(|| Window {
        wait_for_start: false,
        close_ends_session: false,
        options: args.window.options(),
    });
    run_with(args, window)
}

/// Runs the exploration, in a window if one is given (`gcs explore --gui`, `gcs gui`).
pub fn run_with(args: &ExploreArgs, window: Option<Window>) -> anyhow::Result<()> {
    let faults = validate(args)?;
    let waits = window.as_ref().is_some_and(|w| w.wait_for_start);
    let session = window.as_ref().is_some_and(|w| w.close_ends_session);
    let world = Arc::new(World::load(&args.sim.world)?);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let fleet = SimFleet::start(&SimFleetConfig {
        world: world.clone(),
        drones: args.sim.drones,
        link: args.sim.link,
        speed: args.sim.speed,
        seed: args.sim.seed,
        flight_time_s: args.sim.flight_time * 60.0,
        battery_swap_s: args.sim.battery_swap,
        tlog_dir: (!args.log.no_log).then(|| args.out.clone()),
        lowest_band_m: args.sim.altitude,
    })?;
    eprintln!(
        "explore: world '{}', {} drone(s) over {}, {} assignment, poses from {}, {}× real time",
        world.name(),
        args.sim.drones,
        args.sim.link.name(),
        args.sim.strategy.name(),
        args.sim.poses.name(),
        args.sim.speed
    );
    let recorder = if args.log.no_log {
        None
    } else {
        let r = Recorder::create(&args.out.join("mission.mcap"), args.log.log_camera_hz)?;
        let b = sim_body_from_camera();
        r.send(Record::Setup(Setup {
            version: 1,
            world: Some(world.name().into()),
            strategy: args.sim.strategy.name().into(),
            planner_radii: RuntimeConfig::default().planner_radii,
            region_radius_m: Some(args.sim.region_radius),
            hold_margin_m: Some(args.sim.hold_margin),
            max_pocket_m2: Some(args.sim.max_pocket),
            turn_m_per_rad: Some(args.sim.turn_cost),
            stage_back_m: Some(args.sim.stage_back),
            centre_paths: Some(args.sim.centre_paths),
            unknown_comfort_m: Some(args.sim.unknown_comfort),
            drones: fleet
                .drones
                .iter()
                .map(|d| SetupDrone::new(&d.name, d.start, &b, d.altitude))
                .collect(),
        }));
        Some(r)
    };
    let slam = Slam::new(
        SlamConfig {
            known_poses: args.sim.poses == PoseSource::Truth,
            ..SlamConfig::default()
        },
        fleet.setups.clone(),
    );
    let SimFleet {
        sitl,
        drones,
        frames,
        clock,
        ..
    } = fleet;
    let runtime = Runtime::start(
        RuntimeConfig {
            strategy: args.sim.strategy.strategy(),
            region_radius_m: args.sim.region_radius,
            hold_margin_m: args.sim.hold_margin,
            max_pocket_m2: args.sim.max_pocket,
            turn_m_per_rad: args.sim.turn_cost,
            stage_back_m: args.sim.stage_back,
            centre_paths: args.sim.centre_paths,
            unknown_comfort_m: args.sim.unknown_comfort,
            plan_when_looked: args.sim.plan_when_looked,
            timeout: Some(args.timeout),
            drone: DroneConfig {
                sweep: match args.sim.look_around {
                    LookAround::Sweep | LookAround::MostUnknownFirst => {
                        DroneConfig::default().sweep
                    }
                    LookAround::Whole => None,
                },
                look_most_unknown_first: args.sim.look_around == LookAround::MostUnknownFirst,
                battery_swap: args.sim.battery_swap.map(|_| BatterySwap::default()),
                follower: FollowerConfig {
                    max_speed_mps: args.sim.max_speed,
                    view_m: args.sim.view_ahead,
                    ..DroneConfig::default().follower
                },
                speed_gain: if args.sim.speed_loop {
                    DroneConfig::SPEED_LOOP_GAIN
                } else {
                    0.0
                },
                ..DroneConfig::default()
            },
            // In the window the operator starts the mission (again, after a landing), and the
            // runtime lasts until the window closes.
            auto_start: !waits,
            exit_when_done: !session,
            ..RuntimeConfig::default()
        },
        drones,
        slam,
        frames,
        clock.clone(),
        recorder,
    )?;
    runtime.land_all_on_ctrl_c("explore");
    let Some(window) = window else {
        return watch(args, &world, sitl, runtime, clock, &faults);
    };
    let station = Station::of(
        &runtime,
        Some(world.clone()),
        format!(
            "{} drone(s) in SITL '{}' over {}, poses from {}, {}× real time",
            args.sim.drones,
            world.name(),
            args.sim.link.name(),
            args.sim.poses.name(),
            args.sim.speed
        ),
    );
    let commander = runtime.commander();
    let (args, world) = (args.clone(), world.clone());
    beside_window(station, window, commander, move || {
        watch(&args, &world, sitl, runtime, clock, &faults)
    })
}

/// Watches a running exploration to its end (progress, ground truth, the fault if one was
/// asked for), then writes the outputs and prints the summary.
fn watch(
    args: &ExploreArgs,
    world: &World,
    sitl: sitl::Sitl,
    runtime: Runtime,
    clock: Arc<dyn gcs::clock::Clock>,
    faults: &[Fault],
) -> anyhow::Result<()> {
    let reachable = reachable_free(world, sitl::VehicleParams::default().radius);
    let wall = Instant::now();
    let t0 = clock.now();
    let mut truth_tracks: Vec<Vec<(f64, [f64; 4])>> = vec![vec![]; args.sim.drones];
    // Squared horizontal error of the flown pose, and samples, per drone.
    let mut flight_error = vec![(0.0f64, 0usize); args.sim.drones];
    let mut next_progress = t0;
    let mut next_truth = t0;
    let mut injected = vec![false; faults.len()];
    let mut trace = match &args.pose_trace {
        Some(path) => {
            let mut f = std::io::BufWriter::new(
                std::fs::File::create(path)
                    .with_context(|| format!("cannot create {}", path.display()))?,
            );
            writeln!(
                f,
                "time_s,drone,phase,slam,true_x,true_y,true_z,true_yaw,flown_x,flown_y,flown_z,flown_yaw,sigma_m,slam_t,slam_x,slam_y,setpoint_x,setpoint_y,roll,pitch,yaw_rate,inliers"
            )?;
            Some(f)
        }
        None => None,
    };
    while !runtime.finished() {
        let now = clock.now();
        let s = runtime.snapshot();
        // Mission time: from the operator's start (at once when headless).
        let elapsed = s.elapsed;
        if now >= next_truth {
            next_truth += 0.1;
            for (k, p) in truth(&sitl).into_iter().enumerate() {
                truth_tracks[k].push((now, p));
                if let (Some(f), Some(d)) = (trace.as_mut(), s.drones.get(k))
                    && let Err(e) = {
                        let flown = d.pose.map_or_else(
                            || ",,,".to_owned(),
                            |e| format!("{:.3},{:.3},{:.3},{:.4}", e[0], e[1], e[2], e[3]),
                        );
                        // The SLAM's latest body pose, at its frame's time.
                        let slam = s
                            .slam
                            .robots
                            .get(k)
                            .and_then(|r| Some((r.stamp, r.map_from_body()?)))
                            .map_or_else(
                                || ",,".to_owned(),
                                |(t, b)| {
                                    let v = b.translation.vector;
                                    format!("{t:.2},{:.3},{:.3}", v.x, v.y)
                                },
                            );
                        let sticks = d.sticks.map_or_else(
                            || ",,".to_owned(),
                            |c| format!("{:.3},{:.3},{:.3}", c.roll, c.pitch, c.yaw),
                        );
                        writeln!(
                            f,
                            "{now:.2},{},{},{},{:.3},{:.3},{:.3},{:.4},{flown},{:.3},{slam},{:.3},{:.3},{sticks},{}",
                            k + 1,
                            d.phase.name(),
                            d.slam.name(),
                            p[0],
                            p[1],
                            p[2],
                            p[3],
                            d.pose_sigma,
                            d.setpoint[0],
                            d.setpoint[1],
                            d.inliers.map_or_else(String::new, |n| n.to_string()),
                        )
                    }
                {
                    // A diagnostic: the mission goes on without it.
                    eprintln!("explore: pose trace stopped: {e}");
                    trace = None;
                }
                if let Some(e) = s
                    .drones
                    .get(k)
                    .and_then(|d| d.pose.filter(|_| d.phase.flying()))
                {
                    flight_error[k].0 += (e[0] - p[0]).powi(2) + (e[1] - p[1]).powi(2);
                    flight_error[k].1 += 1;
                }
            }
        }
        for (fault, done) in faults.iter().zip(&mut injected) {
            if !*done && s.state != MissionState::Waiting && elapsed >= fault.at {
                fault.inject(&sitl, elapsed);
                *done = true;
            }
        }
        if now >= next_progress && s.state != MissionState::Waiting {
            next_progress = now + 5.0;
            let cov = s
                .grid
                .as_ref()
                .map_or(0.0, |g| coverage(&reachable, world, g));
            let states: Vec<String> = s
                .drones
                .iter()
                .map(|d| format!("{}: {}", d.id + 1, d.phase.name()))
                .collect();
            eprintln!(
                "[{:6.1} s] coverage {:5.1} %  {}  {} keyframes, {} loops, SLAM {:.1} ms/frame  ({:.1}× real time)",
                elapsed,
                cov * 100.0,
                states.join(", "),
                s.slam.stats.keyframes,
                s.slam.stats.loop_closures,
                s.slam.ms_per_frame,
                (now - t0) / wall.elapsed().as_secs_f64().max(1e-3)
            );
        }
        if elapsed > args.timeout + 120.0 {
            eprintln!("explore: drones still flying 120 s after the timeout; giving up");
            runtime.send(Operator::Shutdown);
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if let Some(Err(e)) = trace.as_mut().map(Write::flush) {
        eprintln!("explore: pose trace incomplete: {e}");
    }
    let last_snapshot = runtime.snapshot();
    let report = runtime
        .join()
        .context("the mission loop stopped unexpectedly")?;
    // A drone whose link was lost is landed by its own failsafe: give it time to come down
    // (the summary's `all_landed` is what the simulator says, not what the station believes).
    let down_by = clock.now() + 60.0;
    while !all_down(&sitl) && clock.now() < down_by {
        std::thread::sleep(Duration::from_millis(20));
    }
    let rc = sitl.rc_stats();
    let (collisions, battery_left): (Vec<u32>, Vec<u8>) = sitl.with_sim(|sim| {
        (0..sim.len())
            .map(|k| {
                let v = sim.vehicle(k);
                (v.state().collisions, v.battery_remaining())
            })
            .unzip()
    });
    let perception = report
        .perception
        .context("the SLAM thread stopped unexpectedly")?;
    // The final map is read in place (a copy of a building's voxels doubled the station's memory
    // at the end of the soak run).
    let map = perception.slam.map();
    let grid = map.project();
    let stats = perception.slam.stats();
    let completed = report.outcome == Some(Outcome::Completed);
    let summary = Summary {
        completed,
        outcome: report.outcome.map_or("stopped", Outcome::name).into(),
        exploration_time_s: report.mission_time_s,
        frontiers_out_of_reach: report.frontiers_out_of_reach,
        goals_given_up: report.goals_given_up,
        goals_never_seen: report.goals_never_seen,
        coverage: grid
            .as_ref()
            .map_or(0.0, |g| coverage(&reachable, world, g)),
        wall_error: grid.as_ref().and_then(|g| wall_error(world, g)),
        collisions: collisions.iter().sum(),
        all_landed: all_down(&sitl),
        world: world.name().into(),
        link: args.sim.link.name(),
        strategy: args.sim.strategy.name(),
        pose_source: match args.sim.poses {
            PoseSource::Slam => "slam",
            PoseSource::Truth => "ground truth",
        },
        loop_closures: stats.loop_closures,
        loop_closures_rejected: stats.rejected_loop_closures,
        loop_closures_wrong: (args.sim.poses == PoseSource::Slam).then(|| {
            let closures = perception.slam.loop_closures();
            loop_closure_errors(&closures, &perception.truth, 1e-3)
                .iter()
                .zip(&closures)
                .filter(|&(e, c)| {
                    c.alive && e.is_some_and(|(t, r)| t > 0.2 || r > 5f64.to_radians())
                })
                .count()
        }),
        keyframes: stats.keyframes,
        drones: (0..args.sim.drones)
            .map(|k| {
                let estimated = perception.slam.trajectory(k);
                let score = |est: &[Stamped]| {
                    (args.sim.poses == PoseSource::Slam)
                        .then(|| ate(&perception.truth[k], est, Alignment::Se3, 1e-3))
                        .flatten()
                        .map(|a| a.rmse_m)
                };
                DroneSummary {
                    id: k + 1,
                    path_length_m: path_length(&truth_tracks[k]),
                    ate_rmse_m: score(&estimated),
                    ate_online_rmse_m: score(&perception.online[k]),
                    flight_pose_error_m: (flight_error[k].1 > 0)
                        .then(|| (flight_error[k].0 / flight_error[k].1 as f64).sqrt()),
                    lost_frames: perception.slam.estimate(k).map_or(0, |e| e.lost_frames),
                    odometry_frames: perception.slam.estimate(k).map_or(0, |e| e.odometry_frames),
                    projection_frames: perception
                        .slam
                        .estimate(k)
                        .map_or(0, |e| e.projection_frames),
                    weak_frames: perception.slam.estimate(k).map_or(0, |e| e.weak_frames),
                    collisions: collisions[k],
                    battery_swaps: report.drones[k].battery_swaps,
                    battery_left_pct: battery_left[k],
                    final_phase: report.drones[k].phase.name(),
                    left_mission: report.drones[k].left_mission.clone(),
                    rc_frames: rc.get(k).and_then(Option::as_ref).map(|r| r.frames),
                    rc_gap_p99_ms: rc
                        .get(k)
                        .and_then(Option::as_ref)
                        .and_then(|r| r.quantile_ms(0.99)),
                    rc_gap_max_ms: rc.get(k).and_then(Option::as_ref).and_then(|r| r.max_ms()),
                }
            })
            .collect(),
    };
    let trajectories: Vec<(String, Vec<Stamped>, Vec<Stamped>)> = (0..args.sim.drones)
        .map(|k| {
            (
                format!("drone{}", k + 1),
                perception.slam.trajectory(k),
                perception.truth[k].clone(),
            )
        })
        .collect();
    map.with(|voxels| {
        write_outputs(
            &args.out,
            voxels,
            grid.as_ref(),
            &truth_tracks,
            &trajectories,
            &summary,
        )
    })?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!(
            "{} in {:.0} s simulated: coverage {:.1} %, walls within 0.1 m: {}, {} collision(s), {}; outputs in {}",
            match (
                summary.completed,
                summary.frontiers_out_of_reach + summary.goals_given_up
            ) {
                (true, 0) => "explored".to_owned(),
                (true, _) if summary.goals_never_seen > 0 => format!(
                    "explored as far as the map reaches, but it may end short: {} goal(s) never looked at (every look around there lost the map)",
                    summary.goals_never_seen
                ),
                (true, _) => format!(
                    "explored as far as the map reaches ({} frontier(s) out of reach, {} goal(s) given up)",
                    summary.frontiers_out_of_reach, summary.goals_given_up
                ),
                (false, _) => {
                    // Why: the outcome, and why each drone that left the mission left it.
                    let why: Vec<String> = std::iter::once(summary.outcome.clone())
                        .chain(summary.drones.iter().filter_map(|d| {
                            d.left_mission
                                .as_ref()
                                .map(|w| format!("drone {}: {w}", d.id))
                        }))
                        .collect();
                    format!("not finished ({})", why.join("; "))
                }
            },
            summary.exploration_time_s,
            summary.coverage * 100.0,
            summary
                .wall_error
                .map_or("-".into(), |w| format!("{:.1} %", w.within_0_1_m * 100.0)),
            summary.collisions,
            if summary.all_landed {
                "all landed"
            } else {
                "NOT all landed"
            },
            args.out.display()
        );
    }
    if matches!(last_snapshot.state, MissionState::Exploring) {
        tracing::warn!("the mission was still exploring when the run ended");
    }
    drop(sitl);
    Ok(())
}

/// The simulator's true pose of every drone: x, y, z, yaw.
fn truth(sitl: &sitl::Sitl) -> Vec<[f64; 4]> {
    sitl.with_sim(|sim| {
        (0..sim.len())
            .map(|k| {
                let s = sim.vehicle(k).state();
                [s.position[0], s.position[1], s.position[2], s.yaw]
            })
            .collect()
    })
}

/// Whether every simulated vehicle is on the ground and disarmed.
fn all_down(sitl: &sitl::Sitl) -> bool {
    sitl.with_sim(|sim| {
        (0..sim.len()).all(|k| {
            let s = sim.vehicle(k).state();
            s.landed && !s.armed
        })
    })
}

fn path_length(track: &[(f64, [f64; 4])]) -> f64 {
    track
        .windows(2)
        .map(|w| (w[1].1[0] - w[0].1[0]).hypot(w[1].1[1] - w[0].1[1]))
        .sum()
}

/// Writes the map (PGM + YAML, PNG with the true trajectories), the 3D map (PLY), the camera
/// trajectories (TUM, estimated and true) and `summary.json`.
fn write_outputs(
    out: &Path,
    voxels: &slam::occupancy::VoxelMap,
    grid: Option<&Grid>,
    truth_tracks: &[Vec<(f64, [f64; 4])>],
    trajectories: &[(String, Vec<Stamped>, Vec<Stamped>)],
    summary: &Summary,
) -> anyhow::Result<()> {
    if let Some(g) = grid {
        outputs::write_map(out, g)?;
        let tracks: Vec<Vec<[f64; 2]>> = truth_tracks
            .iter()
            .map(|t| t.iter().map(|(_, p)| [p[0], p[1]]).collect())
            .collect();
        outputs::write_picture(&out.join("map.png"), g, &tracks)?;
    }
    outputs::write_ply(&out.join("map.ply"), voxels)?;
    for (name, estimated, truth) in trajectories {
        outputs::write_trajectory(&out.join(format!("{name}.tum")), estimated)?;
        outputs::write_trajectory(&out.join(format!("{name}-truth.tum")), truth)?;
    }
    outputs::write_json(&out.join("summary.json"), summary)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        explore: ExploreArgs,
    }

    fn parse(args: &[&str]) -> ExploreArgs {
        match Cli::try_parse_from(std::iter::once("explore").chain(args.iter().copied())) {
            Ok(cli) => cli.explore,
            Err(e) => panic!("{args:?}: {e}"),
        }
    }

    #[test]
    fn planning_at_the_end_of_a_look_is_off_unless_asked_for() {
        assert!(!parse(&[]).sim.plan_when_looked);
        assert!(parse(&["--plan-when-looked", "true"]).sim.plan_when_looked);
        assert!(!parse(&["--plan-when-looked", "false"]).sim.plan_when_looked);
        assert!(Cli::try_parse_from(["explore", "--plan-when-looked", "soon"]).is_err());
    }

    #[test]
    fn a_look_around_sweeps_the_short_way_unless_told_to_see_the_most_unknown_first_or_turn_whole()
    {
        assert_eq!(parse(&[]).sim.look_around, LookAround::Sweep);
        for (value, want) in [
            ("sweep", LookAround::Sweep),
            ("most-unknown-first", LookAround::MostUnknownFirst),
            ("whole", LookAround::Whole),
        ] {
            assert_eq!(parse(&["--look-around", value]).sim.look_around, want);
        }
        let e = Cli::try_parse_from(["explore", "--look-around", "most"])
            .err()
            .expect("not a way to look around");
        assert!(e.to_string().contains("most-unknown-first"), "{e}");
    }

    #[test]
    fn the_camera_watches_the_path_ahead_unless_told_not_to() {
        let default = parse(&[]).sim.view_ahead;
        assert_eq!(default, DroneConfig::default().follower.view_m);
        assert!(default > 0.0);
        assert_eq!(parse(&["--view-ahead", "0"]).sim.view_ahead, 0.0);
        assert!(validate(&parse(&["--view-ahead", "0"])).is_ok());
        for bad in ["-1", "NaN", "11"] {
            let e = validate(&parse(&[&format!("--view-ahead={bad}")])).expect_err(bad);
            assert!(e.to_string().contains("--view-ahead"), "{bad}: {e}");
        }
    }

    #[test]
    fn the_speed_loop_is_on_unless_turned_off() {
        assert!(parse(&[]).sim.speed_loop);
        assert!(DroneConfig::default().speed_gain > 0.0);
        assert!(!parse(&["--speed-loop", "false"]).sim.speed_loop);
        assert!(Cli::try_parse_from(["explore", "--speed-loop", "fast"]).is_err());
    }
}
