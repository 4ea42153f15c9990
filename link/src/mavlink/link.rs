//! The station as a MAVLink ground station: heartbeats, telemetry requests, commands with
//! acknowledgement and retry, flight modes, RC overrides at the RC rate, and link health for every
//! vehicle on one transport (told apart by system id).

use std::collections::{BTreeMap, VecDeque};
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ::mavlink::dialects::ardupilotmega::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult,
    MavSensorOrientation, MavState, MavType, RC_CHANNELS_OVERRIDE_DATA,
};
// SET_MODE and REQUEST_DATA_STREAM are superseded, but older autopilots only understand them:
// they are the fallbacks when DO_SET_MODE and SET_MESSAGE_INTERVAL get no answer.
#[allow(deprecated)]
use ::mavlink::dialects::ardupilotmega::{MavDataStream, REQUEST_DATA_STREAM_DATA, SET_MODE_DATA};
use ::mavlink::{MavHeader, MavlinkVersion, SigningConfig, SigningData};

use super::frame::{FrameScanner, RawFrame, encode};
use super::modes::{copter_custom_mode, copter_mode_name};
use crate::address::Address;
use crate::heartbeat::{HeartbeatMonitor, LinkState, VehicleClock};
use crate::rc::{ChannelMap, Sticks};
use crate::tlog::Recorder;
use crate::transport::{
    Connection, Transport, TransportError, Writer, duplex, is_timeout, run_sessions,
};
use crate::vehicle::{
    Attitude, Battery, Command, CommandError, FlightMode, LinkStatus, StatusText, Telemetry,
    TextQueue, VehicleLink,
};

/// A MAVLink 2 signing key.
#[derive(Clone)]
pub struct SigningKey {
    /// The 32-byte secret.
    pub secret: [u8; 32],
    /// Our link id in signatures.
    pub link_id: u8,
    /// Accept unsigned frames from vehicles (a vehicle that signs is always checked).
    pub allow_unsigned: bool,
}

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SigningKey")
            .field("secret", &"<hidden>")
            .field("link_id", &self.link_id)
            .field("allow_unsigned", &self.allow_unsigned)
            .finish()
    }
}

impl SigningKey {
    /// The key MAVProxy's `signing setup PASSPHRASE` makes: SHA-256 of the passphrase.
    pub fn from_passphrase(passphrase: &str) -> Self {
        use sha2::Digest;
        let secret: [u8; 32] = sha2::Sha256::digest(passphrase.as_bytes()).into();
        Self {
            secret,
            link_id: 0,
            allow_unsigned: false,
        }
    }

    /// A key from 64 hexadecimal digits.
    pub fn from_hex(hex: &str) -> Result<Self, String> {
        let hex = hex.trim();
        if hex.len() != 64 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err("a signing key is 64 hexadecimal digits (32 bytes)".into());
        }
        let mut secret = [0u8; 32];
        for (i, byte) in secret.iter_mut().enumerate() {
            *byte = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).map_err(|e| e.to_string())?;
        }
        Ok(Self {
            secret,
            link_id: 0,
            allow_unsigned: false,
        })
    }
}

/// MAVLink link settings.
#[derive(Debug, Clone)]
pub struct MavlinkConfig {
    /// Our system id (255: a ground station).
    pub system_id: u8,
    /// Our component id (190: MAV_COMP_ID_MISSIONPLANNER, what ground stations use).
    pub component_id: u8,
    /// What our heartbeat says we are. A ground station (`MAV_TYPE_GCS`) keeps the vehicles'
    /// GCS failsafe at bay; a passive listener (a camera bridge: `MAV_TYPE_CAMERA`) must not.
    pub mav_type: MavType,
    /// Protocol version we send (we accept both).
    pub version: MavlinkVersion,
    /// RC override frames per second (ArduPilot drops an override 3 s after the last one).
    pub rc_rate_hz: f64,
    /// Our heartbeat period, and the period we expect from vehicles, in the vehicles' time.
    pub heartbeat_period: Duration,
    /// The time the vehicles live in (wall time for real ones).
    pub clock: VehicleClock,
    /// Wait this long for a COMMAND_ACK before sending again.
    pub command_timeout: Duration,
    /// Send a command at most this many times.
    pub command_attempts: u32,
    /// Rate requested for attitude and position telemetry.
    pub telemetry_rate_hz: f32,
    /// How sticks map to RC channels.
    pub channel_map: ChannelMap,
    /// Sign outgoing frames and check incoming ones.
    pub signing: Option<SigningKey>,
}

