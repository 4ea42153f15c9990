//! `sitl`: runs simulated drones in a simulated building, reachable like hardware.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use sitl::bridge::{BridgeConfig, BridgedVehicle, CameraBridge};
use sitl::render::render;
use sitl::world::{BUILT_IN, DEFAULT_WORLD};
use sitl::{Camera, EndpointSpec, Protocol, SimConfig, Sitl, SitlConfig, VehicleParams, World};

/// The simulator: drones behind a shield or a MAVLink autopilot, their RGB-D cameras, a building.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run simulated vehicles, each served on its own address like real hardware.
    ///
    /// Example: sitl run --vehicle mavlink@tcpin:127.0.0.1:5760 --vehicle shield@tcpin:127.0.0.1:5800 --camera tcpin:127.0.0.1:5900
    Run(RunArgs),
    /// Render cameras for autopilots flown elsewhere (ArduPilot SITL), at the pose each reports.
    ///
    /// Example, beside `sim_vehicle.py -v ArduCopter` (its MAVProxy sends to UDP 14550 and
    /// 14551): sitl camera --vehicle udpin:127.0.0.1:14551@13.1,2.1,0 --camera tcpin:127.0.0.1:5900
    Camera(CameraArgs),
    /// Render one camera view of a world to PNG files (colour, and depth in millimetres).
    Snapshot(SnapshotArgs),
    /// List the built-in worlds.
    Worlds,
}

#[derive(clap::Args)]
struct WorldArg {
    /// A built-in world name, or a world file: .txt (world text), .yaml (ROS map_server), .json (HouseExpo).
    #[arg(long, default_value = DEFAULT_WORLD)]
    world: String,
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    world: WorldArg,
    /// A vehicle: PROTOCOL@ADDRESS with PROTOCOL mavlink or shield and ADDRESS tcpin:HOST:PORT,
    /// udpin:HOST:PORT, udpout:HOST:PORT or serial:PATH:BAUD. Repeat for more vehicles; MAVLink
    /// vehicle k (from 1) has system id k.
    #[arg(long = "vehicle", value_name = "PROTOCOL@ADDRESS", required = true)]
    vehicles: Vec<EndpointSpec>,
    /// Serve the camera frame stream (link/CAMERA.md) on tcpin:HOST:PORT.
    #[arg(long, value_name = "ADDRESS")]
    camera: Option<link::Address>,
    /// Camera image size.
    #[arg(long, default_value = "320x240", value_parser = parse_size)]
    camera_size: (u32, u32),
    /// Camera frames per second (simulated time).
    #[arg(long, default_value_t = 10.0)]
    camera_hz: f64,
    /// Simulated seconds per real second, or "max" to run as fast as the machine can.
    #[arg(long, default_value = "1", value_parser = parse_speed)]
    speed: f64,
    /// Seed of every noise source: the same seed and inputs give the same run.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Turbulence, m/s (standard deviation of the wind; 0 for still air).
    #[arg(long, default_value_t = 0.1)]
    gust: f64,
    /// Each vehicle's flight time on one battery at hover, minutes.
    #[arg(long, value_name = "MINUTES", default_value_t = 12.0)]
    flight_time: f64,
    /// A simulated operator puts a charged battery in a vehicle that has rested disarmed this
    /// many seconds with less than half its charge left (the link stays up); default: never.
    #[arg(long, value_name = "SECONDS")]
    battery_swap: Option<f64>,
    /// Stop after this many simulated seconds (default: run until interrupted).
    #[arg(long)]
    duration: Option<f64>,
    /// MAVLink vehicles sign from power-up with this key (a file of 64 hexadecimal digits that
    /// only its owner may read, e.g. one made by `gcs key new`); without it they sign once a
    /// station sends SETUP_SIGNING (`gcs key setup`).
    #[arg(long, value_name = "FILE")]
    signing_key: Option<PathBuf>,
}

#[derive(clap::Args)]
struct CameraArgs {
    #[command(flatten)]
    world: WorldArg,
    /// An autopilot: ADDRESS, or ADDRESS@X,Y,NORTH when it reports positions from an origin of
    /// its own (ArduPilot: where it was powered up) — that origin in the map (metres) and the
    /// map heading of its north axis (degrees). Repeat for more; camera ids on the stream
    /// follow this order (0, 1, …). Without @, positions are taken as map coordinates (what
    /// `sitl run`'s own autopilots report).
    #[arg(long = "vehicle", value_name = "ADDRESS[@X,Y,NORTH]", required = true)]
    vehicles: Vec<BridgedVehicle>,
    /// Serve the camera frame stream (link/CAMERA.md) on tcpin:HOST:PORT.
    #[arg(long, value_name = "ADDRESS", default_value = "tcpin:127.0.0.1:5900")]
    camera: link::Address,
    /// Camera image size.
    #[arg(long, default_value = "320x240", value_parser = parse_size)]
    camera_size: (u32, u32),
    /// Camera frames per second per vehicle (wall time), at most 100.
    #[arg(long, default_value_t = 10.0)]
    camera_hz: f64,
    /// Seed of the cameras' noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Stop after this many seconds (default: run until interrupted).
    #[arg(long)]
    duration: Option<f64>,
}

