//! The station side of a shield link: RPYT packets at a fixed rate, special commands with
//! acknowledgement and retry, telemetry and link health.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::wire::{FrameDecoder, RpytRepr, Special, UpRepr, special_bytes};
use crate::address::Address;
use crate::heartbeat::{HeartbeatMonitor, VehicleClock};
use crate::rc::{ChannelMap, Sticks};
use crate::transport::{
    Connection, Transport, TransportError, Writer, duplex, is_timeout, run_sessions,
};
use crate::vehicle::{
    Battery, Command, CommandError, FlightMode, LinkStatus, StatusText, Telemetry, TextQueue,
    VehicleLink,
};

/// Shield link settings.
#[derive(Debug, Clone)]
pub struct ShieldConfig {
    /// RPYT packets per second (10–50).
    pub rc_rate_hz: f64,
    /// The vehicle's wiring.
    pub channel_map: ChannelMap,
    /// Expected telemetry period, in the vehicle's time: degraded after 1.5, lost after 5.
    pub heartbeat_period: Duration,
    /// The time the vehicle lives in (wall time for a real one).
    pub clock: VehicleClock,
    /// Wait this long for an acknowledgement before sending again.
    pub ack_timeout: Duration,
    /// Send a special command at most this many times.
    pub attempts: u32,
}

impl Default for ShieldConfig {
    fn default() -> Self {
        Self {
            rc_rate_hz: 20.0,
            channel_map: ChannelMap::thesis_naza(),
            heartbeat_period: Duration::from_millis(200),
            clock: VehicleClock::wall(),
            ack_timeout: Duration::from_millis(500),
            attempts: 3,
        }
    }
}

struct Pending {
    command: Command,
    action: Special,
    seq: u16,
    attempts: u32,
    next_send: Instant,
    reply: mpsc::Sender<Result<(), CommandError>>,
}

struct State {
    sticks: Option<Sticks>,
    telemetry: Telemetry,
    monitor: HeartbeatMonitor,
    texts: TextQueue,
    transport_up: bool,
    connections: u32,
    frames_ok: u64,
    frames_bad: u64,
    pending: VecDeque<Pending>,
    next_seq: u16,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    config: ShieldConfig,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A vehicle behind an I/O shield.
pub struct ShieldLink {
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    name: String,
}

impl ShieldLink {
    /// Opens the transport and starts talking to the shield in the background.
    pub fn connect(address: &Address, config: ShieldConfig) -> Result<Self, TransportError> {
        Ok(Self::start(Transport::open(address)?, config))
    }

    /// Starts a link over an opened transport.
    pub fn start(mut transport: Transport, config: ShieldConfig) -> Self {
        let name = format!("shield {}", transport.address());
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                sticks: None,
                telemetry: Telemetry::default(),
                monitor: HeartbeatMonitor::new(config.heartbeat_period),
                texts: TextQueue::default(),
                transport_up: false,
                connections: 0,
                frames_ok: 0,
                frames_bad: 0,
                pending: VecDeque::new(),
                next_seq: 0,
            }),
            wake: Condvar::new(),
            config,
        });
        let stop = Arc::new(AtomicBool::new(false));
        let (sh, st) = (shared.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("shield-link".into())
            .spawn(move || {
                run_sessions(
                    &mut transport,
                    &st,
                    |up| {
                        let mut s = sh.lock();
                        s.transport_up = up;
                        if up {
                            s.connections += 1;
                        }
                    },
                    |conn| session(&sh, conn, &st),
                );
                for p in sh.lock().pending.drain(..) {
                    let _ = p
                        .reply
                        .send(Err(CommandError::Closed { command: p.command }));
                }
            })
            .ok();
        Self {
            shared,
            stop,
            thread,
            name,
        }
    }
}

