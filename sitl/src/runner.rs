//! The simulator as a running system: the physics loop paced to real time (or faster), each
//! vehicle served over its own transport like hardware, and the cameras streamed.
//!
//! * A **shield** vehicle is a [`link::shield::emulator::ShieldEmulator`] (the firmware model of
//!   `link/PROTOCOL.md`) on simulated time: its output pulses fly the vehicle through a DJI
//!   Naza-like controller in ATTI mode (altitude hold, thesis wiring), and it reports sonar, IMU
//!   yaw and battery.
//! * A **MAVLink** vehicle is an [`Autopilot`] (ArduCopter-like) with system id `k + 1`.
//! * Cameras reach in-process consumers through [`Sitl::subscribe`] and other processes through
//!   the TCP frame stream of `link/CAMERA.md`.
//!
//! Timeouts and failsafes count simulated time, as ArduPilot's SITL does when sped up.

use std::io::{Read, Write};
use std::net::SocketAddr;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use link::mavlink::frame::{FrameScanner, RawFrame};
use link::shield::emulator::{EmulatorConfig, EmulatorServer, Sensors as ShieldSensors};
use link::transport::{duplex, is_timeout, run_sessions};
use link::{Address, ChannelMap, FlightMode, Sticks, Transport, TransportError};

use crate::autopilot::{Autopilot, AutopilotConfig, RcStats};
use crate::sensors::Readings;
use crate::sim::{Sim, SimConfig, SimError};
use crate::stream::{self, Subscribers, Subscription};
use crate::vehicle::{Vehicle, VehicleEvent};
use crate::world::World;

/// The protocol a simulated vehicle speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protocol {
    /// The thesis's I/O shield (`link/PROTOCOL.md`) in front of a Naza-like controller.
    Shield,
    /// MAVLink, as ArduPilot Copter.
    Mavlink,
}

/// One simulated vehicle's endpoint: `PROTOCOL@ADDRESS`, e.g. `mavlink@tcpin:127.0.0.1:5760`.
#[derive(Debug, Clone, PartialEq)]
pub struct EndpointSpec {
    /// What it speaks.
    pub protocol: Protocol,
    /// Where it listens (or sends to).
    pub address: Address,
}

impl FromStr for EndpointSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (protocol, address) = s.split_once('@').ok_or_else(|| {
            format!("'{s}': expected PROTOCOL@ADDRESS, e.g. mavlink@tcpin:127.0.0.1:5760 or shield@tcpin:127.0.0.1:5800")
        })?;
        let protocol = match protocol {
            "mavlink" => Protocol::Mavlink,
            "shield" => Protocol::Shield,
            p => {
                return Err(format!(
                    "'{s}': unknown protocol '{p}' (use mavlink or shield)"
                ));
            }
        };
        let address = address.parse().map_err(|e| format!("'{s}': {e}"))?;
        Ok(Self { protocol, address })
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct SitlConfig {
    /// The building.
    pub world: Arc<World>,
    /// Physics, sensors and cameras.
    pub sim: SimConfig,
    /// One endpoint per vehicle, in start-position order.
    pub vehicles: Vec<EndpointSpec>,
    /// Where the camera frame stream listens (`tcpin:HOST:PORT`), if anywhere.
    pub camera: Option<Address>,
    /// Simulated seconds per real second; `f64::INFINITY` runs as fast as the machine can.
    pub speed: f64,
    /// The MAVLink vehicles' signing key at power-up (`None`: off until a station sends
    /// `SETUP_SIGNING`).
    pub signing_key: Option<[u8; 32]>,
}

/// The simulator could not start.
#[derive(Debug, thiserror::Error)]
pub enum SitlError {
    /// The simulation itself is ill-formed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// An endpoint's transport could not be opened.
    #[error("vehicle {vehicle}: {source}")]
    Transport {
        /// The vehicle's index.
        vehicle: usize,
        /// Why.
        source: TransportError,
    },
    /// The camera stream's address.
    #[error("camera stream: {0}")]
    Camera(String),
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
}

