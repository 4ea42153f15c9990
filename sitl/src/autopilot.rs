//! A simulated ArduPilot Copter autopilot: what a MAVLink ground station sees on the other end.
//!
//! It behaves as ArduCopter's SITL does for the messages a station uses: HEARTBEAT at 1 Hz; the
//! modes STABILIZE, ALT_HOLD, LOITER, GUIDED and LAND (`DO_SET_MODE` and `SET_MODE`); arming with
//! pre-arm checks (mode, throttle, battery; `param2 = 21196` forces); `RC_CHANNELS_OVERRIDE` with
//! ArduPilot's channel semantics and its override timeout (`RC_OVERRIDE_TIME`, 3 s: afterwards the
//! idle radio — sticks centred, throttle low — flies it, so it sinks and lands); the GCS failsafe
//! (no GCS heartbeat for `FS_GCS_TIMEOUT`, 5 s, while flying → LAND); the battery failsafe;
//! auto-disarm after landing; `SET_MESSAGE_INTERVAL`, `REQUEST_DATA_STREAM`, `REQUEST_MESSAGE`;
//! parameters; the telemetry a station reads, in NED; and MAVLink 2 signing as ArduPilot does it:
//! with a key set (at start, or by `SETUP_SIGNING`), every frame without a valid signature — none,
//! a wrong key, or a timestamp already seen (a replay) — is dropped, and every frame sent is
//! signed. `SETUP_SIGNING` is taken unsigned only while no key is set (ArduPilot takes it on USB);
//! an all-zero key turns signing off.
//!
//! The state machine is pure: [`Autopilot::handle`] takes received frames, [`Autopilot::update`]
//! runs it at the simulator's rate, and the bytes to send are taken with
//! [`Autopilot::take_output`]. `runner` connects it to a transport.

use std::collections::BTreeMap;
use std::time::Duration;

use link::mavlink::frame::{RawFrame, encode};
use link::mavlink::modes::copter_custom_mode;
use link::{ChannelMap, FlightMode, Pulses};
use mavlink::dialects::ardupilotmega::*;
use mavlink::{MavHeader, MavlinkVersion, SigningConfig, SigningData};

use crate::sensors::Readings;
use crate::vehicle::{Vehicle, VehicleEvent};

/// The autopilot's identity and constants.
#[derive(Debug, Clone, PartialEq)]
pub struct AutopilotConfig {
    /// MAVLink system id.
    pub system_id: u8,
    /// Home position: latitude and longitude in degrees, altitude above sea level in metres.
    pub home: [f64; 3],
    /// Telemetry rate of every stream until a station asks otherwise, Hz.
    pub default_rate_hz: f64,
    /// The MAVLink 2 signing key at power-up (`None`: signing off until `SETUP_SIGNING`).
    pub signing_key: Option<[u8; 32]>,
}

impl Default for AutopilotConfig {
    fn default() -> Self {
        Self {
            system_id: 1,
            // ArduPilot SITL's default home (CMAC, Canberra).
            home: [-35.363_261, 149.165_230, 584.0],
            default_rate_hz: 4.0,
            signing_key: None,
        }
    }
}

/// The autopilot's component id.
pub const COMPONENT_ID: u8 = 1;
/// `param2` of ARM_DISARM that skips the checks (ArduPilot's magic number).
pub const FORCE_ARM: f32 = 21196.0;

/// Telemetry streams this autopilot can send, by message id.
const STREAMS: [u32; 9] = [1, 30, 32, 33, 65, 74, 132, 147, 173];

/// The ArduCopter parameters this simulation honours, with their defaults.
const PARAMS: [(&str, f32); 8] = [
    ("SYSID_THISMAV", 1.0),
    ("ARMING_CHECK", 1.0),
    ("FS_GCS_ENABLE", 1.0),
    ("FS_GCS_TIMEOUT", 5.0),
    ("RC_OVERRIDE_TIME", 3.0),
    ("DISARM_DELAY", 10.0),
    ("LAND_SPEED", 50.0),
    ("BATT_LOW_VOLT", 10.8),
];

/// The radio with no transmitter: sticks centred, throttle low (ArduPilot SITL's idle RC).
const IDLE_RC: [u16; 18] = {
    let mut ch = [1500u16; 18];
    ch[2] = 1000;
    ch
};

/// A simulated ArduCopter.
#[derive(Debug)]
pub struct Autopilot {
    config: AutopilotConfig,
    params: Vec<(&'static str, f32)>,
    channel_map: ChannelMap,
    sequence: u8,
    version: MavlinkVersion,
    out: Vec<u8>,
    overrides: [Option<u16>; 18],
    last_override: Option<Duration>,
    last_gcs_heartbeat: Option<Duration>,
    gcs_failsafe: bool,
    battery_failsafe: bool,
    intervals: BTreeMap<u32, Option<Duration>>,
    last_sent: BTreeMap<u32, Duration>,
    landed_low_since: Option<Duration>,
    requested_once: Vec<u32>,
    now: Duration,
    signing: Signing,
    rc_stats: RcStats,
    last_rc_frame: Option<Duration>,
}

/// How regularly RC overrides arrived: a histogram of the gaps between consecutive override
/// frames, in whole milliseconds of vehicle time (the last bucket holds every gap of 2 s or more).
#[derive(Debug, Clone, PartialEq)]
pub struct RcStats {
    /// Override frames received.
    pub frames: u64,
    /// `gaps[ms]`: how many gaps lasted `ms` milliseconds.
    pub gaps: Vec<u64>,
}

impl Default for RcStats {
    fn default() -> Self {
        Self {
            frames: 0,
            gaps: vec![0; 2001],
        }
    }
}

impl RcStats {
    /// The gap that `q` (0–1) of all gaps do not exceed, milliseconds (`None` before two frames).
    pub fn quantile_ms(&self, q: f64) -> Option<u64> {
        let total: u64 = self.gaps.iter().sum();
        if total == 0 {
            return None;
        }
        let want = (q.clamp(0.0, 1.0) * total as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        self.gaps.iter().enumerate().find_map(|(ms, n)| {
            seen += n;
            (seen >= want).then_some(ms as u64)
        })
    }

    /// The longest gap, milliseconds (2000 means 2 s or more).
    pub fn max_ms(&self) -> Option<u64> {
        self.gaps.iter().rposition(|n| *n > 0).map(|ms| ms as u64)
    }
}

/// The autopilot's signing state.
#[derive(Default)]
struct Signing {
    data: Option<SigningData>,
    /// Frames dropped for a missing, wrong or replayed signature.
    rejected: u64,
}

impl Signing {
    fn with_key(key: Option<[u8; 32]>) -> Self {
        let mut s = Self::default();
        s.set_key(key.unwrap_or([0; 32]));
        s
    }

