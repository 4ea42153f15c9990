//! Everything the mission sees and does, recorded to MCAP with Foxglove's schemas so Foxglove
//! opens the log as it is: camera frames (`foxglove.CompressedImage`, colour as JPEG, depth as
//! 16-bit PNG in millimetres, with `foxglove.CameraCalibration`, and the simulator's true camera
//! pose as `foxglove.PoseInFrame` when there is one), every drone's telemetry, link
//! state, RC sticks and phase (JSON), its pose (`foxglove.PoseInFrame`, and `foxglove.FrameTransform`
//! on `/tf`), the 2D map (`foxglove.Grid`), the occupied voxels (`foxglove.PointCloud`), the
//! planner's decisions (JSON) and the operator's commands (`foxglove.Log`).
//!
//! A writer thread takes records from a queue and closes a zstd chunk every second, so a crash
//! loses at most the last second: the file reads back up to the last closed chunk.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use foxglove::Encode;
use foxglove::messages::{
    CameraCalibration, CompressedImage, FrameTransform, Grid as FoxGrid, Log, PackedElementField,
    PointCloud, Pose, PoseInFrame, Quaternion, Timestamp, Vector2, Vector3, log::Level,
    packed_element_field::NumericType,
};
use link::camera::RgbdFrame;
use link::{Sticks, Telemetry};
use nav::grid::{Cell, Grid};
use serde::{Deserialize, Serialize};

/// What the log was recorded with, for replay: written once at the start on `/setup`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// Format version of the log.
    pub version: u32,
    /// The world, when simulated.
    pub world: Option<String>,
    /// Assignment strategy.
    pub strategy: String,
    /// The planner's robot radii, tried widest first (absent from older logs).
    #[serde(default)]
    pub planner_radii: Vec<f64>,
    /// The planner's region radius, metres (absent from logs recorded before regions: 0, off).
    #[serde(default)]
    pub region_radius_m: Option<f64>,
    /// What a drone's held goal was worth in the assignment, metres (absent from older logs,
    /// whose plans held no goal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_margin_m: Option<f64>,
    /// Frontiers onto enclosed pockets of unknown up to this area were not explored, m²
    /// (absent from older logs, which explored every frontier).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_pocket_m2: Option<f64>,
    /// What turning on the spot to face a path cost a drone in the assignment, metres per
    /// radian (absent from older logs, whose plans weighed paths alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_m_per_rad: Option<f64>,
    /// How far short of another drone's frontier a drone without one waited, metres (absent
    /// from older logs, whose drones without a frontier hovered).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage_back_m: Option<f64>,
    /// Whether paths at a thinner radius kept the widest one's distance from the walls where
    /// they could (`nav::mission::centring_comfort`; absent from older logs, whose paths were
    /// shortest at every radius).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub centre_paths: Option<bool>,
    /// How far paths kept from the unknown where they could, metres
    /// (`nav::mission::PlannerConfig::unknown_comfort_m`; absent from older logs, whose paths
    /// kept nothing more from it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unknown_comfort_m: Option<f64>,
    /// The drones.
    pub drones: Vec<SetupDrone>,
}

/// One drone in [`Setup`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetupDrone {
    /// Display name.
    pub name: String,
    /// Start in the map (x, y, yaw), when known.
    pub start: Option<[f64; 3]>,
    /// The camera on the body: x, y, z, qx, qy, qz, qw.
    pub body_from_camera: [f64; 7],
    /// Altitude band, metres.
    pub altitude: f64,
}

impl SetupDrone {
    /// A drone as recorded, with its camera mount as an isometry.
    pub fn new(
        name: &str,
        start: Option<[f64; 3]>,
        body_from_camera: &nalgebra::Isometry3<f64>,
        altitude: f64,
    ) -> Self {
        let (t, q) = (
            body_from_camera.translation.vector,
            body_from_camera.rotation,
        );
        Self {
            name: name.to_owned(),
            start,
            body_from_camera: [t.x, t.y, t.z, q.i, q.j, q.k, q.w],
            altitude,
        }
    }
}