/// The shared state of a running simulator.
struct Shared {
    sim: Mutex<Sim>,
    stop: Arc<AtomicBool>,
    time_us: AtomicU64,
    /// Camera frame subscribers, in process and over the network (the lossless ones hold up
    /// the simulation while they are behind).
    subscribers: Arc<Subscribers>,
    /// Endpoints whose link is to die at the next tick.
    cut: Mutex<Vec<usize>>,
    /// Vehicles whose camera has failed (their frames are no longer sent).
    dead_cameras: Mutex<Vec<u8>>,
    /// Each vehicle's RC override regularity, refreshed every simulated second.
    rc_stats: Mutex<Vec<Option<RcStats>>>,
}

/// A running simulator. Dropping it stops every thread and closes every endpoint.
pub struct Sitl {
    shared: Arc<Shared>,
    endpoints: Vec<Option<SocketAddr>>,
    camera: Option<SocketAddr>,
    threads: Vec<JoinHandle<()>>,
}

/// Simulated time per physics tick.
pub const TICK: Duration = Duration::from_millis(10);

impl Sitl {
    /// Opens every endpoint (so a taken port fails here, before anything runs) and starts.
    pub fn start(config: SitlConfig) -> Result<Self, SitlError> {
        if config.speed.is_nan() || config.speed <= 0.0 {
            return Err(SitlError::Config(format!(
                "speed {} must be a positive factor of real time",
                config.speed
            )));
        }
        let sim = Sim::new(
            config.world.clone(),
            config.vehicles.len(),
            config.sim.clone(),
        )?;
        let shared = Arc::new(Shared {
            sim: Mutex::new(sim),
            stop: Arc::new(AtomicBool::new(false)),
            time_us: AtomicU64::new(0),
            subscribers: Arc::default(),
            cut: Mutex::new(vec![]),
            dead_cameras: Mutex::new(vec![]),
            rc_stats: Mutex::new(vec![]),
        });
        let mut threads = vec![];
        let mut endpoints: Vec<Box<dyn Endpoint>> = vec![];
        let mut local = vec![];
        for (k, spec) in config.vehicles.iter().enumerate() {
            let transport = Transport::open(&spec.address)
                .map_err(|source| SitlError::Transport { vehicle: k, source })?;
            local.push(transport.local_addr());
            let endpoint: Box<dyn Endpoint> = match spec.protocol {
                Protocol::Shield => {
                    let clock_shared = shared.clone();
                    let clock = Arc::new(move || {
                        Duration::from_micros(clock_shared.time_us.load(Ordering::Relaxed))
                    });
                    Box::new(ShieldEndpoint::new(transport, clock))
                }
                Protocol::Mavlink => {
                    let (endpoint, thread) = MavlinkEndpoint::start(
                        transport,
                        AutopilotConfig {
                            system_id: (k + 1) as u8,
                            signing_key: config.signing_key,
                            ..AutopilotConfig::default()
                        },
                        shared.clone(),
                    );
                    threads.extend(thread);
                    Box::new(endpoint)
                }
            };
            tracing::info!(vehicle = k, address = %spec.address, protocol = ?spec.protocol, "vehicle endpoint open");
            endpoints.push(endpoint);
        }
        let camera = match &config.camera {
            None => None,
            Some(address) => {
                let (addr, thread) =
                    stream::listen(address, shared.subscribers.clone(), shared.stop.clone())
                        .map_err(SitlError::Camera)?;
                threads.push(thread);
                Some(addr)
            }
        };
        {
            let mut sim = shared.sim.lock().unwrap_or_else(PoisonError::into_inner);
            for (k, e) in endpoints.iter_mut().enumerate() {
                e.init(sim.vehicle_mut(k));
            }
        }
        let physics_shared = shared.clone();
        let speed = config.speed;
        threads.push(
            std::thread::Builder::new()
                .name("sitl-physics".into())
                .spawn(move || physics(&physics_shared, endpoints, speed))
                .map_err(|e| SitlError::Config(format!("cannot start the physics thread: {e}")))?,
        );
        Ok(Self {
            shared,
            endpoints: local,
            camera,
            threads,
        })
    }

    /// The local address each vehicle endpoint listens on (`None` for serial and `udpout`).
    pub fn endpoint_addrs(&self) -> &[Option<SocketAddr>] {
        &self.endpoints
    }

    /// The camera stream's local address.
    pub fn camera_addr(&self) -> Option<SocketAddr> {
        self.camera
    }

    /// Simulated time now.
    pub fn time(&self) -> Duration {
        Duration::from_micros(self.shared.time_us.load(Ordering::Relaxed))
    }