    /// Sets the key; all zeros turns signing off (as ArduPilot).
    fn set_key(&mut self, key: [u8; 32]) {
        self.data = (key != [0; 32])
            .then(|| SigningData::from_config(SigningConfig::new(key, 0, true, false)));
    }
}

impl std::fmt::Debug for Signing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Signing")
            .field("on", &self.data.is_some())
            .field("rejected", &self.rejected)
            .finish()
    }
}

/// Largest backlog of bytes kept for a station that is not reading, bytes.
const MAX_BACKLOG: usize = 256 * 1024;

impl Autopilot {
    /// A powered-up autopilot: disarmed, in STABILIZE.
    pub fn new(config: AutopilotConfig) -> Self {
        let signing = Signing::with_key(config.signing_key);
        let mut params: Vec<(&'static str, f32)> = PARAMS.to_vec();
        params[0].1 = f32::from(config.system_id);
        let period = Duration::from_secs_f64(1.0 / config.default_rate_hz.clamp(0.1, 50.0));
        Self {
            config,
            params,
            channel_map: ChannelMap::ardupilot(),
            sequence: 0,
            version: MavlinkVersion::V2,
            out: vec![],
            overrides: [None; 18],
            last_override: None,
            last_gcs_heartbeat: None,
            gcs_failsafe: false,
            battery_failsafe: false,
            intervals: STREAMS.iter().map(|&id| (id, Some(period))).collect(),
            last_sent: BTreeMap::new(),
            landed_low_since: None,
            requested_once: vec![],
            now: Duration::ZERO,
            signing,
            rc_stats: RcStats::default(),
            last_rc_frame: None,
        }
    }

    /// How regularly RC overrides have arrived so far.
    pub fn rc_stats(&self) -> &RcStats {
        &self.rc_stats
    }

    /// The system id.
    pub fn system_id(&self) -> u8 {
        self.config.system_id
    }

    /// Whether frames must be signed.
    pub fn signing(&self) -> bool {
        self.signing.data.is_some()
    }

    /// Frames dropped for a missing, wrong or replayed signature.
    pub fn rejected_signatures(&self) -> u64 {
        self.signing.rejected
    }

    /// The bytes to send to the station since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// The RC channels the flight controller acts on (overrides over the idle radio).
    pub fn channels(&self) -> [u16; 18] {
        let mut ch = IDLE_RC;
        for (c, o) in ch.iter_mut().zip(&self.overrides) {
            if let Some(v) = o {
                *c = *v;
            }
        }
        ch
    }

    fn param(&self, name: &str) -> f32 {
        self.params
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(0.0, |(_, v)| *v)
    }

    fn send(&mut self, msg: MavMessage) {
        let header = MavHeader {
            system_id: u32::from(self.config.system_id),
            component_id: COMPONENT_ID,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        if self.out.len() > MAX_BACKLOG {
            self.out.clear(); // nobody is reading: old telemetry is worthless
        }
        self.out.extend(encode(
            self.version,
            header,
            &msg,
            self.signing.data.as_ref(),
        ));
    }

    fn text(&mut self, severity: MavSeverity, text: &str) {
        tracing::info!(system = self.config.system_id, "{text}");
        self.send(MavMessage::STATUSTEXT(STATUSTEXT_DATA {
            severity,
            text: text.into(),
            ..STATUSTEXT_DATA::default()
        }));
    }

    fn ack(&mut self, command: MavCmd, result: MavResult, to: MavHeader) {
        self.send(MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command,
            result,
            target_system: u8::try_from(to.system_id).unwrap_or(0),
            target_component: to.component_id,
            ..COMMAND_ACK_DATA::default()
        }));
    }

    fn for_me(&self, target_system: u8) -> bool {
        target_system == 0 || target_system == self.config.system_id
    }

    /// Handles one frame from the station. (ArduPilot still honours the deprecated SET_MODE and
    /// REQUEST_DATA_STREAM, and so do we.)
    #[allow(deprecated)]
    pub fn handle(&mut self, now: Duration, frame: &RawFrame, vehicle: &mut Vehicle) {
        self.now = now;
        if let Some(signing) = &self.signing.data
            && !frame.verify(signing)
        {
            self.signing.rejected += 1;
            return;
        }
        let Ok(msg) = frame.decode() else {
            return; // a message of another dialect: not for us
        };
        let from = frame.header();
        if from.system_id == u32::from(self.config.system_id) {
            return; // our own echo
        }
        self.version = frame.version();
        match msg {
            MavMessage::HEARTBEAT(hb) if hb.mavtype == MavType::MAV_TYPE_GCS => {
                self.last_gcs_heartbeat = Some(now);
                if self.gcs_failsafe {
                    self.gcs_failsafe = false;
                    self.text(MavSeverity::MAV_SEVERITY_INFO, "GCS Failsafe Cleared");
                }
            }
            MavMessage::COMMAND_LONG(c) if self.for_me(c.target_system) => {
                self.command(&c, from, vehicle);
            }
            MavMessage::SET_MODE(m) if self.for_me(m.target_system) => {
                self.set_mode(m.custom_mode, vehicle);
            }
            MavMessage::REQUEST_DATA_STREAM(r) if self.for_me(r.target_system) => {
                let ids: &[u32] = match r.req_stream_id {
                    MavDataStream::MAV_DATA_STREAM_ALL => &STREAMS,
                    MavDataStream::MAV_DATA_STREAM_EXTENDED_STATUS => &[1],
                    MavDataStream::MAV_DATA_STREAM_RC_CHANNELS => &[65],
                    MavDataStream::MAV_DATA_STREAM_POSITION => &[32, 33],
                    MavDataStream::MAV_DATA_STREAM_EXTRA1 => &[30],
                    MavDataStream::MAV_DATA_STREAM_EXTRA2 => &[74],
                    MavDataStream::MAV_DATA_STREAM_EXTRA3 => &[132, 147, 173],
                    _ => &[],
                };
                let period = (r.start_stop != 0 && r.req_message_rate > 0)
                    .then(|| Duration::from_secs_f64(1.0 / f64::from(r.req_message_rate)));
                for id in ids {
                    self.intervals.insert(*id, period);
                }
            }
            MavMessage::RC_CHANNELS_OVERRIDE(o) if self.for_me(o.target_system) => {
                self.rc_override(&o);
            }
            MavMessage::SETUP_SIGNING(k) if self.for_me(k.target_system) => {
                // Signed with the current key if one is set: checked above.
                self.signing.set_key(k.secret_key);
                if self.signing.data.is_some() {
                    self.version = MavlinkVersion::V2; // signatures exist in MAVLink 2 only
                    self.text(MavSeverity::MAV_SEVERITY_NOTICE, "Signing key set");
                } else {
                    self.text(MavSeverity::MAV_SEVERITY_WARNING, "Signing disabled");
                }
            }
            MavMessage::PARAM_REQUEST_LIST(p) if self.for_me(p.target_system) => {
                for i in 0..self.params.len() {
                    self.param_value(i);
                }
            }
            MavMessage::PARAM_REQUEST_READ(p) if self.for_me(p.target_system) => {
                let name = param_name(&p.param_id);
                let i = if p.param_index >= 0 {
                    Some(p.param_index as usize).filter(|i| *i < self.params.len())
                } else {
                    self.params.iter().position(|(n, _)| *n == name)
                };
                if let Some(i) = i {
                    self.param_value(i);
                }
            }
            MavMessage::PARAM_SET(p) if self.for_me(p.target_system) => {
                let name = param_name(&p.param_id);
                if let Some(i) = self.params.iter().position(|(n, _)| *n == name) {
                    if name != "SYSID_THISMAV" && p.param_value.is_finite() {
                        self.params[i].1 = p.param_value;
                    }
                    self.param_value(i);
                }
            }
            _ => {}
        }
    }