/// The state of one drone at one control tick, as written on `/droneK/state`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DroneState {
    /// Mission clock, seconds.
    pub t: f64,
    /// Phase name.
    pub phase: String,
    /// Height from the rangefinder, metres.
    pub height_m: Option<f32>,
    /// IMU heading, radians.
    pub yaw_rad: Option<f32>,
    /// When the heading arrived, mission clock, seconds (absent from older logs, and for a
    /// link that does not stamp it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_t: Option<f64>,
    /// Roll, pitch, yaw from the flight controller, radians.
    pub attitude: Option<[f32; 3]>,
    /// Battery voltage, volts.
    pub battery_v: Option<f32>,
    /// Battery charge, percent.
    pub battery_pct: Option<u8>,
    /// Armed as the vehicle says.
    pub armed: Option<bool>,
    /// Flight mode as the vehicle says.
    pub mode: Option<String>,
    /// Sticks sent (roll, pitch, yaw, throttle), −1…1.
    pub sticks: Option<[f32; 4]>,
    /// The filter's pose (x, y, z, yaw), if valid.
    pub pose: Option<[f64; 4]>,
    /// The horizontal standard deviation of `pose`, metres (absent from older logs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_sigma_m: Option<f64>,
    /// The filter's roll and pitch, radians (what the SLAM checked registrations against;
    /// absent from older logs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tilt: Option<[f64; 2]>,
    /// The nearest wall the drone keeps in mind, from its camera's ranges and, while it had a
    /// pose, the map's (what it leans off when it has no pose), metres; absent from older
    /// logs, and when none is near.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nearest_wall_m: Option<f64>,
    /// Where the position controller pulled it (x, y, map frame: its path's carrot or the spot
    /// it holds, kept off the walls), while it flew on a pose; absent from older logs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setpoint: Option<[f64; 2]>,
}

/// One exploring drone in a planner decision, as written on `/plan` (`drone` 1-based there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedGoal {
    /// The drone (0-based here; 1-based in the log).
    #[serde(serialize_with = "one_based", deserialize_with = "from_one_based")]
    pub drone: usize,
    /// Where the planner had it (x, y), `None` without a valid pose.
    #[serde(default)]
    pub position: Option<[f64; 2]>,
    /// The goal it flew to when the planner was called, which it kept unless another was
    /// cheaper by the hold margin ([`Setup::hold_margin_m`]; absent from older logs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held: Option<[f64; 2]>,
    /// The way it faced (radians, map frame), from which a path setting off behind it cost a
    /// turn ([`Setup::turn_m_per_rad`]); absent while it looked around, and from older logs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading: Option<f64>,
    /// The frontier goal it was given, if any.
    pub goal: Option<[f64; 2]>,
    /// The path planned to it (x, y waypoints, map frame), which it then followed; absent from
    /// older logs and without a goal.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub path: Vec<[f64; 2]>,
}

fn one_based<S: serde::Serializer>(k: &usize, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_u64(*k as u64 + 1)
}

fn from_one_based<'de, D: serde::Deserializer<'de>>(d: D) -> Result<usize, D::Error> {
    let k = u64::deserialize(d)?;
    usize::try_from(k)
        .ok()
        .and_then(|k| k.checked_sub(1))
        .ok_or_else(|| serde::de::Error::custom(format!("drone {k}: drones count from 1")))
}

