//! A shield firmware model: what the board on the drone does with the bytes it receives. Used by
//! tests and by the simulator, over any [`Connection`] (pseudo-terminal, TCP).
//!
//! Time is passed in as a [`Duration`] since an arbitrary start, so a simulator can drive it with
//! simulated time.

use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::wire::{AckRepr, Event, Receiver, ShieldFlags, Special, TelemetryRepr, UpRepr};
use crate::rc::{ChannelMap, Pulses, Sticks};
use crate::transport::{Connection, Transport, is_timeout, run_sessions};

/// Emulator settings (the firmware's constants).
#[derive(Debug, Clone)]
pub struct EmulatorConfig {
    /// No valid command for this long while armed: failsafe landing.
    pub failsafe_after: Duration,
    /// Give up landing and disarm after this long.
    pub land_timeout: Duration,
    /// How the outputs are wired (needed to centre sticks and descend in failsafe).
    pub channel_map: ChannelMap,
    /// Telemetry period.
    pub telemetry_period: Duration,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            failsafe_after: Duration::from_secs(1),
            land_timeout: Duration::from_secs(20),
            channel_map: ChannelMap::thesis_naza(),
            telemetry_period: Duration::from_millis(100),
        }
    }
}

/// Sensor readings the shield reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensors {
    /// Sonar height, mm (`None`: no echo).
    pub sonar_mm: Option<u16>,
    /// IMU yaw, centi-degrees.
    pub yaw_cdeg: i16,
    /// Battery, mV.
    pub battery_mv: u16,
}

impl Default for Sensors {
    fn default() -> Self {
        Self {
            sonar_mm: Some(0),
            yaw_cdeg: 0,
            battery_mv: 12_600,
        }
    }
}

/// The shield firmware state machine.
#[derive(Debug)]
pub struct ShieldEmulator {
    config: EmulatorConfig,
    receiver: Receiver,
    outputs: Option<Pulses>,
    flags: ShieldFlags,
    last_valid: Option<Duration>,
    landing_since: Option<Duration>,
    low_since: Option<Duration>,
    last_seq: [Option<u16>; 4],
    rx_errors: u8,
    /// Every command received intact.
    pub commands_ok: u64,
    /// Every command dropped (resynchronisation, parity, range).
    pub commands_bad: u64,
    sensors: Sensors,
    upstream: Vec<u8>,
    last_telemetry: Option<Duration>,
    history: Vec<Pulses>,
}

const HISTORY_CAP: usize = 8192;

impl ShieldEmulator {
    /// A powered-up shield: disarmed, outputs idle.
    pub fn new(config: EmulatorConfig) -> Self {
        Self {
            config,
            receiver: Receiver::new(),
            outputs: None,
            flags: ShieldFlags::default(),
            last_valid: None,
            landing_since: None,
            low_since: None,
            last_seq: [None; 4],
            rx_errors: 0,
            commands_ok: 0,
            commands_bad: 0,
            sensors: Sensors::default(),
            upstream: vec![],
            last_telemetry: None,
            history: vec![],
        }
    }

    /// The pulses on the four outputs, `None` before the first command.
    pub fn outputs(&self) -> Option<Pulses> {
        self.outputs
    }

    /// The outputs applied so far (the most recent 8192), for tests.
    pub fn history(&self) -> &[Pulses] {
        &self.history
    }

    /// Status flags.
    pub fn flags(&self) -> ShieldFlags {
        self.flags
    }

    /// Updates the sensor readings reported upstream.
    pub fn set_sensors(&mut self, sensors: Sensors) {
        self.sensors = sensors;
    }

    /// Queues a text message for the station (what the firmware prints, e.g. a collision).
    pub fn report(&mut self, text: &str) {
        UpRepr::Text(text.into()).emit(&mut self.upstream);
    }

    /// Queues raw bytes for the station, e.g. noise for a fault-injection test.
    pub fn queue_upstream_raw(&mut self, bytes: &[u8]) {
        self.upstream.extend_from_slice(bytes);
    }