    fn param_value(&mut self, i: usize) {
        let (name, value) = self.params[i];
        self.send(MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: value,
            param_count: self.params.len() as u16,
            param_index: i as u16,
            param_id: name.into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }));
    }

    fn rc_override(&mut self, o: &RC_CHANNELS_OVERRIDE_DATA) {
        let ch = [
            o.chan1_raw,
            o.chan2_raw,
            o.chan3_raw,
            o.chan4_raw,
            o.chan5_raw,
            o.chan6_raw,
            o.chan7_raw,
            o.chan8_raw,
            o.chan9_raw,
            o.chan10_raw,
            o.chan11_raw,
            o.chan12_raw,
            o.chan13_raw,
            o.chan14_raw,
            o.chan15_raw,
            o.chan16_raw,
            o.chan17_raw,
            o.chan18_raw,
        ];
        for (i, &v) in ch.iter().enumerate() {
            // Channels 1–8: 0 releases, UINT16_MAX leaves alone. Channels 9–18: 0 and
            // UINT16_MAX leave alone, UINT16_MAX − 1 releases.
            let release = if i < 8 { v == 0 } else { v == u16::MAX - 1 };
            let ignore = v == u16::MAX || (i >= 8 && v == 0);
            if release {
                self.overrides[i] = None;
            } else if !ignore {
                self.overrides[i] = Some(v.clamp(800, 2200));
            }
        }
        self.last_override = Some(self.now);
        if let Some(last) = self.last_rc_frame {
            let ms = self.now.saturating_sub(last).as_millis().min(2000) as usize;
            self.rc_stats.gaps[ms] += 1;
        }
        self.last_rc_frame = Some(self.now);
        self.rc_stats.frames += 1;
    }

    #[allow(deprecated)] // MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, still sent by older stations
    fn command(&mut self, c: &COMMAND_LONG_DATA, from: MavHeader, vehicle: &mut Vehicle) {
        let result = match c.command {
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                let force = c.param2 == FORCE_ARM;
                if c.param1 == 1.0 {
                    self.arm(vehicle, force)
                } else if c.param1 == 0.0 {
                    if vehicle.state().landed || force {
                        self.disarm(vehicle, "Disarming motors");
                        MavResult::MAV_RESULT_ACCEPTED
                    } else {
                        self.text(
                            MavSeverity::MAV_SEVERITY_CRITICAL,
                            "Disarm: vehicle is flying (use param2=21196 to force)",
                        );
                        MavResult::MAV_RESULT_FAILED
                    }
                } else {
                    MavResult::MAV_RESULT_DENIED
                }
            }
            MavCmd::MAV_CMD_DO_SET_MODE => {
                if c.param2.is_finite() && c.param2 >= 0.0 {
                    self.set_mode(c.param2 as u32, vehicle)
                } else {
                    MavResult::MAV_RESULT_DENIED
                }
            }
            MavCmd::MAV_CMD_NAV_LAND => {
                self.set_mode(copter_custom_mode(FlightMode::Land), vehicle)
            }
            MavCmd::MAV_CMD_NAV_TAKEOFF => {
                if vehicle.mode() == FlightMode::Guided
                    && vehicle.state().armed
                    && c.param7.is_finite()
                    && c.param7 > 0.0
                {
                    vehicle.takeoff(f64::from(c.param7));
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    self.text(
                        MavSeverity::MAV_SEVERITY_WARNING,
                        "Takeoff: arm in GUIDED first",
                    );
                    MavResult::MAV_RESULT_FAILED
                }
            }
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                let id = c.param1 as u32;
                if c.param1.is_finite() && STREAMS.contains(&id) {
                    let default =
                        Duration::from_secs_f64(1.0 / self.config.default_rate_hz.clamp(0.1, 50.0));
                    let period = match c.param2 {
                        p if p < 0.0 => None,
                        p if p > 0.0 && p.is_finite() => {
                            Some(Duration::from_micros((p as u64).max(10_000)))
                        }
                        _ => Some(default), // 0: the default rate
                    };
                    self.intervals.insert(id, period);
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_UNSUPPORTED
                }
            }
            MavCmd::MAV_CMD_REQUEST_MESSAGE => {
                let id = c.param1 as u32;
                if c.param1.is_finite() && (STREAMS.contains(&id) || id == 0 || id == 148) {
                    self.requested_once.push(id);
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_UNSUPPORTED
                }
            }
            MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                self.requested_once.push(148);
                MavResult::MAV_RESULT_ACCEPTED
            }
            _ => MavResult::MAV_RESULT_UNSUPPORTED,
        };
        self.ack(c.command, result, from);
    }

    fn arm(&mut self, vehicle: &mut Vehicle, force: bool) -> MavResult {
        if vehicle.state().armed {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        if !force && self.param("ARMING_CHECK") != 0.0 {
            let throttle = self.channels()[2];
            let problem = if vehicle.mode() == FlightMode::Land {
                Some("Arm: Mode not armable".to_owned())
            } else if !vehicle.state().landed {
                Some("Arm: Vehicle is not on the ground".to_owned())
            } else if (vehicle.mode() == FlightMode::Stabilize && throttle > 1100)
                || (vehicle.mode() != FlightMode::Guided && throttle > 1550)
            {
                Some("Arm: Throttle too high".to_owned())
            } else if vehicle.battery_voltage() < f64::from(self.param("BATT_LOW_VOLT")) {
                Some(format!(
                    "PreArm: Battery below minimum arming voltage ({:.1} V)",
                    vehicle.battery_voltage()
                ))
            } else {
                None
            };
            if let Some(p) = problem {
                self.text(MavSeverity::MAV_SEVERITY_CRITICAL, &p);
                return MavResult::MAV_RESULT_FAILED;
            }
        }
        vehicle.set_armed(true);
        self.landed_low_since = None;
        self.text(MavSeverity::MAV_SEVERITY_INFO, "Arming motors");
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn disarm(&mut self, vehicle: &mut Vehicle, why: &str) {
        if vehicle.state().armed {
            vehicle.set_armed(false);
            self.text(MavSeverity::MAV_SEVERITY_INFO, why);
        }
    }

    fn set_mode(&mut self, custom_mode: u32, vehicle: &mut Vehicle) -> MavResult {
        match FlightMode::ALL
            .into_iter()
            .find(|m| copter_custom_mode(*m) == custom_mode)
        {
            Some(mode) => {
                vehicle.set_mode(mode);
                MavResult::MAV_RESULT_ACCEPTED
            }
            None => {
                let name = link::mavlink::modes::copter_mode_name(custom_mode);
                self.text(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Mode change to {name} failed: not available in this simulation"),
                );
                MavResult::MAV_RESULT_FAILED
            }
        }
    }

    /// Runs the flight controller's inputs, failsafes and telemetry at simulated time `now`.
    pub fn update(
        &mut self,
        now: Duration,
        vehicle: &mut Vehicle,
        readings: &Readings,
        events: &[VehicleEvent],
    ) {
        self.now = now;
        // Overrides time out: the idle radio takes over.
        let timeout = Duration::from_secs_f32(self.param("RC_OVERRIDE_TIME").clamp(0.0, 120.0));
        if let Some(t) = self.last_override
            && now.saturating_sub(t) > timeout
            && self.overrides.iter().any(Option::is_some)
        {
            self.overrides = [None; 18];
            self.last_override = None;
            self.text(MavSeverity::MAV_SEVERITY_WARNING, "RC override timed out");
        }
        let ch = self.channels();
        let pulses = Pulses {
            roll: ch[usize::from(self.channel_map.roll.number) - 1],
            pitch: ch[usize::from(self.channel_map.pitch.number) - 1],
            yaw: ch[usize::from(self.channel_map.yaw.number) - 1],
            throttle: ch[usize::from(self.channel_map.throttle.number) - 1],
        };
        vehicle.set_sticks(self.channel_map.sticks(&pulses));
        for e in events {
            match e {
                VehicleEvent::Collision(p) => self.text(
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    &format!("Collision at ({:.2}, {:.2}, {:.2})", p[0], p[1], p[2]),
                ),
                VehicleEvent::BatterySwapped => {
                    // A fresh battery clears the battery failsafe (a reboot does on ArduPilot).
                    self.battery_failsafe = false;
                    self.text(MavSeverity::MAV_SEVERITY_INFO, "Battery replaced");
                }
                VehicleEvent::Landed | VehicleEvent::TookOff => {}
            }
        }
        // LAND ends disarmed on the ground, however the vehicle got there: one that fell to the
        // floor before LAND came (a wall, a bad height) is landed already and sees no touchdown.
        if vehicle.mode() == FlightMode::Land && vehicle.state().armed && vehicle.state().landed {
            self.disarm(vehicle, "Land complete: disarming");
        }
        let flying = vehicle.state().armed && !vehicle.state().landed;
        // GCS failsafe.
        let gcs_timeout = Duration::from_secs_f32(self.param("FS_GCS_TIMEOUT").clamp(0.5, 120.0));
        if self.param("FS_GCS_ENABLE") != 0.0
            && flying
            && !self.gcs_failsafe
            && self
                .last_gcs_heartbeat
                .is_some_and(|t| now.saturating_sub(t) > gcs_timeout)
        {
            self.gcs_failsafe = true;
            self.text(MavSeverity::MAV_SEVERITY_CRITICAL, "GCS Failsafe: landing");
            vehicle.set_mode(FlightMode::Land);
        }
        // Battery failsafe.
        if flying && !self.battery_failsafe && readings.battery_pct <= 10 {
            self.battery_failsafe = true;
            self.text(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "Battery failsafe: landing",
            );
            vehicle.set_mode(FlightMode::Land);
        }
        // Auto-disarm: on the ground with the throttle low for DISARM_DELAY.
        let s = vehicle.state();
        if s.armed && s.landed && vehicle.mode() != FlightMode::Guided && ch[2] <= 1150 {
            let since = *self.landed_low_since.get_or_insert(now);
            let delay = Duration::from_secs_f32(self.param("DISARM_DELAY").clamp(0.0, 127.0));
            if delay > Duration::ZERO && now.saturating_sub(since) >= delay {
                self.disarm(vehicle, "Auto disarm: landed");
            }
        } else {
            self.landed_low_since = None;
        }
        self.telemetry(now, vehicle, readings);
    }

    fn telemetry(&mut self, now: Duration, vehicle: &Vehicle, readings: &Readings) {
        let heartbeat_due = self
            .last_sent
            .get(&0)
            .is_none_or(|t| now.saturating_sub(*t) >= Duration::from_secs(1));
        let once = std::mem::take(&mut self.requested_once);
        if heartbeat_due || once.contains(&0) {
            self.last_sent.insert(0, now);
            let msg = self.heartbeat(vehicle);
            self.send(msg);
        }
        if once.contains(&148) {
            self.send(MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
                capabilities: MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
                    | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
                    | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                flight_sw_version: (4 << 24) | (6 << 16) | 0xFF, // 4.6.0 official
                uid: u64::from(self.config.system_id),
                ..AUTOPILOT_VERSION_DATA::default()
            }));
        }
        for id in STREAMS {
            let due = match self.intervals.get(&id).copied().flatten() {
                Some(period) => self
                    .last_sent
                    .get(&id)
                    .is_none_or(|t| now.saturating_sub(*t) >= period),
                None => false,
            };
            if due || once.contains(&id) {
                self.last_sent.insert(id, now);
                if let Some(msg) = self.stream_message(id, now, vehicle, readings) {
                    self.send(msg);
                }
            }
        }
    }

    fn heartbeat(&self, vehicle: &Vehicle) -> MavMessage {
        let s = vehicle.state();
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED;
        if s.armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        if matches!(vehicle.mode(), FlightMode::Guided) {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED;
        }
        let system_status = if self.gcs_failsafe || self.battery_failsafe {
            MavState::MAV_STATE_CRITICAL
        } else if s.armed {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        };
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: copter_custom_mode(vehicle.mode()),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode,
            system_status,
            mavlink_version: 3,
        })
    }

    /// One telemetry message. Map (x north, y west, z up) → NED is a half turn about x.
    fn stream_message(
        &self,
        id: u32,
        now: Duration,
        vehicle: &Vehicle,
        readings: &Readings,
    ) -> Option<MavMessage> {
        let s = vehicle.state();
        let time_boot_ms = now.as_millis() as u32;
        let [x, y, z] = s.position;
        let [vx, vy, vz] = s.velocity;
        let (north, east, down) = (x, -y, -z);
        let yaw_ned = -s.yaw;
        let heading_deg = yaw_ned.to_degrees().rem_euclid(360.0);
        let battery_mv = (readings.battery_v * 1000.0).clamp(0.0, 65534.0) as u16;
        let current_ca: i16 = if s.armed {
            if s.landed { 150 } else { 1500 }
        } else {
            20
        };
        let sonar_cm = readings
            .sonar
            .map_or(401, |d| (d * 100.0).round().clamp(2.0, 400.0) as u16);
        Some(match id {
            1 => {
                let sensors = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
                    | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL
                    | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
                    | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
                    | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_LASER_POSITION
                    | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
                    | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY;
                // As ArduPilot: pre-arm checks present and healthy while arming would pass; the
                // fence healthy (not breached) although none is set.
                let sensors = sensors | MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
                let mut health = sensors | MavSysStatusSensor::MAV_SYS_STATUS_GEOFENCE;
                if readings.battery_v < f64::from(self.param("BATT_LOW_VOLT")) {
                    health.remove(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK);
                }
                MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                    onboard_control_sensors_present: sensors,
                    onboard_control_sensors_enabled: sensors,
                    onboard_control_sensors_health: health,
                    load: 200,
                    voltage_battery: battery_mv,
                    current_battery: current_ca,
                    battery_remaining: readings.battery_pct as i8,
                    ..SYS_STATUS_DATA::default()
                })
            }
            30 => MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms,
                roll: s.roll as f32,
                pitch: -s.pitch as f32,
                yaw: yaw_ned as f32,
                rollspeed: 0.0,
                pitchspeed: 0.0,
                yawspeed: -s.yaw_rate as f32,
            }),
            32 => MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                time_boot_ms,
                x: north as f32,
                y: east as f32,
                z: down as f32,
                vx: vx as f32,
                vy: -vy as f32,
                vz: -vz as f32,
            }),
            33 => {
                let [lat0, lon0, alt0] = self.config.home;
                let lat = lat0 + north / 111_319.5;
                let lon = lon0 + east / (111_319.5 * lat0.to_radians().cos());
                MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                    time_boot_ms,
                    lat: (lat * 1e7).round() as i32,
                    lon: (lon * 1e7).round() as i32,
                    alt: ((alt0 + z) * 1000.0).round() as i32,
                    relative_alt: (z * 1000.0).round() as i32,
                    vx: (vx * 100.0).round() as i16,
                    vy: (-vy * 100.0).round() as i16,
                    vz: (-vz * 100.0).round() as i16,
                    hdg: (heading_deg * 100.0).round() as u16 % 36000,
                })
            }
            65 => {
                let c = self.channels();
                MavMessage::RC_CHANNELS(RC_CHANNELS_DATA {
                    time_boot_ms,
                    chan1_raw: c[0],
                    chan2_raw: c[1],
                    chan3_raw: c[2],
                    chan4_raw: c[3],
                    chan5_raw: c[4],
                    chan6_raw: c[5],
                    chan7_raw: c[6],
                    chan8_raw: c[7],
                    chan9_raw: c[8],
                    chan10_raw: c[9],
                    chan11_raw: c[10],
                    chan12_raw: c[11],
                    chan13_raw: c[12],
                    chan14_raw: c[13],
                    chan15_raw: c[14],
                    chan16_raw: c[15],
                    chan17_raw: c[16],
                    chan18_raw: c[17],
                    chancount: 18,
                    rssi: 255,
                })
            }
            74 => MavMessage::VFR_HUD(VFR_HUD_DATA {
                airspeed: vx.hypot(vy) as f32,
                groundspeed: vx.hypot(vy) as f32,
                alt: z as f32,
                climb: vz as f32,
                heading: heading_deg.round() as i16 % 360,
                throttle: if s.armed { 50 } else { 0 },
            }),
            132 => MavMessage::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
                time_boot_ms,
                min_distance: 2,
                max_distance: 400,
                current_distance: sonar_cm,
                mavtype: MavDistanceSensor::MAV_DISTANCE_SENSOR_ULTRASOUND,
                id: 0,
                orientation: MavSensorOrientation::MAV_SENSOR_ROTATION_PITCH_270,
                covariance: 255,
                ..DISTANCE_SENSOR_DATA::default()
            }),
            147 => {
                let mut voltages = [u16::MAX; 10];
                voltages[0] = battery_mv;
                MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
                    voltages,
                    current_battery: current_ca,
                    battery_remaining: readings.battery_pct as i8,
                    current_consumed: -1,
                    energy_consumed: -1,
                    temperature: i16::MAX,
                    battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
                    mavtype: MavBatteryType::MAV_BATTERY_TYPE_LIPO,
                    ..BATTERY_STATUS_DATA::default()
                })
            }
            173 => MavMessage::RANGEFINDER(RANGEFINDER_DATA {
                distance: readings.sonar.map_or(f32::NAN, |d| d as f32),
                voltage: 0.0,
            }),
            _ => return None,
        })
    }
}