    /// Every vehicle's pose now as x, y (metres) and yaw (radians): at the start, where each
    /// one starts (a station needs them to anchor its map).
    pub fn starts(&self) -> Vec<[f64; 3]> {
        self.with_sim(|sim| {
            (0..sim.len())
                .map(|k| {
                    let s = sim.vehicle(k).state();
                    [s.position[0], s.position[1], s.yaw]
                })
                .collect()
        })
    }

    /// A handle that reads simulated time from any thread, for as long as it is held.
    pub fn clock(&self) -> SimClock {
        SimClock(self.shared.clone())
    }

    /// Every camera frame from now on; when 4 of a camera's frames wait, its next drops its
    /// oldest (like a network stream: see [`Subscribers::add`]).
    pub fn subscribe(&self) -> Subscription {
        self.shared.subscribers.add(false, 4)
    }

    /// Every camera frame from now on, none dropped: when the receiver falls 2 behind, simulated
    /// time waits for it (an in-process station whose SLAM must see every frame, whatever the
    /// machine's load — and see it soon: a deeper queue is latency, in simulated time, between
    /// a frame and the pose the vehicle flies on). Drop the receiver to release the simulation.
    pub fn subscribe_all(&self) -> Subscription {
        self.shared.subscribers.add(true, 2)
    }

    /// Kills vehicle `k`'s link, as a radio that dies in flight: from the next tick its
    /// endpoint neither hears nor answers the station, while the vehicle flies on, so its own
    /// failsafe (GCS heartbeat lost, or the shield's command timeout) must land it.
    pub fn kill_endpoint(&self, k: usize) {
        self.shared
            .cut
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(k);
    }

    /// Fails vehicle `k`'s camera: from now on its frames are neither sent to subscribers nor
    /// streamed, while the vehicle and its link carry on.
    pub fn kill_camera(&self, k: usize) {
        if let Ok(k) = u8::try_from(k) {
            self.shared
                .dead_cameras
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(k);
        }
    }

    /// How regularly each vehicle received RC overrides (MAVLink vehicles; `None` for the
    /// shield), as of the last simulated second.
    pub fn rc_stats(&self) -> Vec<Option<RcStats>> {
        self.shared
            .rc_stats
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Runs `f` on the simulation between two physics ticks (ground truth, wind, ...).
    pub fn with_sim<R>(&self, f: impl FnOnce(&mut Sim) -> R) -> R {
        f(&mut self
            .shared
            .sim
            .lock()
            .unwrap_or_else(PoisonError::into_inner))
    }

    /// Stops the simulator and waits for its threads.
    pub fn stop(self) {}
}

impl Drop for Sitl {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// Reads a running simulator's time (see [`Sitl::clock`]).
#[derive(Clone)]
pub struct SimClock(Arc<Shared>);

impl SimClock {
    /// Simulated time now.
    pub fn now(&self) -> Duration {
        Duration::from_micros(self.0.time_us.load(Ordering::Relaxed))
    }
}

impl std::fmt::Debug for SimClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SimClock({:?})", self.now())
    }
}

/// One vehicle's connection to the outside world.
trait Endpoint: Send {
    /// Prepares the vehicle before the first tick.
    fn init(&mut self, vehicle: &mut Vehicle);
    /// Applies the station's inputs before a physics tick.
    fn control(&mut self, now: Duration, vehicle: &mut Vehicle);
    /// Reports the vehicle's state after a physics tick.
    fn report(
        &mut self,
        now: Duration,
        vehicle: &mut Vehicle,
        readings: &Readings,
        events: &[VehicleEvent],
    );
    /// The link dies: nothing in or out from now on.
    fn cut(&mut self);
    /// How regularly RC overrides arrived, if the protocol has them.
    fn rc_stats(&self) -> Option<RcStats> {
        None
    }
}

/// The shield firmware in front of a Naza-like controller in ATTI mode.
struct ShieldEndpoint {
    server: EmulatorServer,
    channel_map: ChannelMap,
}

impl ShieldEndpoint {
    fn new(transport: Transport, clock: link::shield::emulator::Clock) -> Self {
        let config = EmulatorConfig::default();
        let channel_map = config.channel_map;
        Self {
            server: EmulatorServer::spawn_simulated(transport, config, clock),
            channel_map,
        }
    }
}

