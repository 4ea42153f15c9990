//! `gcs fly --config FLEET.toml`: the mission on real or external vehicles — each reached at
//! its own address over MAVLink or the shield protocol, its camera read from a TCP frame stream
//! (`link/CAMERA.md`), all on the wall clock. `sitl run` in another process is such a fleet, and
//! so is ArduPilot SITL given a camera (see the README).
//!
//! The fleet file is described in [`gcs::fleet_file`].

use std::collections::BTreeMap;
use std::io::BufReader;
use std::net::TcpStream;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{SyncSender, sync_channel};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use link::camera::RgbdFrame;
use slam::system::{RobotSetup, Slam, SlamConfig};

use gcs::clock::{Clock, WallClock, link_clock};
use gcs::fleet::{LinkKind, LinkOptions, connect, sim_body_from_camera};
use gcs::fleet_file::{self, Vehicle};
use gcs::gui::Station;
use gcs::outputs;
use gcs::record::{Record, Recorder, Setup, SetupDrone};
use gcs::runtime::drone::{BatterySwap, DroneConfig};
use gcs::runtime::drone::{DroneSpec, StartSequence};
use gcs::runtime::perception::CameraFrame;
use gcs::runtime::{Outcome, Runtime, RuntimeConfig};
use link::mavlink::KeyStore;

use crate::gui_cmd::{LogArgs, Window, beside_window};

/// Arguments of `gcs fly`.
#[derive(Args, Debug, Clone)]
pub struct FlyArgs {
    /// The fleet: one `[[vehicle]]` table per drone (see `gcs fly --help` and the README).
    #[arg(long)]
    pub config: PathBuf,
    /// Give up (and land) after this many seconds.
    #[arg(long, default_value_t = 900.0)]
    pub timeout: f64,
    /// Where to write the map, trajectories, log and summary.
    #[arg(long, default_value = "fly-out")]
    pub out: PathBuf,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// A drone that came home for a low battery waits there for a charged one (swapped while
    /// its flight controller stays on) and takes off 5 s after it reads a charged one (90 % or
    /// more; 4.1 V a cell where it reports only the voltage), to rejoin the exploration.
    /// Default: it stays down.
    #[arg(long)]
    pub rejoin_after_battery_swap: bool,
    /// The mission log.
    #[command(flatten)]
    pub log: LogArgs,
}

/// The end of a flight, as written to `summary.json`.
#[derive(Debug, serde::Serialize)]
struct FlySummary {
    completed: bool,
    outcome: String,
    exploration_time_s: f64,
    loop_closures: usize,
    keyframes: usize,
    drones: Vec<FlyDrone>,
}

#[derive(Debug, serde::Serialize)]
struct FlyDrone {
    id: usize,
    name: String,
    /// Distance flown according to its filter, metres.
    path_length_m: f64,
    camera_frames: usize,
    lost_frames: usize,
    final_phase: &'static str,
    /// Why it left the mission before the end; `null` if it flew until the end.
    left_mission: Option<String>,
    /// Charged batteries it took off again on (`--rejoin-after-battery-swap`).
    battery_swaps: u32,
}

/// Runs `gcs fly`.
pub fn run(args: &FlyArgs) -> anyhow::Result<()> {
    run_with(args, None)
}