    /// Takes the bytes to send to the station.
    pub fn take_upstream(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.upstream)
    }

    fn apply(&mut self, pulses: Pulses) {
        self.outputs = Some(pulses);
        if self.history.len() == HISTORY_CAP {
            self.history.drain(..HISTORY_CAP / 2);
        }
        self.history.push(pulses);
    }

    /// Feeds received bytes at time `now`.
    pub fn receive(&mut self, bytes: &[u8], now: Duration) {
        for &b in bytes {
            match self.receiver.push(b) {
                None => {}
                Some(Event::Dropped(e)) => {
                    self.commands_bad += 1;
                    self.rx_errors = self.rx_errors.saturating_add(1);
                    tracing::debug!("shield dropped input: {e}");
                }
                Some(event) => {
                    self.commands_ok += 1;
                    self.last_valid = Some(now);
                    self.execute(event, now);
                }
            }
        }
        self.tick(now);
    }

    fn execute(&mut self, event: Event, now: Duration) {
        match event {
            Event::Dropped(_) => {}
            Event::Pulses(p) => match (self.flags.landing, self.flags.failsafe, self.outputs) {
                (false, _, _) => self.apply(p),
                // A commanded landing owns the throttle (its slow descent); roll, pitch and yaw
                // still pass, so the station can hold the drone's position as it comes down.
                (true, false, Some(landing)) => self.apply(Pulses {
                    throttle: landing.throttle,
                    ..p
                }),
                // A failsafe landing owns every output.
                (true, true, _) | (true, false, None) => {}
            },
            Event::Special { action, seq } => {
                let slot = usize::from(action.id() - 4);
                let repeat = self.last_seq[slot] == Some(seq);
                let accepted = if repeat {
                    true
                } else {
                    self.special(action, now)
                };
                if !repeat && accepted {
                    self.last_seq[slot] = Some(seq);
                }
                UpRepr::Ack(AckRepr {
                    action,
                    seq,
                    accepted,
                })
                .emit(&mut self.upstream);
            }
        }
    }

    fn special(&mut self, action: Special, now: Duration) -> bool {
        match action {
            Special::Arm => {
                if self.flags.landing {
                    return false;
                }
                self.flags.armed = true;
                self.flags.failsafe = false;
                true
            }
            Special::Start => {
                if !self.flags.armed || self.flags.landing {
                    return false;
                }
                self.flags.motors_running = true;
                true
            }
            Special::Disarm => {
                self.disarm();
                true
            }
            Special::Land => {
                if !self.flags.armed {
                    return true; // already on the ground
                }
                self.start_landing(now, "land command: landing");
                true
            }
        }
    }

    fn disarm(&mut self) {
        self.flags.armed = false;
        self.flags.motors_running = false;
        self.flags.landing = false;
        self.landing_since = None;
        self.low_since = None;
        let idle = self.config.channel_map.pulses(&Sticks {
            throttle: -1.0,
            ..Sticks::CENTRED
        });
        self.apply(idle);
    }

    fn start_landing(&mut self, now: Duration, why: &str) {
        if self.flags.landing {
            return;
        }
        self.flags.landing = true;
        self.landing_since = Some(now);
        UpRepr::Text(why.into()).emit(&mut self.upstream);
        let descend = self.config.channel_map.pulses(&Sticks {
            throttle: super::LAND_THROTTLE,
            ..Sticks::CENTRED
        });
        self.apply(descend);
    }

    /// Advances time: link-loss failsafe, landing, telemetry.
    pub fn tick(&mut self, now: Duration) {
        if self.flags.armed && !self.flags.failsafe {
            let since = self
                .last_valid
                .map_or(Duration::MAX, |t| now.saturating_sub(t));
            if since >= self.config.failsafe_after {
                self.flags.failsafe = true;
                let s = self.config.failsafe_after.as_secs_f32();
                self.start_landing(now, &format!("failsafe: no commands for {s:.1} s, landing"));
            }
        }
        if let Some(since) = self.landing_since {
            let low = self.sensors.sonar_mm.is_some_and(|mm| mm < 100);
            self.low_since = if low {
                self.low_since.or(Some(now))
            } else {
                None
            };
            let landed = self
                .low_since
                .is_some_and(|t| now.saturating_sub(t) >= Duration::from_secs(1));
            if landed || now.saturating_sub(since) >= self.config.land_timeout {
                UpRepr::Text("landed: disarmed".into()).emit(&mut self.upstream);
                self.disarm();
            }
        }
        let due = self
            .last_telemetry
            .is_none_or(|t| now.saturating_sub(t) >= self.config.telemetry_period);
        if due {
            self.last_telemetry = Some(now);
            UpRepr::Telemetry(TelemetryRepr {
                sonar_mm: self.sensors.sonar_mm,
                yaw_cdeg: self.sensors.yaw_cdeg,
                battery_mv: self.sensors.battery_mv,
                flags: self.flags,
                rx_errors: std::mem::take(&mut self.rx_errors),
            })
            .emit(&mut self.upstream);
        }
    }
}

/// The firmware's clock: time since the shield powered up (real or simulated).
pub type Clock = Arc<dyn Fn() -> Duration + Send + Sync>;