impl Endpoint for ShieldEndpoint {
    fn init(&mut self, vehicle: &mut Vehicle) {
        vehicle.set_mode(FlightMode::AltHold); // Naza ATTI: attitude plus altitude hold
    }

    fn control(&mut self, now: Duration, vehicle: &mut Vehicle) {
        self.server.tick(now);
        let (outputs, armed) = self.server.with(|e| (e.outputs(), e.flags().armed));
        let sticks = outputs.map_or(Sticks::CENTRED, |p| self.channel_map.sticks(&p));
        vehicle.set_sticks(sticks);
        if armed != vehicle.state().armed {
            vehicle.set_armed(armed);
        }
    }

    fn cut(&mut self) {
        self.server.disconnect();
    }

    fn report(
        &mut self,
        _now: Duration,
        _vehicle: &mut Vehicle,
        readings: &Readings,
        events: &[VehicleEvent],
    ) {
        let sensors = ShieldSensors {
            sonar_mm: readings
                .sonar
                .map(|d| (d * 1000.0).round().clamp(0.0, 65534.0) as u16),
            yaw_cdeg: (readings.yaw.to_degrees() * 100.0)
                .round()
                .clamp(-18000.0, 18000.0) as i16,
            battery_mv: (readings.battery_v * 1000.0).round().clamp(0.0, 65535.0) as u16,
        };
        self.server.with(|e| {
            e.set_sensors(sensors);
            for ev in events {
                match ev {
                    VehicleEvent::Collision(p) => e.report(&format!(
                        "collision at ({:.2}, {:.2}, {:.2})",
                        p[0], p[1], p[2]
                    )),
                    VehicleEvent::BatterySwapped => e.report("battery replaced"),
                    VehicleEvent::Landed | VehicleEvent::TookOff => {}
                }
            }
        });
    }
}

/// Frames in and bytes out of one MAVLink endpoint's I/O thread.
#[derive(Default)]
struct Mailbox {
    inbox: Vec<RawFrame>,
    outbox: Vec<u8>,
    connected: bool,
}

/// The ArduCopter-like autopilot; its I/O runs on its own thread, its logic on the physics
/// thread.
struct MavlinkEndpoint {
    autopilot: Autopilot,
    mailbox: Arc<Mutex<Mailbox>>,
    /// The link died: frames are neither taken nor sent.
    cut: bool,
}

/// Largest number of received frames waiting for the physics thread.
const MAX_INBOX: usize = 4096;

impl MavlinkEndpoint {
    fn start(
        mut transport: Transport,
        config: AutopilotConfig,
        shared: Arc<Shared>,
    ) -> (Self, Option<JoinHandle<()>>) {
        let mailbox = Arc::new(Mutex::new(Mailbox::default()));
        let mb = mailbox.clone();
        let name = format!("sitl-mavlink-{}", config.system_id);
        let thread = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || {
                run_sessions(
                    &mut transport,
                    &shared.stop,
                    |up| {
                        let mut m = mb.lock().unwrap_or_else(PoisonError::into_inner);
                        m.connected = up;
                        m.outbox.clear();
                    },
                    |conn| {
                        let (rx_box, tx_box) = (mb.clone(), mb.clone());
                        let stop_r = shared.clone();
                        let stop_w = shared.clone();
                        duplex(
                            conn,
                            &name,
                            move |mut reader, alive| {
                                let mut scanner = FrameScanner::new();
                                let mut buf = [0u8; 2048];
                                while alive.load(Ordering::Relaxed)
                                    && !stop_r.stop.load(Ordering::Relaxed)
                                {
                                    match reader.read(&mut buf) {
                                        Ok(0) => {}
                                        Ok(n) => {
                                            scanner.push(&buf[..n]);
                                            let mut m = rx_box
                                                .lock()
                                                .unwrap_or_else(PoisonError::into_inner);
                                            while let Some(f) = scanner.next_frame() {
                                                if m.inbox.len() < MAX_INBOX {
                                                    m.inbox.push(f);
                                                }
                                            }
                                        }
                                        Err(e) if is_timeout(&e) => {}
                                        Err(e) => {
                                            tracing::debug!("MAVLink endpoint read ended: {e}");
                                            return;
                                        }
                                    }
                                }
                            },
                            move |mut writer, alive| {
                                while alive.load(Ordering::Relaxed)
                                    && !stop_w.stop.load(Ordering::Relaxed)
                                {
                                    let out = std::mem::take(
                                        &mut tx_box
                                            .lock()
                                            .unwrap_or_else(PoisonError::into_inner)
                                            .outbox,
                                    );
                                    if !out.is_empty()
                                        && let Err(e) = writer.write_all(&out)
                                    {
                                        tracing::debug!("MAVLink endpoint write ended: {e}");
                                        return;
                                    }
                                    std::thread::sleep(Duration::from_millis(2));
                                }
                            },
                        );
                    },
                );
            })
            .ok();
        (
            Self {
                autopilot: Autopilot::new(config),
                mailbox,
                cut: false,
            },
            thread,
        )
    }
}

