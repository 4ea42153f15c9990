//! Cameras for autopilots this simulator does not fly: ArduPilot's SITL, or any MAVLink vehicle
//! whose physics run elsewhere. The bridge listens to each autopilot over MAVLink (as a camera,
//! not a ground station: its heartbeat keeps no GCS failsafe at bay, and it sends no sticks),
//! renders the world at the pose the autopilot reports (`LOCAL_POSITION_NED` and `ATTITUDE`),
//! and serves the frames on the TCP frame stream of `link/CAMERA.md`, as `sitl run --camera`
//! does for its own vehicles. `gcs fly` then reaches such a vehicle like any other.
//!
//! An autopilot reports its position in its own local frame: north, east, down from its origin
//! (ArduPilot: the EKF origin, where it was powered up). [`BridgedVehicle::map_from_local`]
//! places that frame in the world; this simulator's own autopilots report map coordinates, so
//! theirs is the identity.

use std::net::SocketAddr;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use link::mavlink::{MavlinkConfig, MavlinkLink};
use link::{Address, Telemetry, VehicleLink};
use mavlink::dialects::ardupilotmega::MavType;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::render::{Camera, render_frame};
use crate::sim::CameraFrame;
use crate::stream::{self, Subscribers, Subscription};
use crate::vehicle::{VehicleParams, body_from_camera};
use crate::world::World;

/// One autopilot to give a camera: where to reach it and where its local frame lies in the map.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgedVehicle {
    /// Its MAVLink address (e.g. `udpin:127.0.0.1:14551`, one of ArduPilot SITL's outputs).
    pub address: Address,
    /// The autopilot's local frame in the map: x, y (metres) and the map angle of its north
    /// axis (radians, counter-clockwise).
    pub map_from_local: [f64; 3],
}

impl FromStr for BridgedVehicle {
    type Err = String;

    /// `ADDRESS` (an autopilot that reports map coordinates) or `ADDRESS@X,Y,NORTH` with the
    /// origin of its local frame in the map (metres) and the map heading of its north axis
    /// (degrees).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (address, origin) = match s.rsplit_once('@') {
            Some((a, o)) => (a, Some(o)),
            None => (s, None),
        };
        let address = address.parse().map_err(|e| format!("'{s}': {e}"))?;
        let map_from_local = match origin {
            None => [0.0; 3],
            Some(o) => {
                let v: Vec<f64> = o
                    .split(',')
                    .map(|p| p.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| format!("'{s}': after @ expected X,Y,NORTH (metres, degrees)"))?;
                match v[..] {
                    [x, y, north] if v.iter().all(|p| p.is_finite()) => [x, y, north.to_radians()],
                    _ => {
                        return Err(format!(
                            "'{s}': after @ expected three numbers X,Y,NORTH (metres, degrees)"
                        ));
                    }
                }
            }
        };
        Ok(Self {
            address,
            map_from_local,
        })
    }
}

/// What the bridge serves.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    /// The building the cameras see.
    pub world: Arc<World>,
    /// The camera (size, intrinsics, range).
    pub camera: Camera,
    /// Frames per second per vehicle (wall time).
    pub camera_hz: f64,
    /// Seed of the cameras' noise.
    pub seed: u64,
    /// The camera's mount on the body (FLU, metres), as on the simulator's own vehicles.
    pub camera_offset: [f64; 3],
    /// The autopilots, in the order of their camera ids on the stream (0, 1, …).
    pub vehicles: Vec<BridgedVehicle>,
    /// Where the frame stream listens (`tcpin:HOST:PORT`), if anywhere.
    pub stream: Option<Address>,
}

impl BridgeConfig {
    /// A bridge for `vehicles` in `world` with the simulator's camera (Kinect-like, 320×240,
    /// 10 Hz) and mount.
    pub fn new(world: Arc<World>, vehicles: Vec<BridgedVehicle>, stream: Option<Address>) -> Self {
        Self {
            world,
            camera: Camera::kinect(320, 240),
            camera_hz: 10.0,
            seed: 0,
            camera_offset: VehicleParams::default().camera_offset,
            vehicles,
            stream,
        }
    }
}

/// The bridge could not start.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
    /// An autopilot's address could not be opened.
    #[error("vehicle {vehicle} ({address}): {reason}")]
    Vehicle {
        /// 1-based, in the configured order.
        vehicle: usize,
        /// Its address.
        address: Address,
        /// Why.
        reason: String,
    },
    /// The frame stream could not listen.
    #[error("camera stream: {0}")]
    Stream(String),
}

