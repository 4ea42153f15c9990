//! Fleets: the simulated one (the simulator in-process, each vehicle on its own loopback socket
//! and reached through the real link adapters, exactly as hardware would be) and, from a
//! configuration file, real or external vehicles.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use link::mavlink::{MavlinkConfig, MavlinkLink};
use link::shield::{ShieldConfig, ShieldLink};
use link::{LinkState, VehicleClock, VehicleLink};
use nalgebra::Isometry3;
use sitl::{Camera, EndpointSpec, Protocol, SimConfig, Sitl, SitlConfig, VehicleParams, World};
use slam::system::RobotSetup;

use crate::clock::{Clock, SimulatedClock, link_clock};
use crate::runtime::drone::{DroneSpec, StartSequence};
use crate::runtime::perception::CameraFrame;

/// The link protocol of the simulated fleet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LinkKind {
    /// ArduCopter-like autopilots over MAVLink (TCP).
    Mavlink,
    /// The thesis's I/O shield in front of a Naza-like controller (TCP).
    Shield,
}

impl LinkKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            LinkKind::Mavlink => "mavlink",
            LinkKind::Shield => "shield",
        }
    }
}

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SimFleetConfig {
    /// The building.
    pub world: Arc<World>,
    /// Number of drones.
    pub drones: usize,
    /// How the station talks to them.
    pub link: LinkKind,
    /// Simulated seconds per real second.
    pub speed: f64,
    /// Seed of the simulator's noise.
    pub seed: u64,
    /// Each vehicle's flight time on one battery at hover, seconds.
    pub flight_time_s: f64,
    /// A vehicle resting disarmed with a spent battery gets a charged one after this long,
    /// seconds ([`sitl::vehicle::VehicleParams::battery_swap_s`]); `None`: never.
    pub battery_swap_s: Option<f64>,
    /// Record each MAVLink vehicle's traffic to `droneK.tlog` here.
    pub tlog_dir: Option<std::path::PathBuf>,
    /// Drone 1's altitude band, metres; each further drone flies [`BAND_STEP_M`] higher.
    pub lowest_band_m: f64,
}

/// A simulated fleet, connected.
pub struct SimFleet {
    /// The simulator (ground truth for evaluation).
    pub sitl: Sitl,
    /// The drones for the runtime.
    pub drones: Vec<DroneSpec>,
    /// Their camera frames.
    pub frames: Receiver<CameraFrame>,
    /// The SLAM's robot setups.
    pub setups: Vec<RobotSetup>,
    /// The simulator's clock.
    pub clock: Arc<dyn Clock>,
}

/// The lowest altitude band, drone 1's, metres. The simulated Kinect sees ±24.6° vertically, so
/// from 0.6 m the floor's tiles come into view 1.3 m ahead (from 0.75 m, 1.6 m; from 0.9 m,
/// 2.0 m; from 1.05 m, 2.3 m), and before a bare wall they are what a frame registers on. In
/// SITL (two drones on SLAM poses) the lower the pair, the fewer frames lost: the bands 0.75
/// and 0.9 m lost 43 % fewer in all than 0.9 and 1.05 m (70 missions a pair, stop 78), and 0.6
/// and 0.75 m 65 % fewer than 0.75 and 0.9 m, with no collision against 6 in 3 missions and no
/// drone leaving its mission against 4 (56 missions side by side, stop 79;
/// `docs/benchmarks.md`).
pub const LOWEST_BAND_M: f64 = 0.6;

/// How much higher each further drone flies than the one before it, metres.
pub const BAND_STEP_M: f64 = 0.15;

/// The altitude band of drone `k` when drone 1 flies at `lowest` metres: each its own, so paths
/// may cross (thesis §3.3.3).
pub fn altitude_band(lowest: f64, k: usize) -> f64 {
    lowest + BAND_STEP_M * k as f64
}

/// The heights the map's walls are taken from (`slam::occupancy::OccupancyConfig`), metres, low
/// and high: every drone's altitude band must lie within them, or it flies at a height where
/// the map marks no wall.
pub fn band_limits() -> (f64, f64) {
    let occupancy = slam::occupancy::OccupancyConfig::default();
    (occupancy.occupancy_min_z, occupancy.occupancy_max_z)
}

/// The camera mounting of the simulated vehicles.
pub fn sim_body_from_camera() -> Isometry3<f64> {
    sitl::Vehicle::new(sitl::VehicleParams::default(), 0.0, 0.0, 0.0).map_from_camera()
}