/// One thing to record.
#[derive(Debug, Clone)]
pub enum Record {
    /// The setup (first).
    Setup(Setup),
    /// A camera frame of a drone.
    Camera {
        /// Mission clock, seconds.
        t: f64,
        /// The drone.
        drone: usize,
        /// The frame.
        frame: Arc<RgbdFrame>,
        /// The camera's true pose in the map, when a simulator knows it (written on
        /// `/droneK/camera/truth`, so a replay can map on it and evaluations can use it).
        truth: Option<nalgebra::Isometry3<f64>>,
    },
    /// A drone's control tick.
    Drone {
        /// Mission clock, seconds.
        t: f64,
        /// The drone.
        drone: usize,
        /// Its telemetry.
        telemetry: Telemetry,
        /// Sticks sent.
        sticks: Option<Sticks>,
        /// The filter's pose.
        pose: Option<[f64; 4]>,
        /// Its horizontal standard deviation, metres.
        pose_sigma_m: Option<f64>,
        /// The filter's roll and pitch.
        tilt: Option<[f64; 2]>,
        /// The nearest wall it keeps in mind ([`nav::proximity::Proximity::nearest`]), metres.
        nearest_wall_m: Option<f64>,
        /// Where the position controller pulled it, while it flew on a pose.
        setpoint: Option<[f64; 2]>,
        /// Its phase.
        phase: &'static str,
    },
    /// The 2D map.
    Grid {
        /// Mission clock, seconds.
        t: f64,
        /// The map.
        grid: Arc<Grid>,
    },
    /// Occupied voxel centres (x, y, z).
    Cloud {
        /// Mission clock, seconds.
        t: f64,
        /// The points, metres.
        points: Vec<[f64; 3]>,
    },
    /// A planner decision, with what it was made from besides the map (recorded on `/map` at
    /// the same time), so that a replay can make it again.
    Plan {
        /// Mission clock, seconds.
        t: f64,
        /// Per exploring drone, where it was and the goal it was given.
        goals: Vec<PlannedGoal>,
        /// The frontiers' goal points.
        frontiers: Vec<[f64; 2]>,
        /// The goals given up so far (the planner skips frontiers near them).
        given_up: Vec<[f64; 2]>,
    },
    /// A text message from a vehicle (MAVLink `STATUSTEXT`, the shield's reports).
    VehicleText {
        /// Mission clock, seconds.
        t: f64,
        /// The drone.
        drone: usize,
        /// The message.
        text: link::StatusText,
    },
    /// An operator command.
    Operator {
        /// Mission clock, seconds.
        t: f64,
        /// The command.
        command: String,
    },
    /// What the station told the operator ("drone 2: battery at 35 %: returning to its
    /// start", "no reachable frontier left …"), written on `/station`.
    StationText {
        /// Mission clock, seconds.
        t: f64,
        /// A warning (a fault) rather than news.
        warning: bool,
        /// The message.
        text: String,
    },
}

enum Message {
    /// Boxed: the queue holds hundreds, most far smaller than the largest record.
    Record(Box<Record>),
    Finish,
}

/// Counters of a recording.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecordStats {
    /// Messages written.
    pub messages: u64,
    /// Records dropped because the writer fell behind.
    pub dropped: u64,
    /// Bytes in the file when it was closed.
    pub bytes: u64,
}

struct Inner {
    path: PathBuf,
    /// Camera frames are kept at most this often per drone, seconds (0: every frame; infinite:
    /// none).
    camera_period: f64,
    /// Per drone, the stamp of the last camera frame kept.
    last_camera: Mutex<Vec<f64>>,
    thread: Mutex<Option<JoinHandle<Result<RecordStats, String>>>>,
    dropped: AtomicU64,
    result: Mutex<Option<Result<RecordStats, String>>>,
}

/// A recording in progress; clones share it.
#[derive(Clone)]
pub struct Recorder {
    tx: SyncSender<Message>,
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Recorder({})", self.inner.path.display())
    }
}