#[derive(clap::Args)]
struct SnapshotArgs {
    #[command(flatten)]
    world: WorldArg,
    /// Camera position and heading: X,Y,Z,YAW in metres and degrees (default: drone 1's start, 1.2 m up).
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    pose: Option<[f64; 4]>,
    /// Image size.
    #[arg(long, default_value = "640x480", value_parser = parse_size)]
    size: (u32, u32),
    /// Output prefix: writes PREFIX-rgb.png and PREFIX-depth.png.
    #[arg(long, default_value = "snapshot")]
    out: PathBuf,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("'{s}': expected WIDTHxHEIGHT, e.g. 320x240"))?;
    let (w, h): (u32, u32) = (
        w.parse().map_err(|_| format!("'{w}' is not a width"))?,
        h.parse().map_err(|_| format!("'{h}' is not a height"))?,
    );
    if !(16..=4096).contains(&w) || !(16..=4096).contains(&h) {
        return Err(format!("{w}x{h}: each side must be 16–4096 pixels"));
    }
    Ok((w, h))
}

fn parse_speed(s: &str) -> Result<f64, String> {
    if s == "max" {
        return Ok(f64::INFINITY);
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!(
            "'{s}': give a positive factor of real time (e.g. 1, 10) or max"
        )),
    }
}

fn parse_pose(s: &str) -> Result<[f64; 4], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected X,Y,Z,YAW (metres, degrees)"))?;
    match v[..] {
        [x, y, z, yaw] if v.iter().all(|p| p.is_finite()) => Ok([x, y, z, yaw]),
        _ => Err(format!("'{s}': expected four numbers X,Y,Z,YAW")),
    }
}

fn load_world(arg: &WorldArg) -> anyhow::Result<Arc<World>> {
    Ok(Arc::new(World::load(&arg.world)?))
}

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run(args),
        Command::Camera(args) => camera(args),
        Command::Snapshot(args) => snapshot(args),
        Command::Worlds => {
            for (name, text) in BUILT_IN {
                let first = text.lines().next().unwrap_or("").trim_start_matches("# ");
                println!("{name:<12} {first}");
            }
            Ok(())
        }
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(args: RunArgs) -> anyhow::Result<()> {
    let world = load_world(&args.world)?;
    if !(args.camera_hz.is_finite() && args.camera_hz > 0.0) {
        bail!("--camera-hz {} must be a positive rate", args.camera_hz);
    }
    if !(args.gust.is_finite() && args.gust >= 0.0) {
        bail!("--gust {} must be zero or more m/s", args.gust);
    }
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration {d} must be a positive number of seconds");
    }
    let signing_key = match &args.signing_key {
        Some(path) => Some(link::mavlink::keys::read_key_file(path)?.secret),
        None => None,
    };
    let (w, h) = args.camera_size;
    let config = SitlConfig {
        world: world.clone(),
        sim: SimConfig {
            seed: args.seed,
            camera: Some(Camera::kinect(w, h)),
            camera_hz: args.camera_hz,
            gust_mps: args.gust,
            vehicle: VehicleParams {
                endurance_s: args.flight_time * 60.0,
                battery_swap_s: args.battery_swap,
                ..VehicleParams::default()
            },
            ..SimConfig::default()
        },
        vehicles: args.vehicles.clone(),
        camera: args.camera.clone(),
        speed: args.speed,
        signing_key,
    };
    let sitl = Sitl::start(config).context("cannot start the simulator")?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "sitl: world '{}' ({:.1} × {:.1} m), seed {}, speed {}",
        world.name(),
        world.size().0 as f64 * world.resolution(),
        world.size().1 as f64 * world.resolution(),
        args.seed,
        if args.speed.is_finite() {
            format!("{}×", args.speed)
        } else {
            "max".into()
        }
    )?;
    let starts: Vec<[f64; 3]> = sitl.starts();
    for (k, (spec, local)) in args.vehicles.iter().zip(sitl.endpoint_addrs()).enumerate() {
        let [x, y, yaw] = starts[k];
        let what = match spec.protocol {
            Protocol::Mavlink => format!("MAVLink ArduCopter, system id {}", k + 1),
            Protocol::Shield => "I/O shield + Naza".to_owned(),
        };
        let at = local.map_or_else(
            || spec.address.to_string(),
            |a| format!("{} (port {})", spec.address, a.port()),
        );
        writeln!(
            out,
            "sitl: vehicle {}: {what} on {at}, start [{x:.2}, {y:.2}, {yaw:.3}] (x, y, yaw)",
            k + 1
        )?;
    }
    if let Some(a) = sitl.camera_addr() {
        writeln!(
            out,
            "sitl: camera stream on tcp {a} ({w}×{h} at {} Hz)",
            args.camera_hz
        )?;
    }
    writeln!(out, "sitl: ready")?;
    out.flush()?;
    drop(out);
    let start = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let now = sitl.time().as_secs_f64();
        if args.duration.is_some_and(|d| now >= d) {
            break;
        }
        if start.elapsed() > Duration::from_secs(5) && now == 0.0 {
            bail!("the simulator is not advancing");
        }
    }
    let summary = sitl.with_sim(|sim| {
        (0..sim.len())
            .map(|k| {
                let s = sim.vehicle(k).state();
                format!(
                    "sitl: vehicle {}: at ({:.2}, {:.2}, {:.2}), {}, {} collision(s)",
                    k + 1,
                    s.position[0],
                    s.position[1],
                    s.position[2],
                    if s.armed { "armed" } else { "disarmed" },
                    s.collisions
                )
            })
            .collect::<Vec<_>>()
    });
    for line in summary {
        println!("{line}");
    }
    sitl.stop();
    Ok(())
}