/// A parameter's name as a station sent it (NUL-padded, possibly not UTF-8: then empty).
fn param_name(id: &mavlink::types::CharArray<16>) -> String {
    id.to_str().unwrap_or("").trim_end_matches('\0').to_owned()
}

#[cfg(test)]
#[allow(deprecated)]
mod tests {
    use super::*;
    use crate::vehicle::VehicleParams;
    use crate::world::World;
    use link::mavlink::frame::FrameScanner;

    const GCS: MavHeader = MavHeader {
        system_id: 255,
        component_id: 190,
        sequence: 0,
    };

    struct Bench {
        ap: Autopilot,
        vehicle: Vehicle,
        world: World,
        now: Duration,
        received: Vec<MavMessage>,
        /// Signs what the bench sends, when set.
        signer: Option<SigningData>,
    }

    fn signer(key: [u8; 32]) -> SigningData {
        SigningData::from_config(SigningConfig::new(key, 0, true, false))
    }

    impl Bench {
        fn new() -> Self {
            let world = World::load(crate::world::DEFAULT_WORLD).unwrap();
            let [x, y] = world.starts()[0];
            Self {
                ap: Autopilot::new(AutopilotConfig::default()),
                vehicle: Vehicle::new(VehicleParams::default(), x, y, 0.0),
                world,
                now: Duration::ZERO,
                received: vec![],
                signer: None,
            }
        }