impl SimFleet {
    /// Starts the simulator and connects a link to every vehicle.
    pub fn start(config: &SimFleetConfig) -> anyhow::Result<Self> {
        let protocol = match config.link {
            LinkKind::Mavlink => Protocol::Mavlink,
            LinkKind::Shield => Protocol::Shield,
        };
        let vehicles: Vec<EndpointSpec> = (0..config.drones)
            .map(|_| {
                Ok(EndpointSpec {
                    protocol,
                    address: "tcpin:127.0.0.1:0".parse()?,
                })
            })
            .collect::<anyhow::Result<_>>()?;
        let sitl = Sitl::start(SitlConfig {
            world: config.world.clone(),
            sim: SimConfig {
                seed: config.seed,
                camera: Some(Camera::kinect(320, 240)),
                camera_hz: 10.0,
                vehicle: VehicleParams {
                    endurance_s: config.flight_time_s,
                    battery_swap_s: config.battery_swap_s,
                    ..VehicleParams::default()
                },
                ..SimConfig::default()
            },
            vehicles,
            camera: None,
            speed: config.speed,
            signing_key: None,
        })
        .context("cannot start the simulator")?;
        let clock: Arc<dyn Clock> = Arc::new(SimulatedClock {
            clock: sitl.clock(),
            speed: config.speed,
        });
        let starts: Vec<[f64; 3]> = sitl.starts();
        let mut drones = vec![];
        for (k, addr) in sitl.endpoint_addrs().iter().enumerate() {
            let port = addr
                .context("vehicle endpoint has no local address")?
                .port();
            let tlog = config
                .tlog_dir
                .as_ref()
                .map(|d| d.join(format!("drone{}.tlog", k + 1)));
            let link = connect(
                config.link,
                &format!("tcpout:127.0.0.1:{port}"),
                link_clock(&clock),
                LinkOptions {
                    tlog,
                    ..LinkOptions::default()
                },
            )
            .with_context(|| format!("drone {}", k + 1))?;
            drones.push(DroneSpec {
                name: format!("drone {}", k + 1),
                link,
                start_sequence: match config.link {
                    LinkKind::Mavlink => StartSequence::Mavlink,
                    LinkKind::Shield => StartSequence::Shield,
                },
                altitude: altitude_band(config.lowest_band_m, k),
                start: Some(starts[k]),
            });
        }
        let body_from_camera = sim_body_from_camera();
        let setups = starts
            .iter()
            .map(|s| RobotSetup {
                body_from_camera,
                // The starts are known, as in the thesis (the SLAM can do without: see
                // `slam::system`).
                start: Some(Isometry3::new(
                    nalgebra::Vector3::new(s[0], s[1], 0.0),
                    nalgebra::Vector3::z() * s[2],
                )),
            })
            .collect();
        // Camera frames in-process, none dropped: when the station's SLAM falls behind, the
        // simulation waits for it (the bounded queue passes the back-pressure on). The queues
        // are short: every frame waiting in them is simulated time between a frame and the pose
        // the drone flies on (14 frames, 0.7 s at 20 frames per second, made the filter fly on
        // poses half a metre off).
        let (tx, frames) = sync_channel(1);
        let source = sitl.subscribe_all();
        std::thread::Builder::new()
            .name("sim-cameras".into())
            .spawn(move || {
                for f in source {
                    let frame = CameraFrame {
                        drone: usize::from(f.frame.vehicle),
                        stamp: f.frame.stamp.as_secs_f64(),
                        frame: Arc::new(f.frame.clone()),
                        truth: Some(f.map_from_camera),
                    };
                    if tx.send(frame).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            sitl,
            drones,
            frames,
            setups,
            clock,
        })
    }

    /// The simulator's true pose of every drone: x, y, z, yaw.
    pub fn truth(&self) -> Vec<[f64; 4]> {
        self.sitl.with_sim(|sim| {
            (0..sim.len())
                .map(|k| {
                    let s = sim.vehicle(k).state();
                    [s.position[0], s.position[1], s.position[2], s.yaw]
                })
                .collect()
        })
    }

    /// Wall collisions of every drone so far.
    pub fn collisions(&self) -> Vec<u32> {
        self.sitl.with_sim(|sim| {
            (0..sim.len())
                .map(|k| sim.vehicle(k).state().collisions)
                .collect()
        })
    }
}

/// How a link is opened beyond its protocol and address.
#[derive(Debug, Default)]
pub struct LinkOptions {
    /// Record MAVLink traffic to this `.tlog`.
    pub tlog: Option<std::path::PathBuf>,
    /// The RC wiring, if not the protocol's default.
    pub channel_map: Option<link::ChannelMap>,
    /// Sign MAVLink frames with this key and refuse any not signed with it.
    pub signing: Option<link::mavlink::SigningKey>,
}

/// Connects a link to one vehicle and waits until it is heard. Heartbeat timeouts count the
/// vehicle's `clock` (simulated time for a simulated vehicle, so a simulation held up is not a
/// lost link) and the station's rates scale with its speed, so they stay per simulated second
/// as in real time. MAVLink traffic is recorded to `tlog` when given.
pub fn connect(
    kind: LinkKind,
    address: &str,
    clock: VehicleClock,
    options: LinkOptions,
) -> anyhow::Result<Arc<dyn VehicleLink>> {
    let LinkOptions {
        tlog,
        channel_map,
        signing,
    } = options;
    let address = address.parse()?;
    let link: Arc<dyn VehicleLink> = match kind {
        LinkKind::Mavlink => {
            let link = MavlinkLink::connect(
                &address,
                MavlinkConfig {
                    rc_rate_hz: (20.0 * clock.speed()).min(400.0),
                    clock,
                    channel_map: channel_map
                        .unwrap_or_else(|| MavlinkConfig::default().channel_map),
                    signing,
                    ..MavlinkConfig::default()
                },
            )?;
            if let Some(path) = &tlog {
                link.record_to(path)
                    .with_context(|| format!("cannot record to {}", path.display()))?;
            }
            let v = link
                .wait_for_vehicle(Duration::from_secs(10))
                .context("the vehicle never sent a heartbeat")?;
            Arc::new(v)
        }
        LinkKind::Shield => Arc::new(ShieldLink::connect(
            &address,
            ShieldConfig {
                rc_rate_hz: 50.0,
                clock,
                channel_map: channel_map.unwrap_or_else(|| ShieldConfig::default().channel_map),
                ..ShieldConfig::default()
            },
        )?),
    };
    let until = Instant::now() + Duration::from_secs(10);
    while link.status().state != LinkState::Connected {
        if Instant::now() > until {
            bail!("the link never came up ({:?})", link.status());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(link)
}