/// Telemetry older than this gives no frame: a camera without a pose is no camera.
const STALE: Duration = Duration::from_secs(1);

/// A running bridge. Dropping it stops rendering, closes the stream and the MAVLink links.
pub struct CameraBridge {
    stop: Arc<AtomicBool>,
    subscribers: Arc<Subscribers>,
    addr: Option<SocketAddr>,
    threads: Vec<JoinHandle<()>>,
}

impl CameraBridge {
    /// Opens every autopilot's link and the frame stream (so a bad address or a taken port
    /// fails here), then renders in the background.
    pub fn start(config: BridgeConfig) -> Result<Self, BridgeError> {
        if !(config.camera_hz.is_finite() && config.camera_hz > 0.0 && config.camera_hz <= 100.0) {
            return Err(BridgeError::Config(format!(
                "camera rate {} Hz must be above 0 and at most 100",
                config.camera_hz
            )));
        }
        if config.vehicles.is_empty() || config.vehicles.len() > 255 {
            return Err(BridgeError::Config(
                "give 1 to 255 autopilots to render cameras for".into(),
            ));
        }
        let mut links = vec![];
        for (k, v) in config.vehicles.iter().enumerate() {
            let link = MavlinkLink::connect(
                &v.address,
                MavlinkConfig {
                    // Another program beside the ground station (255), speaking as a camera.
                    system_id: 254,
                    component_id: 100, // MAV_COMP_ID_CAMERA
                    mav_type: MavType::MAV_TYPE_CAMERA,
                    telemetry_rate_hz: 50.0,
                    ..MavlinkConfig::default()
                },
            )
            .map_err(|e| BridgeError::Vehicle {
                vehicle: k + 1,
                address: v.address.clone(),
                reason: e.to_string(),
            })?;
            links.push(link);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let subscribers = Arc::new(Subscribers::default());
        let mut threads = vec![];
        let addr = match &config.stream {
            None => None,
            Some(address) => {
                let (addr, thread) = stream::listen(address, subscribers.clone(), stop.clone())
                    .map_err(BridgeError::Stream)?;
                threads.push(thread);
                Some(addr)
            }
        };
        let (s, subs) = (stop.clone(), subscribers.clone());
        threads.push(
            std::thread::Builder::new()
                .name("camera-bridge".into())
                .spawn(move || render_loop(&config, &links, &subs, &s))
                .map_err(|e| BridgeError::Config(format!("cannot start rendering: {e}")))?,
        );
        Ok(Self {
            stop,
            subscribers,
            addr,
            threads,
        })
    }

    /// The address the frame stream listens on.
    pub fn camera_addr(&self) -> Option<SocketAddr> {
        self.addr
    }

    /// Every frame from now on (when 4 of a camera's frames wait, its next drops its oldest),
    /// with the pose it was rendered at.
    pub fn subscribe(&self) -> Subscription {
        self.subscribers.add(false, 4)
    }
}

impl Drop for CameraBridge {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The body in the map from what an autopilot reports, if it reports a position and an
/// attitude.
pub fn map_from_body(map_from_local: [f64; 3], t: &Telemetry) -> Option<Isometry3<f64>> {
    let (p, a) = (t.position_m?, t.attitude?);
    let local_from_body = Isometry3::from_parts(
        Translation3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])),
        UnitQuaternion::from_euler_angles(f64::from(a.roll), f64::from(a.pitch), f64::from(a.yaw)),
    );
    let [x, y, north] = map_from_local;
    Some(Isometry3::new(Vector3::new(x, y, 0.0), Vector3::z() * north) * local_from_body)
}

/// How often the autopilots' telemetry is looked at, to time when each pose arrived.
const POLL: Duration = Duration::from_millis(5);

/// A pose is carried forward at most this long: past it the vehicle is taken to stand still.
const MAX_EXTRAPOLATION: Duration = Duration::from_millis(250);

/// Reports closer together than this are parts of one (position and attitude come in separate
/// messages, often a millisecond apart): the motion is measured over a longer span.
const MIN_SPAN: Duration = Duration::from_millis(10);