fn camera(args: CameraArgs) -> anyhow::Result<()> {
    let world = load_world(&args.world)?;
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration {d} must be a positive number of seconds");
    }
    let (w, h) = args.camera_size;
    let bridge = CameraBridge::start(BridgeConfig {
        camera: Camera::kinect(w, h),
        camera_hz: args.camera_hz,
        seed: args.seed,
        ..BridgeConfig::new(
            world.clone(),
            args.vehicles.clone(),
            Some(args.camera.clone()),
        )
    })
    .context("cannot start the camera bridge")?;
    let frames = bridge.subscribe();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "sitl camera: world '{}', {} autopilot(s)",
        world.name(),
        args.vehicles.len()
    )?;
    for (k, v) in args.vehicles.iter().enumerate() {
        let [x, y, north] = v.map_from_local;
        writeln!(
            out,
            "sitl camera: camera {k}: the autopilot on {}, its local origin at ({x:.2}, {y:.2}), north at {:.1}° in the map",
            v.address,
            north.to_degrees()
        )?;
    }
    if let Some(a) = bridge.camera_addr() {
        writeln!(
            out,
            "sitl camera: camera stream on tcp {a} ({w}×{h} at {} Hz)",
            args.camera_hz
        )?;
    }
    writeln!(out, "sitl: ready")?;
    out.flush()?;
    drop(out);
    // Every 10 s, how many frames each camera rendered: a camera without frames has no pose
    // from its autopilot.
    let start = Instant::now();
    let mut counts = vec![0u64; args.vehicles.len()];
    let mut last_report = Instant::now();
    loop {
        if let Ok(f) = frames.recv_timeout(Duration::from_millis(100))
            && let Some(c) = counts.get_mut(usize::from(f.frame.vehicle))
        {
            *c += 1;
        }
        if args
            .duration
            .is_some_and(|d| start.elapsed().as_secs_f64() >= d)
        {
            break;
        }
        if last_report.elapsed() >= Duration::from_secs(10) {
            for (k, (c, v)) in counts.iter().zip(&args.vehicles).enumerate() {
                if *c == 0 {
                    tracing::warn!(
                        "camera {k}: no pose from {} yet (no vehicle heard, or it sends no LOCAL_POSITION_NED and ATTITUDE: an ArduPilot needs a position estimate)",
                        v.address
                    );
                } else {
                    tracing::info!("camera {k}: {c} frames");
                }
            }
            last_report = Instant::now();
        }
    }
    for (k, c) in counts.iter().enumerate() {
        println!("sitl camera: camera {k}: {c} frames");
    }
    Ok(())
}

fn snapshot(args: SnapshotArgs) -> anyhow::Result<()> {
    let world = load_world(&args.world)?;
    let [x, y, z, yaw] = match args.pose {
        Some(p) => p,
        None => {
            let sim = sitl::Sim::new(world.clone(), 1, SimConfig::default())?;
            let s = sim.vehicle(0).state();
            [s.position[0], s.position[1], 1.2, s.yaw.to_degrees()]
        }
    };
    let vehicle = sitl::Vehicle::new(sitl::VehicleParams::default(), x, y, yaw.to_radians());
    let pose = {
        let mut p = vehicle.map_from_camera();
        p.translation.z += z;
        p
    };
    let camera = Camera::kinect(args.size.0, args.size.1);
    let (rgb, depth) = render(&world, &pose, &camera, Some((0, 0)));
    let (w, h) = args.size;
    let colour_path = PathBuf::from(format!("{}-rgb.png", args.out.display()));
    let depth_path = PathBuf::from(format!("{}-depth.png", args.out.display()));
    image::RgbImage::from_raw(w, h, rgb)
        .context("colour image size")?
        .save(&colour_path)
        .with_context(|| format!("cannot write {}", colour_path.display()))?;
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, depth)
        .context("depth image size")?
        .save(&depth_path)
        .with_context(|| format!("cannot write {}", depth_path.display()))?;
    println!(
        "wrote {} and {} (depth in mm, 0 = no reading)",
        colour_path.display(),
        depth_path.display()
    );
    Ok(())
}