impl Recorder {
    /// Creates the file and starts the writer; camera frames are recorded at most
    /// `camera_hz` times a second per drone (`None`: every frame; 0: none — what replay needs
    /// goes with them, the rest of the log stays whole). Colour and depth are about 1 MB per
    /// drone per second at 10 Hz.
    pub fn create(path: &Path, camera_hz: Option<f64>) -> anyhow::Result<Self> {
        let camera_period = match camera_hz {
            None => 0.0,
            Some(hz) if hz.is_finite() && hz >= 0.0 => 1.0 / hz,
            Some(hz) => anyhow::bail!("camera log rate {hz} Hz must be 0 or more"),
        };
        let file = File::create(path)
            .map_err(|e| anyhow::anyhow!("cannot create the log {}: {e}", path.display()))?;
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(concat!("gcs ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| anyhow::anyhow!("cannot start the log {}: {e}", path.display()))?;
        // Room for a few seconds of everything; a writer further behind drops records.
        let (tx, rx) = sync_channel(512);
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_all(writer, &rx))?;
        Ok(Self {
            tx,
            inner: Arc::new(Inner {
                path: path.to_owned(),
                camera_period,
                last_camera: Mutex::new(vec![]),
                thread: Mutex::new(Some(thread)),
                dropped: AtomicU64::new(0),
                result: Mutex::new(None),
            }),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.inner.path
    }

    /// Queues a record (never blocks: when the writer is far behind, the record is dropped and
    /// counted).
    pub fn send(&self, record: Record) {
        if let Record::Camera { t, drone, .. } = &record
            && !self.keep_camera(*drone, *t)
        {
            return;
        }
        if let Err(TrySendError::Full(_)) = self.tx.try_send(Message::Record(Box::new(record))) {
            self.inner.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Whether drone `drone`'s camera frame at `t` is due under the camera log rate.
    fn keep_camera(&self, drone: usize, t: f64) -> bool {
        let period = self.inner.camera_period;
        if period == 0.0 {
            return true;
        }
        if period.is_infinite() {
            return false;
        }
        let mut last = self
            .inner
            .last_camera
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if last.len() <= drone {
            last.resize(drone + 1, f64::NEG_INFINITY);
        }
        // A little slack, so that 2 Hz of a 10 Hz camera is every fifth frame.
        if t - last[drone] < period - 1e-3 {
            return false;
        }
        last[drone] = t;
        true
    }

    /// Writes what is queued, closes the file and returns the counters (the first caller does
    /// the work; later callers get the same result).
    pub fn finish(&mut self) -> Result<RecordStats, String> {
        let thread = self
            .inner
            .thread
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        let mut result = self
            .inner
            .result
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some(t) = thread {
            let _ = self.tx.send(Message::Finish);
            let r = t
                .join()
                .unwrap_or_else(|_| Err("the recorder thread panicked".into()))
                .map(|s| RecordStats {
                    dropped: self.inner.dropped.load(Ordering::Relaxed),
                    bytes: std::fs::metadata(&self.inner.path).map_or(0, |m| m.len()),
                    ..s
                });
            *result = Some(r);
        }
        result
            .clone()
            .unwrap_or_else(|| Err("the recording never started".into()))
    }
}

/// The writer's channels by topic.
struct Channels {
    schemas: HashMap<String, u16>,
    topics: HashMap<String, u16>,
    sequence: u32,
}

type McapWriter = mcap::Writer<BufWriter<File>>;

impl Channels {
    /// The channel of `topic` with a Foxglove message type.
    fn foxglove<T: Encode>(&mut self, w: &mut McapWriter, topic: &str) -> Result<u16, String> {
        if let Some(&c) = self.topics.get(topic) {
            return Ok(c);
        }
        let schema = T::get_schema().ok_or("a Foxglove type without a schema")?;
        let schema_id = match self.schemas.get(&schema.name) {
            Some(&s) => s,
            None => {
                let s = w
                    .add_schema(&schema.name, &schema.encoding, &schema.data)
                    .map_err(|e| e.to_string())?;
                self.schemas.insert(schema.name.clone(), s);
                s
            }
        };
        let c = w
            .add_channel(
                schema_id,
                topic,
                &T::get_message_encoding(),
                &BTreeMap::new(),
            )
            .map_err(|e| e.to_string())?;
        self.topics.insert(topic.to_owned(), c);
        Ok(c)
    }

    /// The channel of `topic` carrying JSON of the named schema.
    fn json(&mut self, w: &mut McapWriter, topic: &str, name: &str) -> Result<u16, String> {
        if let Some(&c) = self.topics.get(topic) {
            return Ok(c);
        }
        let schema_id = match self.schemas.get(name) {
            Some(&s) => s,
            None => {
                let s = w
                    .add_schema(name, "jsonschema", br#"{"type":"object"}"#)
                    .map_err(|e| e.to_string())?;
                self.schemas.insert(name.to_owned(), s);
                s
            }
        };
        let c = w
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| e.to_string())?;
        self.topics.insert(topic.to_owned(), c);
        Ok(c)
    }

    fn write(
        &mut self,
        w: &mut McapWriter,
        channel: u16,
        t: f64,
        data: &[u8],
    ) -> Result<(), String> {
        self.sequence = self.sequence.wrapping_add(1);
        let ns = log_time(t);
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: self.sequence,
                log_time: ns,
                publish_time: ns,
            },
            data,
        )
        .map_err(|e| e.to_string())
    }
}

fn encode<T: Encode>(m: &T) -> Result<Vec<u8>, String> {
    let mut buf = Vec::with_capacity(m.encoded_len().unwrap_or(256));
    m.encode(&mut buf).map_err(|e| e.to_string())?;
    Ok(buf)
}

/// A mission time (seconds) as an MCAP log time: nanoseconds, the nearest.
pub(crate) fn log_time(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}

/// A mission time (seconds) as a message's header stamp: the very nanosecond of its log time.
fn stamp(t: f64) -> Option<Timestamp> {
    let ns = log_time(t);
    let seconds = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Some(Timestamp::new(seconds, (ns % 1_000_000_000) as u32))
}

fn quaternion_of_yaw(yaw: f64) -> Quaternion {
    let (s, c) = (yaw / 2.0).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

fn write_all(mut w: McapWriter, rx: &Receiver<Message>) -> Result<RecordStats, String> {
    let mut channels = Channels {
        schemas: HashMap::new(),
        topics: HashMap::new(),
        sequence: 0,
    };
    let mut stats = RecordStats::default();
    let mut last_flush = Instant::now();
    let mut first_error: Option<String> = None;
    loop {
        let message = rx.recv_timeout(Duration::from_millis(200));
        match message {
            Ok(Message::Record(r)) => match write_record(&mut w, &mut channels, &r) {
                Ok(n) => stats.messages += n,
                Err(e) => {
                    if first_error.is_none() {
                        tracing::error!("recording: {e}");
                    }
                    first_error.get_or_insert(e);
                }
            },
            Ok(Message::Finish) | Err(RecvTimeoutError::Disconnected) => break,
            Err(RecvTimeoutError::Timeout) => {}
        }
        // Close the chunk once a second: a crash loses at most that.
        if last_flush.elapsed() >= Duration::from_secs(1) {
            w.flush().map_err(|e| e.to_string())?;
            last_flush = Instant::now();
        }
    }
    w.finish().map_err(|e| e.to_string())?;
    match first_error {
        Some(e) => Err(e),
        None => Ok(stats),
    }
}

/// Writes one record; returns the number of messages.
fn write_record(w: &mut McapWriter, ch: &mut Channels, r: &Record) -> Result<u64, String> {
    match r {
        Record::Setup(setup) => {
            let c = ch.json(w, "/setup", "gcs.Setup")?;
            let data = serde_json::to_vec(setup).map_err(|e| e.to_string())?;
            ch.write(w, c, 0.0, &data)?;
            Ok(1)
        }
        Record::Camera {
            t,
            drone,
            frame,
            truth,
        } => {
            let k = drone + 1;
            let frame_id = format!("drone{k}_camera");
            let colour = image::RgbImage::from_raw(frame.width, frame.height, frame.rgb.clone())
                .ok_or("camera frame of the wrong size")?;
            let mut jpeg = vec![];
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
                .encode_image(&colour)
                .map_err(|e| e.to_string())?;
            let depth = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(
                frame.width,
                frame.height,
                frame.depth_mm.clone(),
            )
            .ok_or("depth image of the wrong size")?;
            let mut png = vec![];
            depth
                .write_with_encoder(image::codecs::png::PngEncoder::new_with_quality(
                    &mut png,
                    image::codecs::png::CompressionType::Fast,
                    image::codecs::png::FilterType::Sub,
                ))
                .map_err(|e| e.to_string())?;
            for (topic, data, format) in [
                (format!("/drone{k}/camera/color"), jpeg, "jpeg"),
                (format!("/drone{k}/camera/depth"), png, "png"),
            ] {
                let c = ch.foxglove::<CompressedImage>(w, &topic)?;
                let m = CompressedImage {
                    timestamp: stamp(*t),
                    frame_id: frame_id.clone(),
                    data: data.into(),
                    format: format.into(),
                };
                ch.write(w, c, *t, &encode(&m)?)?;
            }
            let slam::dataset::Pinhole { fx, fy, cx, cy } =
                crate::runtime::perception::pinhole(&frame.intrinsics);
            let c =
                ch.foxglove::<CameraCalibration>(w, &format!("/drone{k}/camera/calibration"))?;
            let m = CameraCalibration {
                timestamp: stamp(*t),
                frame_id,
                width: frame.width,
                height: frame.height,
                distortion_model: "plumb_bob".into(),
                d: vec![0.0; 5],
                k: vec![fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                p: vec![fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
            };
            ch.write(w, c, *t, &encode(&m)?)?;
            let Some(pose) = truth else {
                return Ok(3);
            };
            let (v, q) = (pose.translation.vector, pose.rotation);
            let c = ch.foxglove::<PoseInFrame>(w, &format!("/drone{k}/camera/truth"))?;
            let m = PoseInFrame {
                timestamp: stamp(*t),
                frame_id: "map".into(),
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: v.x,
                        y: v.y,
                        z: v.z,
                    }),
                    orientation: Some(Quaternion {
                        x: q.i,
                        y: q.j,
                        z: q.k,
                        w: q.w,
                    }),
                }),
            };
            ch.write(w, c, *t, &encode(&m)?)?;
            Ok(4)
        }
        Record::Drone {
            t,
            drone,
            telemetry,
            sticks,
            pose,
            pose_sigma_m,
            tilt,
            nearest_wall_m,
            setpoint,
            phase,
        } => {
            let k = drone + 1;
            let state = DroneState {
                t: *t,
                phase: (*phase).into(),
                height_m: telemetry.height_m,
                yaw_rad: telemetry.yaw_rad,
                heading_t: telemetry.heading_at.map(|at| at.as_secs_f64()),
                attitude: telemetry.attitude.map(|a| [a.roll, a.pitch, a.yaw]),
                battery_v: telemetry.battery.map(|b| b.voltage_v),
                battery_pct: telemetry.battery.and_then(|b| b.remaining_pct),
                armed: telemetry.armed,
                mode: telemetry.mode.clone(),
                sticks: sticks.map(|s| [s.roll, s.pitch, s.yaw, s.throttle]),
                pose: *pose,
                pose_sigma_m: *pose_sigma_m,
                tilt: *tilt,
                nearest_wall_m: *nearest_wall_m,
                setpoint: *setpoint,
            };
            let c = ch.json(w, &format!("/drone{k}/state"), "gcs.DroneState")?;
            ch.write(
                w,
                c,
                *t,
                &serde_json::to_vec(&state).map_err(|e| e.to_string())?,
            )?;
            let Some(p) = pose else {
                return Ok(1);
            };
            let position = Some(Vector3 {
                x: p[0],
                y: p[1],
                z: p[2],
            });
            let c = ch.foxglove::<PoseInFrame>(w, &format!("/drone{k}/pose"))?;
            let m = PoseInFrame {
                timestamp: stamp(*t),
                frame_id: "map".into(),
                pose: Some(Pose {
                    position,
                    orientation: Some(quaternion_of_yaw(p[3])),
                }),
            };
            ch.write(w, c, *t, &encode(&m)?)?;
            let c = ch.foxglove::<FrameTransform>(w, "/tf")?;
            let m = FrameTransform {
                timestamp: stamp(*t),
                parent_frame_id: "map".into(),
                child_frame_id: format!("drone{k}"),
                translation: position,
                rotation: Some(quaternion_of_yaw(p[3])),
            };
            ch.write(w, c, *t, &encode(&m)?)?;
            Ok(3)
        }
        Record::Grid { t, grid } => {
            let c = ch.foxglove::<FoxGrid>(w, "/map")?;
            // ROS occupancy values: 0 free, 100 occupied, −1 unknown.
            let data: Vec<u8> = (0..grid.height())
                .flat_map(|y| (0..grid.width()).map(move |x| (x, y)))
                .map(|c| match grid.get(c) {
                    Cell::Free => 0u8,
                    Cell::Occupied => 100,
                    Cell::Unknown => (-1i8) as u8,
                })
                .collect();
            let o = grid.origin();
            let m = FoxGrid {
                timestamp: stamp(*t),
                frame_id: "map".into(),
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: o[0],
                        y: o[1],
                        z: 0.0,
                    }),
                    orientation: Some(quaternion_of_yaw(0.0)),
                }),
                column_count: grid.width() as u32,
                cell_size: Some(Vector2 {
                    x: grid.resolution(),
                    y: grid.resolution(),
                }),
                row_stride: grid.width() as u32,
                cell_stride: 1,
                fields: vec![PackedElementField {
                    name: "occupancy".into(),
                    offset: 0,
                    r#type: NumericType::Int8 as i32,
                }],
                data: data.into(),
            };
            ch.write(w, c, *t, &encode(&m)?)?;
            Ok(1)
        }
        Record::Cloud { t, points } => {
            let c = ch.foxglove::<PointCloud>(w, "/map/points")?;
            let mut data = Vec::with_capacity(points.len() * 12);
            for p in points {
                for v in p {
                    data.extend_from_slice(&(*v as f32).to_le_bytes());
                }
            }
            let field = |name: &str, offset| PackedElementField {
                name: name.into(),
                offset,
                r#type: NumericType::Float32 as i32,
            };
            let m = PointCloud {
                timestamp: stamp(*t),
                frame_id: "map".into(),
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                    }),
                    orientation: Some(quaternion_of_yaw(0.0)),
                }),
                point_stride: 12,
                fields: vec![field("x", 0), field("y", 4), field("z", 8)],
                data: data.into(),
            };
            ch.write(w, c, *t, &encode(&m)?)?;
            Ok(1)
        }
        Record::Plan {
            t,
            goals,
            frontiers,
            given_up,
        } => {
            let c = ch.json(w, "/plan", "gcs.Plan")?;
            let v = serde_json::json!({
                "t": t,
                "goals": goals,
                "frontiers": frontiers,
                "given_up": given_up,
            });
            ch.write(
                w,
                c,
                *t,
                &serde_json::to_vec(&v).map_err(|e| e.to_string())?,
            )?;
            Ok(1)
        }
        Record::VehicleText { t, drone, text } => {
            let name = format!("drone{}", drone + 1);
            let topic = format!("/{name}/status");
            write_log(
                w,
                ch,
                &topic,
                *t,
                log_level(text.severity),
                &text.text,
                name,
            )
        }
        Record::StationText { t, warning, text } => {
            let level = if *warning {
                Level::Warning
            } else {
                Level::Info
            };
            write_log(w, ch, "/station", *t, level, text, "station".into())
        }
        Record::Operator { t, command } => write_log(
            w,
            ch,
            "/operator",
            *t,
            Level::Info,
            command,
            "operator".into(),
        ),
    }
}