/// The last two poses an autopilot reported, with when each arrived. Autopilots stream pose at
/// whatever rate the ground station asked for (ArduPilot behind MAVProxy: 4 Hz by default), so
/// a frame rendered at the last reported pose would show the past; the camera renders at the
/// pose carried forward to now at the motion between the last two reports instead.
#[derive(Debug, Default)]
pub struct PoseTrack {
    last: Option<(Instant, Isometry3<f64>)>,
    previous: Option<(Instant, Isometry3<f64>)>,
}

impl PoseTrack {
    /// Records the pose reported now, if it is a new one. A report within [`MIN_SPAN`] of the
    /// last completes it (a new attitude after a new position) instead of following it: carried
    /// forward over a millisecond's span, half an update would read as a leap.
    pub fn observe(&mut self, at: Instant, map_from_body: Isometry3<f64>) {
        match self.last {
            Some((_, p)) if p == map_from_body => {}
            Some((t, _)) if at.saturating_duration_since(t) < MIN_SPAN => {
                self.last = Some((at, map_from_body));
            }
            _ => self.previous = self.last.replace((at, map_from_body)),
        }
    }

    /// The pose at `now`: the last report carried forward at the motion between the last two
    /// (in the body frame, for at most [`MAX_EXTRAPOLATION`]).
    pub fn at(&self, now: Instant) -> Option<Isometry3<f64>> {
        let (t1, p1) = self.last?;
        let Some((t0, p0)) = self.previous else {
            return Some(p1);
        };
        let span = t1.saturating_duration_since(t0).as_secs_f64();
        if span <= 0.0 || span > MAX_EXTRAPOLATION.as_secs_f64() {
            return Some(p1);
        }
        let ahead = now
            .saturating_duration_since(t1)
            .min(MAX_EXTRAPOLATION)
            .as_secs_f64();
        let s = ahead / span;
        let step = p0.inverse() * p1;
        Some(p1 * Isometry3::new(step.translation.vector * s, step.rotation.scaled_axis() * s))
    }
}