/// Flies the fleet, in a window if one is given (`gcs gui --config`).
pub fn run_with(args: &FlyArgs, window: Option<Window>) -> anyhow::Result<()> {
    let waits = window.as_ref().is_some_and(|w| w.wait_for_start);
    let session = window.as_ref().is_some_and(|w| w.close_ends_session);
    args.log.validate()?;
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        bail!(
            "--timeout {} must be a positive number of seconds",
            args.timeout
        );
    }
    let fleet = fleet_file::load(&args.config)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let clock: Arc<dyn Clock> = Arc::new(WallClock::start());
    // Cameras first (a vehicle is no use without one), then the links.
    let (tx, frames) = sync_channel(8);
    let mut streams: BTreeMap<String, Vec<(u8, usize)>> = BTreeMap::new();
    for (k, v) in fleet.iter().enumerate() {
        streams
            .entry(v.camera.to_string())
            .or_default()
            .push((v.camera_id, k));
    }
    for (address, routes) in streams {
        start_camera(&address, routes, tx.clone(), clock.clone())?;
    }
    drop(tx);
    let mut drones = vec![];
    for (k, v) in fleet.iter().enumerate() {
        let tlog = (!args.log.no_log && v.kind == LinkKind::Mavlink)
            .then(|| args.out.join(format!("drone{}.tlog", k + 1)));
        let signing = match &v.signing_key {
            Some(key) => Some(
                KeyStore::user()
                    .and_then(|store| store.load(key))
                    .with_context(|| format!("{}: signing_key", v.name))?,
            ),
            None => None,
        };
        let link = connect(
            v.kind,
            &v.address,
            link_clock(&clock),
            LinkOptions {
                tlog,
                channel_map: v.channels,
                signing,
            },
        )
        .with_context(|| format!("{} at {}", v.name, v.address))?;
        drones.push(DroneSpec {
            name: v.name.clone(),
            link,
            start_sequence: match v.kind {
                LinkKind::Mavlink => StartSequence::Mavlink,
                LinkKind::Shield => StartSequence::Shield,
            },
            altitude: v.altitude,
            start: v.start,
        });
    }
    let body_from_camera = sim_body_from_camera();
    let setups: Vec<RobotSetup> = fleet
        .iter()
        .map(|v| RobotSetup {
            body_from_camera,
            start: v.start.map(|s| {
                nalgebra::Isometry3::new(
                    nalgebra::Vector3::new(s[0], s[1], 0.0),
                    nalgebra::Vector3::z() * s[2],
                )
            }),
        })
        .collect();
    let recorder = if args.log.no_log {
        None
    } else {
        let r = Recorder::create(&args.out.join("mission.mcap"), args.log.log_camera_hz)?;
        r.send(Record::Setup(Setup {
            version: 1,
            world: None,
            strategy: "hungarian".into(),
            planner_radii: RuntimeConfig::default().planner_radii,
            region_radius_m: Some(RuntimeConfig::default().region_radius_m),
            hold_margin_m: Some(RuntimeConfig::default().hold_margin_m),
            max_pocket_m2: Some(RuntimeConfig::default().max_pocket_m2),
            turn_m_per_rad: Some(RuntimeConfig::default().turn_m_per_rad),
            stage_back_m: Some(RuntimeConfig::default().stage_back_m),
            centre_paths: Some(RuntimeConfig::default().centre_paths),
            unknown_comfort_m: Some(RuntimeConfig::default().unknown_comfort_m),
            drones: fleet
                .iter()
                .map(|v| SetupDrone::new(&v.name, v.start, &body_from_camera, v.altitude))
                .collect(),
        }));
        Some(r)
    };
    let runtime = Runtime::start(
        RuntimeConfig {
            timeout: Some(args.timeout),
            auto_start: !waits,
            exit_when_done: !session,
            drone: DroneConfig {
                battery_swap: args.rejoin_after_battery_swap.then(BatterySwap::default),
                ..DroneConfig::default()
            },
            ..RuntimeConfig::default()
        },
        drones,
        Slam::new(SlamConfig::default(), setups),
        frames,
        clock.clone(),
        recorder,
    )?;
    runtime.land_all_on_ctrl_c("fly");
    eprintln!(
        "fly: {} vehicle(s) connected; {} (Ctrl-C lands all)",
        fleet.len(),
        if waits {
            "waiting for the operator's start"
        } else {
            "exploring"
        }
    );
    let Some(window) = window else {
        return watch(args, &fleet, runtime);
    };
    let station = Station::of(
        &runtime,
        None,
        format!("{} vehicle(s) from {}", fleet.len(), args.config.display()),
    );
    let commander = runtime.commander();
    let args = args.clone();
    beside_window(station, window, commander, move || {
        watch(&args, &fleet, runtime)
    })
}