/// Writes one `foxglove.Log` message on `topic`.
fn write_log(
    w: &mut McapWriter,
    ch: &mut Channels,
    topic: &str,
    t: f64,
    level: Level,
    message: &str,
    name: String,
) -> Result<u64, String> {
    let c = ch.foxglove::<Log>(w, topic)?;
    let m = Log {
        timestamp: stamp(t),
        level: level as i32,
        message: message.to_owned(),
        name,
        file: String::new(),
        line: 0,
    };
    ch.write(w, c, t, &encode(&m)?)?;
    Ok(1)
}

/// Foxglove's log level of a syslog (MAVLink `MAV_SEVERITY`) severity.
fn log_level(severity: u8) -> Level {
    match severity {
        0..=2 => Level::Fatal, // emergency, alert, critical
        3 => Level::Error,
        4 => Level::Warning,
        5 | 6 => Level::Info, // notice, info
        _ => Level::Debug,
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use link::camera::{Intrinsics, RgbdFrame};

    use super::*;

    #[test]
    fn a_header_stamp_is_the_nanosecond_of_the_log_time() {
        // The fraction was once cut, not rounded: a third of these times came out a nanosecond
        // short (20.29 s as 20.289999999) of their log time.
        for k in 0..100_000u32 {
            let t = f64::from(k) * 0.01;
            let s = stamp(t).expect("a stamp");
            let ns = u64::from(s.sec()) * 1_000_000_000 + u64::from(s.nsec());
            assert_eq!(ns, log_time(t), "{t} s");
            assert_eq!(ns, (f64::from(k) * 1e7).round() as u64, "{t} s");
        }
        assert_eq!(log_time(-1.0), 0);
    }

    /// Colour frames, and messages of other than the cameras, in a recording of two drones' 10 Hz cameras over 3 s.
    fn camera_messages(camera_hz: Option<f64>) -> (usize, usize) {
        let dir = std::env::temp_dir().join(format!(
            "gcs-record-{}-{}",
            std::process::id(),
            camera_hz.map_or(-1.0, |h| h)
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("mission.mcap");
        let mut recorder = Recorder::create(&path, camera_hz).unwrap();
        for i in 0..30 {
            for drone in 0..2 {
                let t = f64::from(i) * 0.1;
                let frame = RgbdFrame {
                    vehicle: drone as u8,
                    stamp: Duration::from_secs_f64(t),
                    width: 4,
                    height: 2,
                    intrinsics: Intrinsics {
                        fx: 2.0,
                        fy: 2.0,
                        cx: 2.0,
                        cy: 1.0,
                    },
                    rgb: vec![90; 4 * 2 * 3],
                    depth_mm: vec![1500; 4 * 2],
                };
                recorder.send(Record::Camera {
                    t,
                    drone,
                    frame: Arc::new(frame),
                    truth: None,
                });
            }
            recorder.send(Record::Operator {
                t: f64::from(i) * 0.1,
                command: "hold".into(),
            });
        }
        let stats = recorder.finish().unwrap();
        assert_eq!(stats.dropped, 0);
        let bytes = std::fs::read(&path).unwrap();
        let (mut colour, mut other) = (0, 0);
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let topic = m.unwrap().channel.topic.clone();
            if topic.ends_with("/camera/color") {
                colour += 1;
            } else if !topic.contains("camera") {
                other += 1;
            }
        }
        std::fs::remove_dir_all(&dir).ok();
        (colour, other)
    }

    #[test]
    fn drone_states_carry_the_filters_tilt_sigma_nearest_wall_and_setpoint_and_older_ones_read_without_them()
     {
        let older = r#"{"t":1.5,"phase":"exploring","height_m":0.9,"yaw_rad":0.1,
            "attitude":[0.01,0.02,0.1],"battery_v":12.1,"battery_pct":80,"armed":true,
            "mode":"ALT_HOLD","sticks":[0,0,0,0],"pose":[1,2,0.9,0.1]}"#;
        let s: DroneState = serde_json::from_str(older).expect("an older state");
        assert_eq!((s.t, s.tilt, s.pose_sigma_m), (1.5, None, None));
        assert_eq!((s.nearest_wall_m, s.setpoint), (None, None));
        let now = DroneState {
            tilt: Some([0.03, -0.04]),
            pose_sigma_m: Some(0.04),
            nearest_wall_m: Some(0.55),
            setpoint: Some([1.2, 2.1]),
            ..s
        };
        let json = serde_json::to_string(&now).expect("json");
        let back: DroneState = serde_json::from_str(&json).expect("read back");
        assert_eq!(back, now);
    }

    #[test]
    fn vehicle_severities_keep_their_rank_as_log_levels() {
        // ArduPilot's "GCS Failsafe: landing" is critical, "RC override timed out" a warning,
        // "Arming motors" info.
        assert_eq!(log_level(2), Level::Fatal);
        assert_eq!(log_level(3), Level::Error);
        assert_eq!(log_level(4), Level::Warning);
        assert_eq!(log_level(5), Level::Info);
        assert_eq!(log_level(6), Level::Info);
        assert_eq!(log_level(7), Level::Debug);
        assert_eq!(log_level(200), Level::Debug);
    }

    #[test]
    fn the_camera_log_rate_thins_camera_frames_and_nothing_else() {
        let (all, others) = camera_messages(None);
        assert_eq!(all, 60);
        // 2 Hz of a 10 Hz camera: every fifth frame, 6 in 3 s, per drone.
        let (thinned, others_thinned) = camera_messages(Some(2.0));
        assert_eq!(thinned, 12);
        let (none, others_none) = camera_messages(Some(0.0));
        assert_eq!(none, 0);
        assert!(others >= 30, "{others}");
        assert_eq!(others_thinned, others);
        assert_eq!(others_none, others);
        let dir = std::env::temp_dir().join(format!("gcs-record-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let e = Recorder::create(&dir.join("m.mcap"), Some(-1.0))
            .err()
            .unwrap();
        assert!(e.to_string().contains("must be 0 or more"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