impl Default for MavlinkConfig {
    fn default() -> Self {
        Self {
            system_id: 255,
            component_id: 190,
            mav_type: MavType::MAV_TYPE_GCS,
            version: MavlinkVersion::V2,
            rc_rate_hz: 20.0,
            heartbeat_period: Duration::from_secs(1),
            clock: VehicleClock::wall(),
            command_timeout: Duration::from_secs(1),
            command_attempts: 3,
            telemetry_rate_hz: 10.0,
            channel_map: ChannelMap::ardupilot(),
            signing: None,
        }
    }
}

enum Done {
    Reply(Command, mpsc::Sender<Result<(), CommandError>>),
    /// DO_SET_MODE: on "unsupported" or silence, fall back to SET_MODE and watch the heartbeat.
    SetMode(Command, u32, mpsc::Sender<Result<(), CommandError>>),
    /// SET_MESSAGE_INTERVAL: on failure, fall back to REQUEST_DATA_STREAM.
    Stream,
}

struct Pending {
    target: u8,
    msg: COMMAND_LONG_DATA,
    attempts: u32,
    next_send: Instant,
    done: Done,
}

struct ModeWait {
    target: u8,
    custom_mode: u32,
    deadline: Instant,
    command: Command,
    reply: mpsc::Sender<Result<(), CommandError>>,
}

struct Vehicle {
    component: u8,
    autopilot: MavAutopilot,
    custom_mode: u32,
    monitor: HeartbeatMonitor,
    telemetry: Telemetry,
    texts: TextQueue,
    sticks: Option<Sticks>,
    release_frames: u8,
    has_rangefinder: bool,
    stream_fallback_sent: bool,
}

impl Vehicle {
    fn is_ardupilot(&self) -> bool {
        self.autopilot == MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA
    }

    /// The vehicle is in `custom_mode` (its heartbeat said so, or it accepted the change).
    fn set_mode(&mut self, custom_mode: u32) {
        self.custom_mode = custom_mode;
        self.telemetry.mode = Some(if self.is_ardupilot() {
            copter_mode_name(custom_mode)
        } else {
            format!("MODE({custom_mode})")
        });
    }
}

struct State {
    vehicles: BTreeMap<u8, Vehicle>,
    pending: Vec<Pending>,
    mode_waits: Vec<ModeWait>,
    outbox: VecDeque<MavMessage>,
    transport_up: bool,
    connections: u32,
    frames_ok: u64,
    frames_bad: u64,
    rejected_signatures: u64,
    /// Status texts from systems not yet heard by heartbeat (vehicles talk before their first one).
    early_texts: BTreeMap<u8, TextQueue>,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    config: MavlinkConfig,
    signing: Option<SigningData>,
    stop: AtomicBool,
    name: String,
    recorder: Recorder,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Stops the I/O thread when the last handle goes.
struct Runtime {
    shared: Arc<Shared>,
    thread: Mutex<Option<JoinHandle<()>>>,
}

impl Drop for Runtime {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.shared.wake.notify_all();
        if let Some(t) = self
            .thread
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
        {
            let _ = t.join();
        }
    }
}

/// A MAVLink connection to one or more vehicles.
#[derive(Clone)]
pub struct MavlinkLink {
    rt: Arc<Runtime>,
}

/// One vehicle (system id) on a [`MavlinkLink`].
#[derive(Clone)]
pub struct MavlinkVehicle {
    rt: Arc<Runtime>,
    system_id: u8,
}

impl MavlinkLink {
    /// Opens the transport and starts the ground-station loop in the background.
    pub fn connect(address: &Address, config: MavlinkConfig) -> Result<Self, TransportError> {
        Ok(Self::start(Transport::open(address)?, config))
    }