impl Endpoint for MavlinkEndpoint {
    fn init(&mut self, vehicle: &mut Vehicle) {
        vehicle.set_mode(FlightMode::Stabilize); // ArduCopter boots in STABILIZE
    }

    fn cut(&mut self) {
        self.cut = true;
    }

    fn rc_stats(&self) -> Option<RcStats> {
        Some(self.autopilot.rc_stats().clone())
    }

    fn control(&mut self, now: Duration, vehicle: &mut Vehicle) {
        let frames = std::mem::take(
            &mut self
                .mailbox
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .inbox,
        );
        if self.cut {
            return;
        }
        for f in &frames {
            self.autopilot.handle(now, f, vehicle);
        }
    }

    fn report(
        &mut self,
        now: Duration,
        vehicle: &mut Vehicle,
        readings: &Readings,
        events: &[VehicleEvent],
    ) {
        self.autopilot.update(now, vehicle, readings, events);
        let out = self.autopilot.take_output();
        let mut m = self.mailbox.lock().unwrap_or_else(PoisonError::into_inner);
        if m.connected && !self.cut && m.outbox.len() < 1 << 20 {
            m.outbox.extend(out);
        }
    }
}

/// The physics loop: inputs, a tick of physics, reports, cameras; paced to `speed`.
fn physics(shared: &Shared, mut endpoints: Vec<Box<dyn Endpoint>>, speed: f64) {
    let mut start = Instant::now();
    let mut last_report = (Instant::now(), Duration::ZERO);
    while !shared.stop.load(Ordering::Relaxed) {
        for k in std::mem::take(&mut *shared.cut.lock().unwrap_or_else(PoisonError::into_inner)) {
            if let Some(e) = endpoints.get_mut(k) {
                tracing::info!(vehicle = k, "link cut");
                e.cut();
            }
        }
        let (frames, now) = {
            let mut sim = shared.sim.lock().unwrap_or_else(PoisonError::into_inner);
            let now = sim.time() + TICK;
            for (k, e) in endpoints.iter_mut().enumerate() {
                e.control(now, sim.vehicle_mut(k));
            }
            sim.step(TICK);
            for (k, e) in endpoints.iter_mut().enumerate() {
                let events = sim.vehicle_mut(k).take_events();
                let readings = sim.sense(k);
                if let Some(r) = readings {
                    e.report(now, sim.vehicle_mut(k), &r, &events);
                }
            }
            let due = sim.due_cameras();
            if now.as_millis().is_multiple_of(1000) {
                *shared
                    .rc_stats
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner) =
                    endpoints.iter().map(|e| e.rc_stats()).collect();
            }
            (sim.camera_shots(&due), now)
        };
        // Rendered without holding the simulation, so its users (ground truth, wind) never wait.
        let mut frames = frames.render();
        {
            let dead = shared
                .dead_cameras
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            frames.retain(|f| !dead.contains(&f.frame.vehicle));
        }
        shared
            .time_us
            .store(now.as_micros() as u64, Ordering::Relaxed);
        shared.subscribers.publish(frames);
        if speed.is_finite() {
            let due = start + Duration::from_secs_f64(now.as_secs_f64() / speed);
            let wait = due.saturating_duration_since(Instant::now());
            if !wait.is_zero() {
                std::thread::sleep(wait);
            }
            // Held up (a slow camera subscriber, a loaded machine): carry on at the asked speed
            // from here rather than race to catch up, which would starve the station.
            let behind = Instant::now().saturating_duration_since(due);
            if behind > Duration::from_millis(100) {
                start += behind;
            }
        }
        if last_report.0.elapsed() >= Duration::from_secs(10) {
            let factor =
                (now - last_report.1).as_secs_f64() / last_report.0.elapsed().as_secs_f64();
            tracing::info!(
                "simulated {:.0} s, {factor:.2}× real time",
                now.as_secs_f64()
            );
            last_report = (Instant::now(), now);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::TcpListener;

    #[test]
    fn endpoint_specs_parse_and_explain_mistakes() {
        let e: EndpointSpec = "mavlink@tcpin:127.0.0.1:5760".parse().unwrap();
        assert_eq!(e.protocol, Protocol::Mavlink);
        let e: EndpointSpec = "shield@tcpin:127.0.0.1:5800".parse().unwrap();
        assert_eq!(e.protocol, Protocol::Shield);
        assert!(
            "tcpin:127.0.0.1:5760"
                .parse::<EndpointSpec>()
                .unwrap_err()
                .contains("PROTOCOL@ADDRESS")
        );
        assert!(
            "px4@tcpin:1.2.3.4:5"
                .parse::<EndpointSpec>()
                .unwrap_err()
                .contains("unknown protocol 'px4'")
        );
        assert!("mavlink@tcp:1.2.3.4".parse::<EndpointSpec>().is_err());
    }

    /// Two MAVLink vehicles in the default world at 20× real time, cameras of `w`×`h`.
    fn two_copters(w: u32, h: u32) -> Sitl {
        Sitl::start(SitlConfig {
            world: Arc::new(World::load(crate::world::DEFAULT_WORLD).unwrap()),
            sim: SimConfig {
                camera: Some(crate::Camera::kinect(w, h)),
                ..SimConfig::default()
            },
            vehicles: vec!["mavlink@udpin:127.0.0.1:0".parse().unwrap(); 2],
            camera: None,
            speed: 20.0,
            signing_key: None,
        })
        .unwrap()
    }

    #[test]
    fn runs_faster_than_real_time_and_streams_camera_frames_in_process() {
        let sitl = two_copters(64, 48);
        let frames = sitl.subscribe();
        let t0 = Instant::now();
        let mut seen = [0usize; 2];
        while seen.iter().any(|n| *n < 5) && t0.elapsed() < Duration::from_secs(20) {
            if let Ok(f) = frames.recv_timeout(Duration::from_secs(1)) {
                seen[usize::from(f.frame.vehicle)] += 1;
                assert_eq!(f.frame.depth_mm.len(), 64 * 48);
            }
        }
        assert!(seen.iter().all(|n| *n >= 5), "{seen:?}");
        // 5 frames at 10 Hz is 0.5 s of simulated time; at 20× that takes 25 ms.
        let factor = sitl.time().as_secs_f64() / t0.elapsed().as_secs_f64();
        assert!(factor > 2.0, "ran at {factor:.1}× real time");
    }

    #[test]
    fn a_killed_camera_sends_nothing_more_while_the_others_go_on() {
        let sitl = two_copters(32, 24);
        sitl.kill_camera(0);
        let frames = sitl.subscribe();
        let mut seen = [0usize; 2];
        while seen[1] < 20 {
            let f = frames.recv_timeout(Duration::from_secs(5)).unwrap();
            seen[usize::from(f.frame.vehicle)] += 1;
        }
        assert_eq!(seen[0], 0, "frames from a dead camera");
        sitl.with_sim(|s| {
            s.vehicle_mut(1).drain_battery(0.2);
            assert_eq!(s.vehicle(1).battery_remaining(), 20);
            s.vehicle_mut(1).drain_battery(0.9); // never recharges
            assert_eq!(s.vehicle(1).battery_remaining(), 20);
        });
    }

    #[test]
    fn a_taken_port_fails_at_start_with_the_vehicle_named() {
        let first = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = first.local_addr().unwrap().port();
        let world = Arc::new(World::load(crate::world::DEFAULT_WORLD).unwrap());
        let err = Sitl::start(SitlConfig {
            world,
            sim: SimConfig::default(),
            vehicles: vec![
                "mavlink@udpin:127.0.0.1:0".parse().unwrap(),
                format!("shield@tcpin:127.0.0.1:{port}").parse().unwrap(),
            ],
            camera: None,
            speed: 1.0,
            signing_key: None,
        })
        .err()
        .unwrap();
        assert!(
            err.to_string()
                .starts_with("vehicle 1: cannot listen on tcpin:127.0.0.1:"),
            "{err}"
        );
    }
}