/// Runs a [`ShieldEmulator`] on one connection until `stop` or the connection fails: reads
/// commands, writes acknowledgements and telemetry.
pub fn serve(
    emulator: &Mutex<ShieldEmulator>,
    mut conn: Connection,
    stop: &AtomicBool,
    clock: &Clock,
) {
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        let got = match conn.reader.read(&mut buf) {
            Ok(n) => n,
            Err(e) if is_timeout(&e) => 0,
            // A pseudo-terminal whose other side is not open yet reads as an I/O error.
            Err(e) if e.kind() == ErrorKind::Other || e.raw_os_error() == Some(5) => {
                std::thread::sleep(Duration::from_millis(20));
                0
            }
            Err(e) => {
                tracing::warn!("shield emulator: read failed: {e}");
                return;
            }
        };
        let up = {
            let mut em = emulator.lock().unwrap_or_else(PoisonError::into_inner);
            em.receive(&buf[..got], clock());
            em.take_upstream()
        };
        if !up.is_empty()
            && let Err(e) = conn.writer.write_all(&up)
        {
            tracing::warn!("shield emulator: write failed: {e}");
            return;
        }
    }
}

/// A shield emulator serving a transport on its own thread, reconnecting like real hardware
/// (a new TCP client gets the same shield). The firmware's clock runs whether or not anyone is
/// connected, so the link-loss failsafe fires when the station disappears.
pub struct EmulatorServer {
    emulator: Arc<Mutex<ShieldEmulator>>,
    connected: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl EmulatorServer {
    /// Serves `transport` (e.g. `tcpin:127.0.0.1:0`) with a new emulator on a real-time clock.
    pub fn spawn(transport: Transport, config: EmulatorConfig) -> Self {
        let start = Instant::now();
        let mut server =
            Self::spawn_simulated(transport, config, Arc::new(move || start.elapsed()));
        server.start_clock(start);
        server
    }

    /// Serves `transport` with a new emulator whose time is `clock` (a simulator's). Nothing
    /// ticks it: the owner calls [`EmulatorServer::tick`] as its time advances.
    pub fn spawn_simulated(mut transport: Transport, config: EmulatorConfig, clock: Clock) -> Self {
        Self::start(config, move |em, stop, connected| {
            run_sessions(
                &mut transport,
                stop,
                |up| connected.store(up, Ordering::Relaxed),
                |conn| serve(em, conn, stop, &clock),
            );
        })
    }

    /// Serves one already-open connection (e.g. the master side of a pseudo-terminal pair).
    pub fn spawn_on(conn: Connection, config: EmulatorConfig) -> Self {
        let start = Instant::now();
        let clock: Clock = Arc::new(move || start.elapsed());
        let mut server = Self::start(config, move |em, stop, connected| {
            connected.store(true, Ordering::Relaxed);
            serve(em, conn, stop, &clock);
            connected.store(false, Ordering::Relaxed);
        });
        server.start_clock(start);
        server
    }

    fn start(
        config: EmulatorConfig,
        io: impl FnOnce(&Mutex<ShieldEmulator>, &AtomicBool, &AtomicBool) + Send + 'static,
    ) -> Self {
        let emulator = Arc::new(Mutex::new(ShieldEmulator::new(config)));
        let stop = Arc::new(AtomicBool::new(false));
        let connected = Arc::new(AtomicBool::new(false));
        let (em, st, co) = (emulator.clone(), stop.clone(), connected.clone());
        let threads = std::thread::Builder::new()
            .name("shield-emulator".into())
            .spawn(move || io(&em, &st, &co))
            .ok()
            .into_iter()
            .collect();
        Self {
            emulator,
            connected,
            stop,
            threads,
        }
    }

    /// Ticks the firmware every 20 ms of real time.
    fn start_clock(&mut self, start: Instant) {
        let (em, st, co) = (
            self.emulator.clone(),
            self.stop.clone(),
            self.connected.clone(),
        );
        let clock = std::thread::Builder::new()
            .name("shield-clock".into())
            .spawn(move || {
                while !st.load(Ordering::Relaxed) {
                    tick(&em, &co, start.elapsed());
                    std::thread::sleep(Duration::from_millis(20));
                }
            });
        self.threads.extend(clock.ok());
    }

    /// Advances the firmware's clock to `now`: failsafe, landing, telemetry. Telemetry nobody
    /// is connected to read is dropped, like a UART with nobody listening.
    pub fn tick(&self, now: Duration) {
        tick(&self.emulator, &self.connected, now);
    }

    /// Stops serving the transport, as a radio that dies: the connection closes and nothing
    /// more arrives, while the firmware keeps running on [`EmulatorServer::tick`] (so its
    /// link-loss failsafe lands the vehicle).
    pub fn disconnect(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// True while a station is connected.
    pub fn connected(&self) -> bool {
        self.connected.load(Ordering::Relaxed)
    }

    /// Runs `f` on the emulator's state.
    pub fn with<R>(&self, f: impl FnOnce(&mut ShieldEmulator) -> R) -> R {
        f(&mut self.emulator.lock().unwrap_or_else(PoisonError::into_inner))
    }
}

fn tick(emulator: &Mutex<ShieldEmulator>, connected: &AtomicBool, now: Duration) {
    let mut e = emulator.lock().unwrap_or_else(PoisonError::into_inner);
    e.tick(now);
    if !connected.load(Ordering::Relaxed) {
        e.take_upstream();
    }
}

impl Drop for EmulatorServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shield::wire::{FrameDecoder, RpytRepr};

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn special(action: Special, seq: u16) -> [u8; 8] {
        crate::shield::wire::special_bytes(action, seq).unwrap()
    }

    fn rpyt(pulses: Pulses) -> [u8; 8] {
        let mut pkt = [0u8; 8];
        RpytRepr(pulses).emit(&mut pkt).unwrap();
        pkt
    }

    fn acks(em: &mut ShieldEmulator) -> Vec<AckRepr> {
        let mut out = vec![];
        FrameDecoder::new().push(&em.take_upstream(), &mut out);
        out.into_iter()
            .filter_map(|r| match r {
                Ok(UpRepr::Ack(a)) => Some(a),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn rpyt_sets_outputs_and_specials_are_acked_once() {
        let mut em = ShieldEmulator::new(EmulatorConfig::default());
        let p = Pulses {
            roll: 1400,
            pitch: 1600,
            yaw: 1500,
            throttle: 1900,
        };
        em.receive(&rpyt(p), ms(0));
        assert_eq!(em.outputs(), Some(p));
        em.receive(&special(Special::Start, 1), ms(10));
        assert_eq!(
            acks(&mut em),
            vec![AckRepr {
                action: Special::Start,
                seq: 1,
                accepted: false
            }]
        );
        em.receive(&special(Special::Arm, 2), ms(20));
        em.receive(&special(Special::Arm, 2), ms(30)); // retry of the same command
        assert_eq!(acks(&mut em).len(), 2);
        assert!(em.flags().armed);
    }

    #[test]
    fn link_loss_lands_then_disarms() {
        let mut em = ShieldEmulator::new(EmulatorConfig::default());
        em.receive(&special(Special::Arm, 1), ms(0));
        em.receive(&special(Special::Start, 2), ms(10));
        em.set_sensors(Sensors {
            sonar_mm: Some(1500),
            ..Sensors::default()
        });
        em.tick(ms(900));
        assert!(!em.flags().failsafe);
        em.tick(ms(1010));
        assert!(em.flags().failsafe && em.flags().landing);
        // Descending: throttle below mid on the reversed Naza wiring means a pulse above 1500.
        let out = em.outputs().unwrap();
        // (-0.3 to within the pulse's 1 µs step beyond the dead zone.)
        let throttle = em.config.channel_map.sticks(&out).throttle;
        assert!((throttle + 0.3).abs() <= 1.0 / 475.0, "{throttle}");
        // New sticks do not override the landing.
        let all_low = Pulses {
            roll: 1000,
            pitch: 1000,
            yaw: 1000,
            throttle: 1000,
        };
        em.receive(&rpyt(all_low), ms(1100));
        assert_eq!(em.outputs(), Some(out));
        em.set_sensors(Sensors {
            sonar_mm: Some(50),
            ..Sensors::default()
        });
        em.tick(ms(2000));
        assert!(em.flags().armed);
        em.tick(ms(3100));
        assert!(!em.flags().armed && !em.flags().landing);
    }

    #[test]
    fn a_commanded_landing_keeps_its_descent_and_lets_the_station_steer() {
        let mut em = ShieldEmulator::new(EmulatorConfig::default());
        em.set_sensors(Sensors {
            sonar_mm: Some(800),
            ..Sensors::default()
        });
        em.receive(&special(Special::Arm, 1), ms(0));
        em.receive(&special(Special::Start, 2), ms(10));
        em.receive(&special(Special::Land, 3), ms(20));
        assert!(em.flags().landing && !em.flags().failsafe);
        let descent = em.outputs().unwrap();
        let steer = Pulses {
            roll: 1400,
            pitch: 1620,
            yaw: 1480,
            throttle: 1900,
        };
        em.receive(&rpyt(steer), ms(100));
        // Roll, pitch and yaw as sent; the throttle is still the landing's, not the climb sent.
        assert_eq!(
            em.outputs(),
            Some(Pulses {
                throttle: descent.throttle,
                ..steer
            })
        );
        assert!(em.flags().landing);
    }

    #[test]
    fn landing_gives_up_after_the_timeout() {
        let mut em = ShieldEmulator::new(EmulatorConfig::default());
        em.set_sensors(Sensors {
            sonar_mm: None,
            ..Sensors::default()
        });
        em.receive(&special(Special::Arm, 1), ms(0));
        em.receive(&special(Special::Land, 1), ms(0));
        em.tick(ms(19_000));
        assert!(em.flags().armed);
        em.tick(ms(20_001));
        assert!(!em.flags().armed);
    }
}