    /// Starts over an opened transport.
    pub fn start(mut transport: Transport, config: MavlinkConfig) -> Self {
        let signing = config.signing.as_ref().map(|k| {
            SigningData::from_config(SigningConfig::new(
                k.secret,
                k.link_id,
                true,
                k.allow_unsigned,
            ))
        });
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                vehicles: BTreeMap::new(),
                pending: vec![],
                mode_waits: vec![],
                outbox: VecDeque::new(),
                transport_up: false,
                connections: 0,
                frames_ok: 0,
                frames_bad: 0,
                rejected_signatures: 0,
                early_texts: BTreeMap::new(),
            }),
            wake: Condvar::new(),
            name: format!("mavlink {}", transport.address()),
            config,
            signing,
            stop: AtomicBool::new(false),
            recorder: Recorder::default(),
        });
        let sh = shared.clone();
        let thread = std::thread::Builder::new()
            .name("mavlink-link".into())
            .spawn(move || {
                run_sessions(
                    &mut transport,
                    &sh.stop,
                    |up| {
                        let mut s = sh.lock();
                        s.transport_up = up;
                        s.connections += u32::from(up);
                    },
                    |conn| session(&sh, conn),
                );
                let mut s = sh.lock();
                for p in s.pending.drain(..) {
                    if let Done::Reply(c, tx) | Done::SetMode(c, _, tx) = p.done {
                        let _ = tx.send(Err(CommandError::Closed { command: c }));
                    }
                }
                for w in s.mode_waits.drain(..) {
                    let _ = w
                        .reply
                        .send(Err(CommandError::Closed { command: w.command }));
                }
            })
            .ok();
        Self {
            rt: Arc::new(Runtime {
                shared,
                thread: Mutex::new(thread),
            }),
        }
    }

    /// System ids of the vehicles heard so far.
    pub fn vehicles(&self) -> Vec<u8> {
        self.rt.shared.lock().vehicles.keys().copied().collect()
    }

    /// Waits up to `timeout` for the first vehicle's heartbeat.
    pub fn wait_for_vehicle(&self, timeout: Duration) -> Option<MavlinkVehicle> {
        let until = Instant::now() + timeout;
        loop {
            if let Some(&id) = self.rt.shared.lock().vehicles.keys().next() {
                return Some(self.vehicle(id));
            }
            if Instant::now() >= until {
                return None;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// A handle to the vehicle with this system id (heard yet or not).
    pub fn vehicle(&self, system_id: u8) -> MavlinkVehicle {
        MavlinkVehicle {
            rt: self.rt.clone(),
            system_id,
        }
    }

    /// Records every frame received and sent from now on to a `.tlog` file (as QGroundControl and
    /// MAVProxy do), until the link closes or another recording starts.
    pub fn record_to(&self, path: impl AsRef<std::path::Path>) -> std::io::Result<()> {
        self.rt.shared.recorder.start(path)
    }

    /// Frames dropped because their signature was missing, wrong or replayed.
    pub fn rejected_signatures(&self) -> u64 {
        self.rt.shared.lock().rejected_signatures
    }

    /// Queues any message for sending (e.g. SETUP_SIGNING, PARAM_SET).
    pub fn send(&self, msg: MavMessage) {
        self.rt.shared.lock().outbox.push_back(msg);
        self.rt.shared.wake.notify_all();
    }
}

impl MavlinkVehicle {
    /// The vehicle's system id.
    pub fn system_id(&self) -> u8 {
        self.system_id
    }
}

fn command_long(target: u8, component: u8, command: MavCmd, params: [f32; 7]) -> COMMAND_LONG_DATA {
    COMMAND_LONG_DATA {
        param1: params[0],
        param2: params[1],
        param3: params[2],
        param4: params[3],
        param5: params[4],
        param6: params[5],
        param7: params[6],
        command,
        target_system: target,
        target_component: component,
        confirmation: 0,
    }
}

impl VehicleLink for MavlinkVehicle {
    fn name(&self) -> String {
        format!("{} #{}", self.rt.shared.name, self.system_id)
    }

    fn set_sticks(&self, sticks: Option<Sticks>) {
        let mut s = self.rt.shared.lock();
        let Some(v) = s.vehicles.get_mut(&self.system_id) else {
            return;
        };
        if sticks.is_none() && v.sticks.is_some() {
            v.release_frames = 3;
        }
        v.sticks = sticks;
    }

    fn command(&self, command: Command) -> Result<(), CommandError> {
        let shared = &self.rt.shared;
        let (tx, rx) = mpsc::channel();
        {
            let mut s = shared.lock();
            let Some(v) = s.vehicles.get(&self.system_id) else {
                return Err(CommandError::NotConnected { command });
            };
            let (comp, ardupilot) = (v.component, v.is_ardupilot());
            let id = self.system_id;
            let (msg, done) = match command {
                Command::Arm | Command::StartMotors => (
                    command_long(
                        id,
                        comp,
                        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                        [1.0, 0., 0., 0., 0., 0., 0.],
                    ),
                    Done::Reply(command, tx),
                ),
                Command::Disarm => (
                    command_long(id, comp, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
                    Done::Reply(command, tx),
                ),
                Command::Land if !ardupilot => (
                    command_long(id, comp, MavCmd::MAV_CMD_NAV_LAND, [0.0; 7]),
                    Done::Reply(command, tx),
                ),
                Command::Land | Command::SetMode(_) => {
                    let mode = match command {
                        Command::SetMode(m) => m,
                        _ => FlightMode::Land,
                    };
                    if !ardupilot {
                        return Err(CommandError::Unsupported {
                            command,
                            backend: "this autopilot (ArduPilot modes only)",
                        });
                    }
                    let custom = copter_custom_mode(mode);
                    let flag = f32::from(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits());
                    (
                        command_long(
                            id,
                            comp,
                            MavCmd::MAV_CMD_DO_SET_MODE,
                            [flag, custom as f32, 0., 0., 0., 0., 0.],
                        ),
                        Done::SetMode(command, custom, tx),
                    )
                }
            };
            s.pending.push(Pending {
                target: id,
                msg,
                attempts: 0,
                next_send: Instant::now(),
                done,
            });
        }
        shared.wake.notify_all();
        rx.recv().unwrap_or(Err(CommandError::Closed { command }))
    }

    fn telemetry(&self) -> Telemetry {
        self.rt
            .shared
            .lock()
            .vehicles
            .get(&self.system_id)
            .map(|v| v.telemetry.clone())
            .unwrap_or_default()
    }

    fn status(&self) -> LinkStatus {
        let s = self.rt.shared.lock();
        let now = self.rt.shared.config.clock.now();
        let v = s.vehicles.get(&self.system_id);
        LinkStatus {
            state: v.map_or(LinkState::Connecting, |v| v.monitor.state(now)),
            last_message_age: v.and_then(|v| v.monitor.age(now)),
            transport_up: s.transport_up,
            connections: s.connections,
            frames_ok: s.frames_ok,
            frames_bad: s.frames_bad,
        }
    }

    fn take_status_texts(&self) -> Vec<StatusText> {
        self.rt
            .shared
            .lock()
            .vehicles
            .get_mut(&self.system_id)
            .map(|v| v.texts.take())
            .unwrap_or_default()
    }
}

/// One connection: a reader thread decodes, this thread writes on schedule.
fn session(shared: &Arc<Shared>, conn: Connection) {
    let sh = shared.clone();
    duplex(
        conn,
        "mavlink-rx",
        move |reader, alive| read_loop(&sh, reader, alive),
        |writer, alive| write_loop(shared, writer, alive),
    );
}

/// Sends heartbeats, queued messages, commands and RC overrides on schedule until the
/// connection fails or the link stops (then releases every override first).
fn write_loop(shared: &Shared, mut writer: Writer, alive: &AtomicBool) {
    let mut writer = Sender {
        writer: &mut writer,
        seq: 0,
        shared,
    };
    let cfg = &shared.config;
    let rc_period = Duration::from_secs_f64(1.0 / cfg.rc_rate_hz.clamp(1.0, 100.0));
    let mut next_rc = Instant::now();
    let mut next_hb = Instant::now();
    let mut out: Vec<MavMessage> = Vec::new();
    while alive.load(Ordering::Relaxed) {
        out.clear();
        let stopping = shared.stop.load(Ordering::Relaxed);
        {
            let mut s = shared.lock();
            let now = Instant::now();
            let wake_at = s
                .pending
                .iter()
                .map(|p| p.next_send)
                .chain(s.mode_waits.iter().map(|w| w.deadline))
                .chain([next_rc, next_hb])
                .min()
                .unwrap_or(next_rc);
            if wake_at > now && s.outbox.is_empty() && !stopping {
                s = shared
                    .wake
                    .wait_timeout(s, wake_at - now)
                    .unwrap_or_else(PoisonError::into_inner)
                    .0;
            }
            let now = Instant::now();
            if now >= next_hb {
                out.push(heartbeat(cfg.mav_type));
                next_hb = now + cfg.clock.wall_period(cfg.heartbeat_period);
            }
            out.extend(s.outbox.drain(..));
            schedule_commands(&mut s, cfg, now, &mut out);
            if now >= next_rc || stopping {
                for (&id, v) in s.vehicles.iter_mut() {
                    if stopping && v.sticks.take().is_some() {
                        v.release_frames = 3;
                    }
                    if let Some(sticks) = v.sticks {
                        out.push(rc_override(
                            id,
                            v.component,
                            &cfg.channel_map.override_channels(&sticks),
                        ));
                    } else if v.release_frames > 0 {
                        v.release_frames -= 1;
                        let release = RC_CHANNELS_OVERRIDE_DATA {
                            target_system: id,
                            target_component: v.component,
                            ..RC_CHANNELS_OVERRIDE_DATA::default()
                        };
                        out.push(MavMessage::RC_CHANNELS_OVERRIDE(release));
                    }
                }
                next_rc += rc_period;
                if next_rc < now {
                    next_rc = now + rc_period;
                }
            }
        }
        for m in &out {
            if let Err(e) = writer.send(m) {
                tracing::warn!("{}: write failed: {e}", shared.name);
                alive.store(false, Ordering::Relaxed);
                break;
            }
        }
        if stopping {
            let releasing = shared
                .lock()
                .vehicles
                .values()
                .any(|v| v.release_frames > 0);
            if !releasing {
                break;
            }
            std::thread::sleep(rc_period);
        }
    }
}

struct Sender<'a> {
    writer: &'a mut Box<dyn Write + Send>,
    seq: u8,
    shared: &'a Shared,
}

impl Sender<'_> {
    fn send(&mut self, msg: &MavMessage) -> std::io::Result<()> {
        let cfg = &self.shared.config;
        let header = MavHeader {
            system_id: u32::from(cfg.system_id),
            component_id: cfg.component_id,
            sequence: self.seq,
        };
        self.seq = self.seq.wrapping_add(1);
        let frame = encode(cfg.version, header, msg, self.shared.signing.as_ref());
        self.shared.recorder.record(&frame);
        // One write per frame: on UDP each write is one datagram.
        self.writer.write_all(&frame)
    }
}

fn heartbeat(mavtype: MavType) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn rc_override(target: u8, component: u8, ch: &[u16; 18]) -> MavMessage {
    MavMessage::RC_CHANNELS_OVERRIDE(RC_CHANNELS_OVERRIDE_DATA {
        chan1_raw: ch[0],
        chan2_raw: ch[1],
        chan3_raw: ch[2],
        chan4_raw: ch[3],
        chan5_raw: ch[4],
        chan6_raw: ch[5],
        chan7_raw: ch[6],
        chan8_raw: ch[7],
        target_system: target,
        target_component: component,
        chan9_raw: ch[8],
        chan10_raw: ch[9],
        chan11_raw: ch[10],
        chan12_raw: ch[11],
        chan13_raw: ch[12],
        chan14_raw: ch[13],
        chan15_raw: ch[14],
        chan16_raw: ch[15],
        chan17_raw: ch[16],
        chan18_raw: ch[17],
    })
}

/// What to do for a command that had no usable answer.
enum Fallback {
    SetMode {
        target: u8,
        command: Command,
        custom_mode: u32,
        reply: mpsc::Sender<Result<(), CommandError>>,
    },
    Stream {
        target: u8,
    },
}

/// Sends due commands, retries, and times out what has had every attempt.
fn schedule_commands(s: &mut State, cfg: &MavlinkConfig, now: Instant, out: &mut Vec<MavMessage>) {
    let mut fallbacks = vec![];
    s.pending.retain_mut(|p| {
        if p.next_send > now {
            return true;
        }
        if p.attempts >= cfg.command_attempts {
            match std::mem::replace(&mut p.done, Done::Stream) {
                Done::Reply(command, tx) => {
                    let _ = tx.send(Err(CommandError::Timeout {
                        command,
                        attempts: p.attempts,
                    }));
                }
                Done::SetMode(command, custom_mode, reply) => fallbacks.push(Fallback::SetMode {
                    target: p.target,
                    command,
                    custom_mode,
                    reply,
                }),
                Done::Stream => fallbacks.push(Fallback::Stream { target: p.target }),
            }
            return false;
        }
        p.msg.confirmation = p.attempts.min(255) as u8;
        p.attempts += 1;
        p.next_send = now + cfg.command_timeout;
        out.push(MavMessage::COMMAND_LONG(p.msg.clone()));
        true
    });
    for f in fallbacks {
        match f {
            Fallback::SetMode {
                target,
                command,
                custom_mode,
                reply,
            } => set_mode_fallback(s, cfg, now, target, command, custom_mode, reply, out),
            Fallback::Stream { target } => stream_fallback(s, cfg, target, out),
        }
    }
    s.mode_waits.retain(|w| {
        if w.deadline > now {
            return true;
        }
        let attempts = cfg.command_attempts + 1;
        let _ = w.reply.send(Err(CommandError::Timeout {
            command: w.command,
            attempts,
        }));
        false
    });
}

#[allow(clippy::too_many_arguments, deprecated)]
fn set_mode_fallback(
    s: &mut State,
    cfg: &MavlinkConfig,
    now: Instant,
    target: u8,
    command: Command,
    custom_mode: u32,
    reply: mpsc::Sender<Result<(), CommandError>>,
    out: &mut Vec<MavMessage>,
) {
    out.push(MavMessage::SET_MODE(SET_MODE_DATA {
        custom_mode,
        target_system: target,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    }));
    if s.vehicles
        .get(&target)
        .is_some_and(|v| v.custom_mode == custom_mode)
    {
        let _ = reply.send(Ok(()));
        return;
    }
    let deadline = now + cfg.command_timeout * cfg.command_attempts.max(1);
    s.mode_waits.push(ModeWait {
        target,
        custom_mode,
        deadline,
        command,
        reply,
    });
}

#[allow(deprecated)]
fn stream_fallback(s: &mut State, cfg: &MavlinkConfig, target: u8, out: &mut Vec<MavMessage>) {
    let Some(v) = s.vehicles.get_mut(&target) else {
        return;
    };
    if v.stream_fallback_sent {
        return;
    }
    v.stream_fallback_sent = true;
    tracing::info!(
        "vehicle {target} did not accept SET_MESSAGE_INTERVAL; using REQUEST_DATA_STREAM"
    );
    out.push(MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
        req_message_rate: cfg.telemetry_rate_hz.round().clamp(1.0, 50.0) as u16,
        target_system: target,
        target_component: v.component,
        req_stream_id: MavDataStream::MAV_DATA_STREAM_ALL,
        start_stop: 1,
    }));
}