impl Drop for ShieldLink {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.shared.wake.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn session(shared: &Arc<Shared>, conn: Connection, stop: &AtomicBool) {
    let sh = shared.clone();
    duplex(
        conn,
        "shield-rx",
        move |reader, alive| read_loop(&sh, reader, alive),
        |writer, alive| write_loop(shared, writer, alive, stop),
    );
}

/// Sends RPYT packets at the RC rate and special packets between them until the connection
/// fails or the link stops.
fn write_loop(shared: &Shared, mut writer: Writer, alive: &AtomicBool, stop: &AtomicBool) {
    let period = Duration::from_secs_f64(1.0 / shared.config.rc_rate_hz.clamp(10.0, 50.0));
    let mut next_rc = Instant::now();
    let mut out = Vec::with_capacity(64);
    while !stop.load(Ordering::Relaxed) && alive.load(Ordering::Relaxed) {
        out.clear();
        {
            let mut s = shared.lock();
            let now = Instant::now();
            let wake_at = s
                .pending
                .iter()
                .map(|p| p.next_send)
                .chain([next_rc])
                .min()
                .unwrap_or(next_rc);
            if wake_at > now {
                let (g, _) = shared
                    .wake
                    .wait_timeout(s, wake_at - now)
                    .unwrap_or_else(PoisonError::into_inner);
                s = g;
            }
            let now = Instant::now();
            // Special commands go between packets, never inside one.
            let cfg = &shared.config;
            s.pending.retain_mut(|p| {
                if p.next_send > now {
                    return true;
                }
                if p.attempts >= cfg.attempts {
                    let _ = p.reply.send(Err(CommandError::Timeout {
                        command: p.command,
                        attempts: p.attempts,
                    }));
                    return false;
                }
                if let Ok(b) = special_bytes(p.action, p.seq) {
                    out.extend_from_slice(&b);
                }
                p.attempts += 1;
                p.next_send = now + cfg.ack_timeout;
                true
            });
            if now >= next_rc {
                let sticks = s.sticks.unwrap_or(Sticks::CENTRED);
                let mut pkt = [0u8; 8];
                if RpytRepr(cfg.channel_map.pulses(&sticks))
                    .emit(&mut pkt)
                    .is_ok()
                {
                    out.extend_from_slice(&pkt);
                }
                next_rc += period;
                if next_rc < now {
                    next_rc = now + period; // we fell behind (suspended); do not burst
                }
            }
        }
        if !out.is_empty()
            && let Err(e) = writer.write_all(&out)
        {
            tracing::warn!("shield link: write failed: {e}");
            break;
        }
    }
}

fn read_loop(shared: &Shared, mut reader: Box<dyn Read + Send>, alive: &AtomicBool) {
    let mut decoder = FrameDecoder::new();
    let mut buf = [0u8; 512];
    let mut frames = Vec::new();
    let mut last_warn: Option<Instant> = None;
    while alive.load(Ordering::Relaxed) {
        let n = match reader.read(&mut buf) {
            Ok(n) => n,
            Err(e) if is_timeout(&e) => continue,
            Err(e) => {
                tracing::warn!("shield link: read failed: {e}");
                break;
            }
        };
        frames.clear();
        decoder.push(&buf[..n], &mut frames);
        let now = Instant::now();
        let mut s = shared.state.lock().unwrap_or_else(PoisonError::into_inner);
        for f in frames.drain(..) {
            match f {
                Err(e) => {
                    s.frames_bad += 1;
                    if last_warn.is_none_or(|t| now - t > Duration::from_secs(5)) {
                        tracing::warn!(
                            "shield link: dropped input from the shield ({e}); {} so far",
                            s.frames_bad
                        );
                        last_warn = Some(now);
                    }
                }
                Ok(frame) => {
                    s.frames_ok += 1;
                    apply(&mut s, frame, shared.config.clock.now());
                }
            }
        }
    }
}

fn apply(s: &mut State, frame: UpRepr, now: Duration) {
    match frame {
        UpRepr::Telemetry(t) => {
            s.monitor.heard(now);
            let yaw = f32::from(t.yaw_cdeg).to_radians() / 100.0;
            let tm = &mut s.telemetry;
            tm.height_m = t.sonar_mm.map(|mm| f32::from(mm) / 1000.0);
            tm.yaw_rad = Some(yaw);
            tm.heading_at = Some(now);
            tm.attitude = None;
            tm.battery = Some(Battery {
                voltage_v: f32::from(t.battery_mv) / 1000.0,
                remaining_pct: None,
            });
            tm.armed = Some(t.flags.armed);
            tm.mode = Some(
                if t.flags.failsafe {
                    "FAILSAFE_LAND"
                } else if t.flags.landing {
                    "LAND"
                } else {
                    "ATTI"
                }
                .into(),
            );
            if t.rx_errors > 0 {
                tracing::warn!("shield reports {} bad commands received", t.rx_errors);
            }
        }
        UpRepr::Ack(a) => {
            if let Some(i) = s
                .pending
                .iter()
                .position(|p| p.action == a.action && p.seq == a.seq)
                && let Some(p) = s.pending.remove(i)
            {
                let r = if a.accepted {
                    Ok(())
                } else {
                    Err(CommandError::Rejected {
                        command: p.command,
                        reason: "the shield refused it".into(),
                    })
                };
                let _ = p.reply.send(r);
            }
        }
        UpRepr::Text(text) => {
            tracing::debug!("shield: {text}");
            s.texts.push(StatusText {
                severity: StatusText::WARNING,
                text,
            });
        }
    }
}

impl VehicleLink for ShieldLink {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn set_sticks(&self, sticks: Option<Sticks>) {
        self.shared.lock().sticks = sticks;
    }

    fn command(&self, command: Command) -> Result<(), CommandError> {
        let action = match command {
            Command::Arm => Special::Arm,
            Command::Disarm => Special::Disarm,
            Command::StartMotors => Special::Start,
            Command::Land | Command::SetMode(FlightMode::Land) => Special::Land,
            // The Naza flies ATTI (attitude + altitude hold) behind the shield; nothing to switch.
            Command::SetMode(FlightMode::AltHold) => return Ok(()),
            Command::SetMode(_) => {
                return Err(CommandError::Unsupported {
                    command,
                    backend: "the I/O shield",
                });
            }
        };
        let (tx, rx) = mpsc::channel();
        {
            let mut s = self.shared.lock();
            let seq = s.next_seq;
            s.next_seq = (seq + 1) % 1024;
            s.pending.push_back(Pending {
                command,
                action,
                seq,
                attempts: 0,
                next_send: Instant::now(),
                reply: tx,
            });
        }
        self.shared.wake.notify_all();
        rx.recv().unwrap_or(Err(CommandError::Closed { command }))
    }

    fn telemetry(&self) -> Telemetry {
        self.shared.lock().telemetry.clone()
    }

    fn status(&self) -> LinkStatus {
        let s = self.shared.lock();
        let now = self.shared.config.clock.now();
        LinkStatus {
            state: s.monitor.state(now),
            last_message_age: s.monitor.age(now),
            transport_up: s.transport_up,
            connections: s.connections,
            frames_ok: s.frames_ok,
            frames_bad: s.frames_bad,
        }
    }

    fn take_status_texts(&self) -> Vec<StatusText> {
        self.shared.lock().texts.take()
    }
}