        fn send(&mut self, msg: MavMessage) {
            let bytes = encode(MavlinkVersion::V2, GCS, &msg, self.signer.as_ref());
            self.send_bytes(&bytes);
        }

        fn send_bytes(&mut self, bytes: &[u8]) {
            let frame = FrameScanner::single(bytes).unwrap();
            self.ap.handle(self.now, &frame, &mut self.vehicle);
            self.collect();
        }

        fn collect(&mut self) {
            let mut scanner = FrameScanner::new();
            scanner.push(&self.ap.take_output());
            while let Some(f) = scanner.next_frame() {
                assert_eq!(f.header().system_id, 1);
                self.received.push(f.decode().unwrap());
            }
        }

        fn command(&mut self, command: MavCmd, p: [f32; 7]) -> MavResult {
            self.send(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                param5: p[4],
                param6: p[5],
                param7: p[6],
                command,
                target_system: 1,
                target_component: 1,
                confirmation: 0,
            }));
            self.received
                .iter()
                .rev()
                .find_map(|m| match m {
                    MavMessage::COMMAND_ACK(a) if a.command == command => Some(a.result),
                    _ => None,
                })
                .unwrap()
        }

        fn set_mode(&mut self, mode: FlightMode) -> MavResult {
            self.command(
                MavCmd::MAV_CMD_DO_SET_MODE,
                [
                    1.0,
                    copter_custom_mode(mode) as f32,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                ],
            )
        }

        fn rc(&mut self, throttle: u16) {
            self.send(MavMessage::RC_CHANNELS_OVERRIDE(
                RC_CHANNELS_OVERRIDE_DATA {
                    chan1_raw: 1500,
                    chan2_raw: 1500,
                    chan3_raw: throttle,
                    chan4_raw: 1500,
                    chan5_raw: u16::MAX,
                    chan6_raw: u16::MAX,
                    chan7_raw: u16::MAX,
                    chan8_raw: u16::MAX,
                    target_system: 1,
                    target_component: 1,
                    ..RC_CHANNELS_OVERRIDE_DATA::default()
                },
            ));
        }

        fn gcs_heartbeat(&mut self) {
            self.send(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_GCS,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }));
        }

        /// Runs `seconds` of simulated time at 100 Hz, with a GCS heartbeat each second and an
        /// override each 0.2 s if `keep` is given.
        fn run(&mut self, seconds: f64, keep: Option<u16>, heartbeats: bool) {
            let steps = (seconds * 100.0).round() as u32;
            for i in 0..steps {
                self.now += Duration::from_millis(10);
                if heartbeats && i % 100 == 0 {
                    self.gcs_heartbeat();
                }
                if let Some(t) = keep
                    && i % 20 == 0
                {
                    self.rc(t);
                }
                self.vehicle.step(&self.world, 0.01);
                let events = self.vehicle.take_events();
                let readings = Readings {
                    sonar: Some(self.vehicle.state().position[2]),
                    yaw: self.vehicle.state().yaw,
                    battery_v: self.vehicle.battery_voltage(),
                    battery_pct: self.vehicle.battery_remaining(),
                };
                self.ap
                    .update(self.now, &mut self.vehicle, &readings, &events);
                self.collect();
            }
        }

        fn texts(&self) -> Vec<String> {
            self.received
                .iter()
                .filter_map(|m| match m {
                    MavMessage::STATUSTEXT(t) => Some(
                        t.text
                            .to_str()
                            .unwrap_or("")
                            .trim_end_matches('\0')
                            .to_owned(),
                    ),
                    _ => None,
                })
                .collect()
        }

        fn z(&self) -> f64 {
            self.vehicle.state().position[2]
        }

        /// A bench whose vehicle was put in ALT_HOLD and armed (on the floor).
        fn armed_in_alt_hold() -> Self {
            let mut b = Self::new();
            assert_eq!(
                b.set_mode(FlightMode::AltHold),
                MavResult::MAV_RESULT_ACCEPTED
            );
            assert_eq!(
                b.command(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
                ),
                MavResult::MAV_RESULT_ACCEPTED
            );
            b
        }
    }

    #[test]
    fn a_vehicle_already_on_the_floor_when_told_to_land_disarms() {
        // Armed and never off the floor (as one that fell there while flying): no touchdown
        // is left to see, and LAND must still end disarmed.
        let mut b = Bench::armed_in_alt_hold();
        b.run(1.0, Some(1100), true);
        assert!(b.vehicle.state().armed && b.vehicle.state().landed);
        assert_eq!(b.set_mode(FlightMode::Land), MavResult::MAV_RESULT_ACCEPTED);
        b.run(1.0, Some(1500), true);
        assert!(!b.vehicle.state().armed, "still armed on the floor in LAND");
        assert!(b.texts().iter().any(|t| t == "Land complete: disarming"));
    }

    #[test]
    fn alt_hold_arm_climb_hold_land_disarm() {
        let mut b = Bench::armed_in_alt_hold();
        b.run(2.0, Some(1800), true);
        assert!(b.z() > 0.8, "climbed to {}", b.z());
        b.run(1.0, Some(1500), true);
        let z = b.z();
        b.run(3.0, Some(1500), true);
        assert!((b.z() - z).abs() < 0.05, "held {z} → {}", b.z());
        assert_eq!(b.set_mode(FlightMode::Land), MavResult::MAV_RESULT_ACCEPTED);
        b.run(6.0, Some(1500), true);
        assert!(!b.vehicle.state().armed && b.vehicle.state().landed);
        assert!(
            b.texts().iter().any(|t| t == "Land complete: disarming"),
            "{:?}",
            b.texts()
        );
        // Telemetry flowed: heartbeats with the mode, positions in NED (z negative when up).
        assert!(
            b.received
                .iter()
                .any(|m| matches!(m, MavMessage::HEARTBEAT(h) if h.custom_mode == 9))
        );
        assert!(
            b.received
                .iter()
                .any(|m| matches!(m, MavMessage::LOCAL_POSITION_NED(p) if p.z < -0.8))
        );
    }

    #[test]
    fn arming_checks_refuse_with_a_reason_and_force_overrides() {
        let mut b = Bench::new();
        b.set_mode(FlightMode::Stabilize);
        b.rc(1500);
        assert_eq!(
            b.command(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            ),
            MavResult::MAV_RESULT_FAILED
        );
        assert!(b.texts().contains(&"Arm: Throttle too high".to_owned()));
        b.set_mode(FlightMode::Land);
        b.rc(1000);
        assert_eq!(
            b.command(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            ),
            MavResult::MAV_RESULT_FAILED
        );
        assert!(b.texts().contains(&"Arm: Mode not armable".to_owned()));
        assert_eq!(
            b.command(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1.0, FORCE_ARM, 0.0, 0.0, 0.0, 0.0, 0.0]
            ),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert!(b.vehicle.state().armed);
        // Unknown modes and commands are refused, not ignored.
        assert_eq!(
            b.command(
                MavCmd::MAV_CMD_DO_SET_MODE,
                [1.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            ),
            MavResult::MAV_RESULT_FAILED
        );
        assert_eq!(
            b.command(MavCmd::MAV_CMD_DO_FLIGHTTERMINATION, [1.0; 7]),
            MavResult::MAV_RESULT_UNSUPPORTED
        );
    }

    #[test]
    fn override_timeout_hands_over_to_the_idle_radio_and_it_sinks() {
        let mut b = Bench::new();
        b.set_mode(FlightMode::AltHold);
        b.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.run(2.0, Some(1800), true);
        let z = b.z();
        b.rc(1800);
        b.run(2.9, None, true); // overrides still in force: climbing on
        assert!(b.z() > z);
        assert_eq!(b.ap.channels()[2], 1800);
        b.run(0.3, None, true);
        assert_eq!(b.ap.channels()[2], 1000, "released after 3 s");
        assert!(b.texts().contains(&"RC override timed out".to_owned()));
        b.run(6.0, None, true);
        assert!(b.vehicle.state().landed, "sank to the floor at {}", b.z());
    }

    #[test]
    fn lost_gcs_heartbeat_lands_after_five_seconds() {
        let mut b = Bench::new();
        b.set_mode(FlightMode::Loiter);
        b.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.run(2.0, Some(1800), true);
        b.gcs_heartbeat();
        b.run(4.5, Some(1500), false);
        assert_eq!(
            b.vehicle.mode(),
            FlightMode::Loiter,
            "4.5 s without heartbeat is within the timeout"
        );
        b.run(1.0, Some(1500), false);
        assert_eq!(b.vehicle.mode(), FlightMode::Land);
        assert!(b.texts().contains(&"GCS Failsafe: landing".to_owned()));
        b.run(6.0, Some(1500), false);
        assert!(!b.vehicle.state().armed);
    }

    #[test]
    fn message_intervals_and_data_streams_set_rates() {
        let mut b = Bench::new();
        b.command(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [30.0, 20_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.command(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [33.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.received.clear();
        b.run(2.0, None, false);
        let count =
            |b: &Bench, f: fn(&MavMessage) -> bool| b.received.iter().filter(|m| f(m)).count();
        let att = count(&b, |m| matches!(m, MavMessage::ATTITUDE(_)));
        assert!((98..=101).contains(&att), "ATTITUDE at 50 Hz: {att} in 2 s");
        assert_eq!(
            count(&b, |m| matches!(m, MavMessage::GLOBAL_POSITION_INT(_))),
            0
        );
        let sys = count(&b, |m| matches!(m, MavMessage::SYS_STATUS(_)));
        assert!(
            (7..=9).contains(&sys),
            "SYS_STATUS at the default 4 Hz: {sys}"
        );
        let hb = count(&b, |m| matches!(m, MavMessage::HEARTBEAT(_)));
        assert!((2..=3).contains(&hb), "{hb}");
        // REQUEST_DATA_STREAM(POSITION, 10 Hz) turns GLOBAL_POSITION_INT back on.
        b.send(MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
            req_message_rate: 10,
            target_system: 1,
            target_component: 1,
            req_stream_id: MavDataStream::MAV_DATA_STREAM_POSITION,
            start_stop: 1,
        }));
        b.received.clear();
        b.run(1.0, None, false);
        let gpi = count(&b, |m| matches!(m, MavMessage::GLOBAL_POSITION_INT(_)));
        assert!((9..=11).contains(&gpi), "{gpi}");
    }

    #[test]
    fn override_channel_semantics_follow_the_spec() {
        let mut b = Bench::new();
        b.rc(1600);
        assert_eq!(b.ap.channels()[2], 1600);
        // UINT16_MAX leaves channel 3 alone; 0 on channels 9–18 is ignored; 0 on 1–8 releases.
        b.send(MavMessage::RC_CHANNELS_OVERRIDE(
            RC_CHANNELS_OVERRIDE_DATA {
                chan1_raw: 0,
                chan2_raw: u16::MAX,
                chan3_raw: u16::MAX,
                chan4_raw: 1400,
                chan9_raw: 1700,
                target_system: 1,
                ..RC_CHANNELS_OVERRIDE_DATA::default()
            },
        ));
        let ch = b.ap.channels();
        assert_eq!(
            (ch[0], ch[2], ch[3], ch[8], ch[9]),
            (1500, 1600, 1400, 1700, 1500)
        );
        b.send(MavMessage::RC_CHANNELS_OVERRIDE(
            RC_CHANNELS_OVERRIDE_DATA {
                chan1_raw: u16::MAX,
                chan2_raw: u16::MAX,
                chan3_raw: 0,
                chan4_raw: u16::MAX,
                chan9_raw: u16::MAX - 1,
                target_system: 1,
                ..RC_CHANNELS_OVERRIDE_DATA::default()
            },
        ));
        let ch = b.ap.channels();
        assert_eq!((ch[2], ch[3], ch[8]), (1000, 1400, 1500));
        // An override for another system changes nothing.
        b.send(MavMessage::RC_CHANNELS_OVERRIDE(
            RC_CHANNELS_OVERRIDE_DATA {
                chan3_raw: 1900,
                target_system: 2,
                ..RC_CHANNELS_OVERRIDE_DATA::default()
            },
        ));
        assert_eq!(b.ap.channels()[2], 1000);
    }

    #[test]
    fn parameters_can_be_listed_read_and_set() {
        let mut b = Bench::new();
        b.send(MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
        }));
        let n = b
            .received
            .iter()
            .filter(|m| matches!(m, MavMessage::PARAM_VALUE(_)))
            .count();
        assert_eq!(n, PARAMS.len());
        b.send(MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: 2.0,
            target_system: 1,
            target_component: 1,
            param_id: "FS_GCS_TIMEOUT".into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }));
        assert_eq!(b.ap.param("FS_GCS_TIMEOUT"), 2.0);
        // The shorter timeout takes effect.
        b.set_mode(FlightMode::AltHold);
        b.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.run(2.0, Some(1800), true);
        b.gcs_heartbeat();
        b.run(1.5, Some(1500), false);
        assert_eq!(b.vehicle.mode(), FlightMode::AltHold);
        b.run(1.0, Some(1500), false);
        assert_eq!(b.vehicle.mode(), FlightMode::Land);
    }

    #[test]
    fn a_collision_is_reported_as_a_status_text() {
        let mut b = Bench::new();
        b.set_mode(FlightMode::AltHold);
        b.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.run(1.5, Some(1800), true);
        // Pitch forward (a low pulse on channel 2) until something is hit.
        for _ in 0..100 {
            b.send(MavMessage::RC_CHANNELS_OVERRIDE(
                RC_CHANNELS_OVERRIDE_DATA {
                    chan1_raw: 1500,
                    chan2_raw: 1200,
                    chan3_raw: 1500,
                    chan4_raw: 1500,
                    target_system: 1,
                    ..RC_CHANNELS_OVERRIDE_DATA::default()
                },
            ));
            b.run(0.1, None, true);
        }
        assert!(b.vehicle.state().collisions >= 1);
        assert!(
            b.texts().iter().any(|t| t.starts_with("Collision at (")),
            "{:?}",
            b.texts()
        );
    }

    #[test]
    fn guided_takeoff() {
        let mut b = Bench::new();
        b.set_mode(FlightMode::Guided);
        assert_eq!(
            b.command(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
            ),
            MavResult::MAV_RESULT_FAILED
        );
        b.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            b.command(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.2]
            ),
            MavResult::MAV_RESULT_ACCEPTED
        );
        b.run(6.0, None, true);
        assert!((b.z() - 1.2).abs() < 0.05, "{}", b.z());
    }

    fn arm_message(arm: bool) -> MavMessage {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: if arm { 1.0 } else { 0.0 },
            param2: FORCE_ARM,
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            target_system: 1,
            target_component: 1,
            ..COMMAND_LONG_DATA::default()
        })
    }

    impl Bench {
        fn armed(&self) -> bool {
            self.vehicle.state().armed
        }

        fn acks(&self) -> usize {
            self.received
                .iter()
                .filter(|m| matches!(m, MavMessage::COMMAND_ACK(_)))
                .count()
        }
    }

    #[test]
    fn with_a_key_only_fresh_frames_signed_with_it_are_obeyed() {
        let key = [7u8; 32];
        let mut b = Bench::new();
        b.ap = Autopilot::new(AutopilotConfig {
            signing_key: Some(key),
            ..AutopilotConfig::default()
        });
        assert!(b.ap.signing());
        // Unsigned, MAVLink 1, and signed with another key: dropped without an answer.
        b.send(arm_message(true));
        b.send_bytes(&encode(MavlinkVersion::V1, GCS, &arm_message(true), None));
        b.signer = Some(signer([8; 32]));
        b.send(arm_message(true));
        assert!(!b.armed());
        assert_eq!(b.ap.rejected_signatures(), 3);
        assert_eq!(b.acks(), 0);

        // The key holder is obeyed, and what the autopilot sends is signed with the key.
        b.signer = Some(signer(key));
        b.send(arm_message(true));
        assert!(b.armed());
        let mut scanner = FrameScanner::new();
        b.now += Duration::from_secs(1);
        let readings = Readings {
            sonar: Some(0.0),
            yaw: 0.0,
            battery_v: 12.6,
            battery_pct: 100,
        };
        b.ap.update(b.now, &mut b.vehicle, &readings, &[]);
        scanner.push(&b.ap.take_output());
        let check = signer(key);
        let mut frames = 0;
        while let Some(f) = scanner.next_frame() {
            assert!(
                f.is_signed() && f.verify(&check),
                "an unsigned or badly signed frame"
            );
            frames += 1;
        }
        assert!(frames > 0);

        // A recorded DISARM sent again (a replay) is dropped: its timestamp was seen.
        let disarm = encode(
            MavlinkVersion::V2,
            GCS,
            &arm_message(false),
            b.signer.as_ref(),
        );
        b.send_bytes(&disarm);
        assert!(!b.armed());
        b.send(arm_message(true));
        assert!(b.armed());
        b.send_bytes(&disarm);
        assert!(b.armed(), "a replayed DISARM was obeyed");
        assert_eq!(b.ap.rejected_signatures(), 4);
    }

    #[test]
    fn setup_signing_sets_a_key_once_and_only_its_holder_changes_or_clears_it() {
        let key = link::mavlink::SigningKey {
            secret: [5; 32],
            link_id: 0,
            allow_unsigned: false,
        };
        let mut b = Bench::new();
        assert!(!b.ap.signing());
        b.send(link::mavlink::keys::setup_signing(&key, 1));
        assert!(b.ap.signing());
        assert!(b.received.iter().any(
            |m| matches!(m, MavMessage::STATUSTEXT(t) if t.text.to_str().is_ok_and(|t| t.contains("Signing key set")))
        ));
        // Someone without the key cannot replace it.
        let intruder = link::mavlink::SigningKey {
            secret: [6; 32],
            ..key.clone()
        };
        b.send(link::mavlink::keys::setup_signing(&intruder, 1));
        b.signer = Some(signer([6; 32]));
        b.send(arm_message(true));
        assert!(!b.armed());
        assert_eq!(b.ap.rejected_signatures(), 2);
        // The key holder turns signing off; then anyone is obeyed again.
        b.signer = Some(signer([5; 32]));
        b.send(link::mavlink::keys::disable_signing(1));
        assert!(!b.ap.signing());
        b.signer = None;
        b.send(arm_message(true));
        assert!(b.armed());
    }

    #[test]
    fn override_gaps_are_counted_in_vehicle_time() {
        let mut b = Bench::new();
        assert_eq!(b.ap.rc_stats().quantile_ms(0.5), None);
        b.run(10.0, Some(1500), true); // an override every 0.2 s
        let stats = b.ap.rc_stats();
        assert_eq!(stats.frames, 50);
        assert_eq!(stats.quantile_ms(0.5), Some(200));
        assert_eq!(stats.quantile_ms(0.99), Some(200));
        b.run(1.0, None, true);
        b.run(1.0, Some(1500), true); // a 1.2 s silence
        assert_eq!(b.ap.rc_stats().max_ms(), Some(1200));
    }
}