/// Messages we ask every vehicle for, with their rate in Hz (0 = the telemetry rate).
const STREAMS: [(u32, f32); 7] = [
    (30, 0.0),  // ATTITUDE
    (32, 0.0),  // LOCAL_POSITION_NED
    (33, 0.0),  // GLOBAL_POSITION_INT
    (1, 2.0),   // SYS_STATUS
    (147, 2.0), // BATTERY_STATUS
    (132, 0.0), // DISTANCE_SENSOR
    (173, 0.0), // RANGEFINDER
];

fn read_loop(shared: &Shared, mut reader: Box<dyn Read + Send>, alive: &AtomicBool) {
    let mut scanner = FrameScanner::new();
    let mut buf = [0u8; 2048];
    let mut last_warn: Option<Instant> = None;
    let mut reported_bad = 0;
    while alive.load(Ordering::Relaxed) {
        let n = match reader.read(&mut buf) {
            Ok(n) => n,
            Err(e) if is_timeout(&e) => continue,
            Err(e) => {
                if !shared.stop.load(Ordering::Relaxed) {
                    tracing::warn!("{}: read failed: {e}", shared.name);
                }
                break;
            }
        };
        scanner.push(&buf[..n]);
        let now = Instant::now();
        while let Some(frame) = scanner.next_frame() {
            handle_frame(shared, &frame, now);
        }
        let bad = scanner.bad_frames + scanner.garbage_runs;
        if bad != reported_bad {
            shared.lock().frames_bad += bad - reported_bad;
            reported_bad = bad;
            if last_warn.is_none_or(|t| now - t > Duration::from_secs(5)) {
                tracing::warn!(
                    "{}: skipped {} bytes and {} bad frames so far (noise, boot text or another protocol)",
                    shared.name,
                    scanner.skipped_bytes,
                    scanner.bad_frames
                );
                last_warn = Some(now);
            }
        }
    }
}