/// Renders every vehicle's frame at `camera_hz` until `stop`.
fn render_loop(
    config: &BridgeConfig,
    links: &[MavlinkLink],
    subscribers: &Subscribers,
    stop: &AtomicBool,
) {
    let start = Instant::now();
    let period = Duration::from_secs_f64(1.0 / config.camera_hz);
    let body_from_camera = body_from_camera(config.camera_offset);
    let mut frame_no = 0u64;
    let mut tracks: Vec<PoseTrack> = links.iter().map(|_| PoseTrack::default()).collect();
    let mut waiting = vec![true; links.len()];
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        // Where each vehicle is, as fresh as its telemetry: the first vehicle heard on its
        // link, whose last message is under a second old.
        let mut heard = vec![None; links.len()];
        for (k, (link, v)) in links.iter().zip(&config.vehicles).enumerate() {
            let Some(&id) = link.vehicles().first() else {
                continue;
            };
            let vehicle = link.vehicle(id);
            let fresh = vehicle
                .status()
                .last_message_age
                .is_some_and(|age| age < STALE);
            if let Some(pose) = map_from_body(v.map_from_local, &vehicle.telemetry())
                && fresh
            {
                tracks[k].observe(now, pose);
                heard[k] = Some(id);
            }
        }
        let due = start + period.mul_f64(frame_no as f64);
        if now < due {
            std::thread::sleep(POLL.min(due - now));
            continue;
        }
        let stamp = start.elapsed();
        let mut frames = vec![];
        for (k, v) in config.vehicles.iter().enumerate() {
            let (Some(id), Some(map_from_body)) = (heard[k], tracks[k].at(now)) else {
                continue;
            };
            if std::mem::take(&mut waiting[k]) {
                tracing::info!("camera {k}: rendering for system {id} on {}", v.address);
            }
            let map_from_camera = map_from_body * body_from_camera;
            frames.push(CameraFrame {
                frame: render_frame(
                    &config.world,
                    &map_from_camera,
                    &config.camera,
                    Some((config.seed.wrapping_add(k as u64), frame_no)),
                    k as u8,
                    stamp,
                ),
                map_from_camera,
            });
        }
        subscribers.publish(frames);
        frame_no += 1;
        // Fell behind (a slow machine): carry on from now rather than race to catch up.
        let behind =
            Instant::now().saturating_duration_since(start + period.mul_f64(frame_no as f64));
        if behind > period {
            frame_no += (behind.as_secs_f64() / period.as_secs_f64()) as u64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use link::Attitude;

    #[test]
    fn vehicles_parse_with_or_without_their_local_frame() {
        let v: BridgedVehicle = "udpin:127.0.0.1:14551".parse().unwrap();
        assert_eq!(v.map_from_local, [0.0; 3]);
        let v: BridgedVehicle = "tcpout:127.0.0.1:5762@13.1,2.5,90".parse().unwrap();
        assert_eq!(v.address, "tcpout:127.0.0.1:5762".parse().unwrap());
        assert!((v.map_from_local[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let e = "tcpout:127.0.0.1:5762@13.1,2.5"
            .parse::<BridgedVehicle>()
            .unwrap_err();
        assert!(e.contains("three numbers X,Y,NORTH"), "{e}");
        let e = "tcpout:127.0.0.1:5762@a,b,c"
            .parse::<BridgedVehicle>()
            .unwrap_err();
        assert!(e.contains("X,Y,NORTH"), "{e}");
        assert!("radio:5762".parse::<BridgedVehicle>().is_err());
    }

    #[test]
    fn a_reported_pose_is_placed_by_the_local_frame() {
        let t = Telemetry {
            position_m: Some([1.0, 0.0, 1.2]),
            attitude: Some(Attitude {
                roll: 0.0,
                pitch: 0.0,
                yaw: 0.3,
            }),
            ..Telemetry::default()
        };
        // North along the map's y axis, origin at (5, 2): one metre north is (5, 3).
        let p = map_from_body([5.0, 2.0, std::f64::consts::FRAC_PI_2], &t).unwrap();
        let v = p.translation.vector;
        assert!((v - Vector3::new(5.0, 3.0, 1.2)).norm() < 1e-6, "{v}");
        let yaw = p.rotation.euler_angles().2;
        assert!(
            (yaw - (0.3 + std::f64::consts::FRAC_PI_2)).abs() < 1e-6,
            "{yaw}"
        );
        // No attitude yet: no pose.
        let t = Telemetry {
            attitude: None,
            ..t
        };
        assert!(map_from_body([0.0; 3], &t).is_none());
    }

    #[test]
    fn a_pose_is_carried_forward_at_the_motion_between_the_last_two_reports() {
        let t0 = Instant::now();
        let mut track = PoseTrack::default();
        assert!(track.at(t0).is_none());
        // Turning at 1 rad/s while flying 1 m/s forward, reported at 10 Hz.
        let pose = |t: f64| Isometry3::new(Vector3::new(t, 0.0, 1.0), Vector3::z() * t);
        track.observe(t0, pose(0.0));
        assert_eq!(track.at(t0 + Duration::from_millis(50)), Some(pose(0.0)));
        let t1 = t0 + Duration::from_millis(100);
        track.observe(t1, pose(0.1));
        // The same report again is no news.
        track.observe(t1 + Duration::from_millis(20), pose(0.1));
        let p = track.at(t1 + Duration::from_millis(50)).unwrap();
        let yaw = p.rotation.euler_angles().2;
        assert!((yaw - 0.15).abs() < 1e-9, "{yaw}");
        assert!((p.translation.x - 0.15).abs() < 0.01, "{}", p.translation);
        // A vehicle whose reports stopped is not carried off for ever.
        let far = track.at(t1 + Duration::from_secs(5)).unwrap();
        assert!((far.rotation.euler_angles().2 - 0.35).abs() < 1e-9);
    }

    #[test]
    fn a_position_and_an_attitude_a_millisecond_apart_are_one_report() {
        // The same motion reported at 50 Hz, position first and the attitude 1 ms later.
        let t0 = Instant::now();
        let ms = |m: u64| t0 + Duration::from_millis(m);
        let mut track = PoseTrack::default();
        let pose = |x: f64, yaw: f64| Isometry3::new(Vector3::new(x, 0.0, 1.0), Vector3::z() * yaw);
        track.observe(ms(0), pose(0.0, 0.0));
        track.observe(ms(20), pose(0.02, 0.0));
        track.observe(ms(21), pose(0.02, 0.02));
        // 10 ms on, the vehicle has moved 0.01 m and turned 0.01 rad more, not 0.1 m (the
        // position step carried over the attitude's 1 ms span) or 0.2 rad.
        let p = track.at(ms(31)).expect("a pose");
        let yaw = p.rotation.euler_angles().2;
        assert!((yaw - 0.03).abs() < 0.003, "{yaw}");
        assert!((p.translation.x - 0.03).abs() < 0.003, "{}", p.translation);
    }
}