/// Follows the mission to its end, then writes the outputs and prints the summary.
fn watch(args: &FlyArgs, fleet: &[Vehicle], runtime: Runtime) -> anyhow::Result<()> {
    let started = Instant::now();
    let mut next = Duration::ZERO;
    while !runtime.finished() {
        if started.elapsed() >= next {
            next += Duration::from_secs(5);
            let s = runtime.snapshot();
            let states: Vec<String> = s
                .drones
                .iter()
                .map(|d| format!("{}: {} ({:?})", d.name, d.phase.name(), d.slam))
                .collect();
            eprintln!(
                "[{:6.1} s] {}  {} keyframes, {} loops",
                s.elapsed,
                states.join(", "),
                s.slam.stats.keyframes,
                s.slam.stats.loop_closures
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let report = runtime
        .join()
        .context("the mission loop stopped unexpectedly")?;
    let perception = report
        .perception
        .context("the SLAM thread stopped unexpectedly")?;
    let map = perception.slam.map();
    if let Some(g) = map.project() {
        outputs::write_map(&args.out, &g)?;
        let tracks: Vec<Vec<[f64; 2]>> = report
            .drones
            .iter()
            .map(|d| d.trajectory.iter().map(|(_, p)| [p[0], p[1]]).collect())
            .collect();
        outputs::write_picture(&args.out.join("map.png"), &g, &tracks)?;
    }
    map.with(|voxels| outputs::write_ply(&args.out.join("map.ply"), voxels))?;
    for k in 0..fleet.len() {
        outputs::write_trajectory(
            &args.out.join(format!("drone{}.tum", k + 1)),
            &perception.slam.trajectory(k),
        )?;
    }
    let stats = perception.slam.stats();
    let summary = FlySummary {
        completed: report.outcome == Some(Outcome::Completed),
        outcome: report.outcome.map_or("stopped", Outcome::name).into(),
        exploration_time_s: report.mission_time_s,
        loop_closures: stats.loop_closures,
        keyframes: stats.keyframes,
        drones: report
            .drones
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let e = perception.slam.estimate(k);
                FlyDrone {
                    id: k + 1,
                    name: d.name.clone(),
                    path_length_m: d.path_length_m,
                    camera_frames: e.as_ref().map_or(0, |e| e.frames),
                    lost_frames: e.as_ref().map_or(0, |e| e.lost_frames),
                    final_phase: d.phase.name(),
                    left_mission: d.left_mission.clone(),
                    battery_swaps: d.battery_swaps,
                }
            })
            .collect(),
    };
    outputs::write_json(&args.out.join("summary.json"), &summary)?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!(
            "{} after {:.0} s: {} keyframes, {} loops; outputs in {}",
            summary.outcome,
            summary.exploration_time_s,
            summary.keyframes,
            summary.loop_closures,
            args.out.display()
        );
    }
    Ok(())
}

/// Reads one camera stream in its own thread and routes its frames to the fleet's drones
/// (stamped on arrival with the mission clock). Reconnects when the stream drops.
fn start_camera(
    address: &str,
    routes: Vec<(u8, usize)>,
    tx: SyncSender<CameraFrame>,
    clock: Arc<dyn Clock>,
) -> anyhow::Result<()> {
    let Some(host) = address.strip_prefix("tcpout:") else {
        bail!("camera {address}: the frame stream is read with tcpout:HOST:PORT");
    };
    let host = host.to_owned();
    let address = address.to_owned();
    std::thread::Builder::new()
        .name(format!("camera {host}"))
        .spawn(move || {
            loop {
                match TcpStream::connect(&host) {
                    Ok(stream) => {
                        let _ = stream.set_nodelay(true);
                        let mut reader = BufReader::new(stream);
                        loop {
                            match RgbdFrame::read_from(&mut reader) {
                                Ok(frame) => {
                                    let Some(&(_, drone)) =
                                        routes.iter().find(|(id, _)| *id == frame.vehicle)
                                    else {
                                        continue;
                                    };
                                    let f = CameraFrame {
                                        drone,
                                        stamp: clock.now(),
                                        frame: Arc::new(frame),
                                        truth: None,
                                    };
                                    if tx.send(f).is_err() {
                                        return;
                                    }
                                }
                                Err(e) => {
                                    tracing::warn!("camera {address}: {e}; reconnecting");
                                    break;
                                }
                            }
                        }
                    }
                    Err(e) => tracing::debug!("camera {address}: {e}"),
                }
                std::thread::sleep(Duration::from_millis(500));
            }
        })?;
    Ok(())
}