fn handle_frame(shared: &Shared, frame: &RawFrame, now: Instant) {
    shared.recorder.record(frame.bytes());
    if let Some(signing) = &shared.signing
        && !frame.verify(signing)
    {
        let mut s = shared.lock();
        s.rejected_signatures += 1;
        s.frames_bad += 1;
        tracing::warn!(
            "{}: dropped a frame with a missing, wrong or replayed signature",
            shared.name
        );
        return;
    }
    let msg = match frame.decode() {
        Ok(m) => m,
        Err(e) => {
            tracing::debug!("{}: undecodable frame: {e}", shared.name);
            shared.lock().frames_bad += 1;
            return;
        }
    };
    let header = frame.header();
    let Ok(sys) = u8::try_from(header.system_id) else {
        return;
    };
    let cfg = &shared.config;
    let mut s = shared.lock();
    s.frames_ok += 1;
    if sys == cfg.system_id {
        return; // another ground station with our id, or our own echo
    }
    if let MavMessage::HEARTBEAT(hb) = &msg {
        if hb.mavtype == MavType::MAV_TYPE_GCS
            || hb.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID
        {
            return;
        }
        let is_new = !s.vehicles.contains_key(&sys);
        let early = s.early_texts.remove(&sys).unwrap_or_default();
        let v = s.vehicles.entry(sys).or_insert_with(|| Vehicle {
            component: header.component_id,
            autopilot: hb.autopilot,
            custom_mode: hb.custom_mode,
            monitor: HeartbeatMonitor::new(cfg.heartbeat_period),
            telemetry: Telemetry::default(),
            texts: early,
            sticks: None,
            release_frames: 0,
            has_rangefinder: false,
            stream_fallback_sent: false,
        });
        if header.component_id != v.component {
            return; // e.g. a gimbal or companion computer of the same system
        }
        v.monitor.heard(cfg.clock.now());
        v.autopilot = hb.autopilot;
        v.set_mode(hb.custom_mode);
        v.telemetry.armed = Some(
            hb.base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
        );
        let component = v.component;
        s.mode_waits.retain(|w| {
            if w.target == sys && w.custom_mode == hb.custom_mode {
                let _ = w.reply.send(Ok(()));
                return false;
            }
            true
        });
        if is_new {
            tracing::info!(
                "{}: vehicle {sys} (component {component}, {:?})",
                shared.name,
                hb.autopilot
            );
            let t = Instant::now();
            for (id, hz) in STREAMS {
                let hz = if hz > 0.0 {
                    hz
                } else {
                    cfg.telemetry_rate_hz.max(0.1)
                };
                let interval_us = 1e6 / hz;
                let msg = command_long(
                    sys,
                    component,
                    MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                    [id as f32, interval_us, 0., 0., 0., 0., 0.],
                );
                s.pending.push(Pending {
                    target: sys,
                    msg,
                    attempts: 0,
                    next_send: t,
                    done: Done::Stream,
                });
            }
            shared.wake.notify_all();
        }
        return;
    }
    if let MavMessage::COMMAND_ACK(ack) = &msg {
        let Some(i) = s
            .pending
            .iter()
            .position(|p| p.target == sys && p.msg.command == ack.command)
        else {
            return;
        };
        if ack.result == MavResult::MAV_RESULT_IN_PROGRESS {
            s.pending[i].next_send = now + cfg.command_timeout;
            return;
        }
        let p = s.pending.remove(i);
        let accepted = ack.result == MavResult::MAV_RESULT_ACCEPTED;
        match p.done {
            Done::Reply(_, tx) if accepted => {
                let _ = tx.send(Ok(()));
            }
            Done::SetMode(_, custom, tx) if accepted => {
                // The vehicle is in the new mode from its acknowledgement on: its heartbeats
                // before it (1 Hz; sent, on an ordered link, before the ack) told the old one,
                // which a station would otherwise take as the mode for up to a second — a
                // vehicle taking off again after a landing would still read LAND.
                if let Some(v) = s.vehicles.get_mut(&sys) {
                    v.set_mode(custom);
                }
                let _ = tx.send(Ok(()));
            }
            Done::SetMode(command, custom, tx)
                if ack.result == MavResult::MAV_RESULT_UNSUPPORTED =>
            {
                let mut out = vec![];
                set_mode_fallback(&mut s, cfg, now, sys, command, custom, tx, &mut out);
                s.outbox.extend(out);
                shared.wake.notify_all();
            }
            Done::Reply(command, tx) | Done::SetMode(command, _, tx) => {
                let reason = format!("{:?}", ack.result);
                let _ = tx.send(Err(CommandError::Rejected { command, reason }));
            }
            Done::Stream if accepted => {}
            Done::Stream => {
                let mut out = vec![];
                stream_fallback(&mut s, cfg, sys, &mut out);
                s.outbox.extend(out);
                shared.wake.notify_all();
            }
        }
        return;
    }
    let Some(v) = s.vehicles.get_mut(&sys) else {
        if let MavMessage::STATUSTEXT(st) = &msg {
            let text = String::from_utf8_lossy(&st.text[..])
                .trim_end_matches('\0')
                .to_owned();
            tracing::debug!("system {sys}: {text}");
            let queue = s.early_texts.entry(sys).or_default();
            queue.push(StatusText {
                severity: st.severity as u8,
                text,
            });
        }
        return;
    };
    let t = &mut v.telemetry;
    // NED (x north, y east, z down) → map (x north/forward, y west/left, z up): a half turn about x.
    // What is no number is dropped here (a broken sensor, a corrupt field): a NaN would
    // otherwise reach the sticks, the display and the log (the station's filter refuses it).
    match msg {
        MavMessage::ATTITUDE(a) if [a.roll, a.pitch, a.yaw].iter().all(|v| v.is_finite()) => {
            let att = Attitude {
                roll: a.roll,
                pitch: -a.pitch,
                yaw: -a.yaw,
            };
            t.attitude = Some(att);
            t.yaw_rad = Some(att.yaw);
            t.heading_at = Some(cfg.clock.now());
        }
        MavMessage::LOCAL_POSITION_NED(p)
            if [p.x, p.y, p.z, p.vx, p.vy, p.vz]
                .iter()
                .all(|v| v.is_finite()) =>
        {
            t.position_m = Some([p.x, -p.y, -p.z]);
            t.velocity_mps = Some([p.vx, -p.vy, -p.vz]);
        }
        MavMessage::GLOBAL_POSITION_INT(g) if !v.has_rangefinder => {
            t.height_m = Some(g.relative_alt as f32 / 1000.0);
        }
        MavMessage::DISTANCE_SENSOR(d)
            if d.orientation == MavSensorOrientation::MAV_SENSOR_ROTATION_PITCH_270 =>
        {
            v.has_rangefinder = true;
            t.height_m = Some(f32::from(d.current_distance) / 100.0);
        }
        MavMessage::RANGEFINDER(r) if r.distance.is_finite() => {
            v.has_rangefinder = true;
            t.height_m = Some(r.distance);
        }
        MavMessage::SYS_STATUS(st) if st.voltage_battery != u16::MAX => {
            let remaining_pct = u8::try_from(st.battery_remaining)
                .ok()
                .filter(|p| *p <= 100);
            t.battery = Some(Battery {
                voltage_v: f32::from(st.voltage_battery) / 1000.0,
                remaining_pct,
            });
        }
        MavMessage::BATTERY_STATUS(b) if t.battery.is_none() => {
            let mv: u32 = b
                .voltages
                .iter()
                .filter(|&&c| c != u16::MAX)
                .map(|&c| u32::from(c))
                .sum();
            if mv > 0 {
                let remaining_pct = u8::try_from(b.battery_remaining).ok().filter(|p| *p <= 100);
                t.battery = Some(Battery {
                    voltage_v: mv as f32 / 1000.0,
                    remaining_pct,
                });
            }
        }
        MavMessage::STATUSTEXT(st) => {
            let text = String::from_utf8_lossy(&st.text[..])
                .trim_end_matches('\0')
                .to_owned();
            tracing::debug!("vehicle {sys}: {text}");
            v.texts.push(StatusText {
                severity: st.severity as u8,
                text,
            });
        }
        _ => {}
    }
}
