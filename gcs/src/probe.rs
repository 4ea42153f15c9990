//! `gcs link probe`: connect, show link state and telemetry, optionally set a mode, arm, hold an
//! RC override, then release and disarm.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use link::mavlink::{KeyStore, MavlinkConfig, MavlinkLink};
use link::shield::{ShieldConfig, ShieldLink};
use link::{Address, ChannelMap, Command, FlightMode, LinkState, Pulses, VehicleLink};
use serde_json::json;

/// Which protocol the vehicle speaks.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Protocol {
    /// MAVLink 2 (1 accepted): ArduPilot, PX4.
    Mavlink,
    /// The thesis's I/O shield (see link/PROTOCOL.md).
    Shield,
}

/// Arguments of `gcs link probe`.
#[derive(Args, Debug)]
pub struct ProbeArgs {
    /// serial:PATH:BAUD, tcpout:HOST:PORT, tcpin:ADDR:PORT, udpin:ADDR:PORT or udpout:HOST:PORT.
    address: String,
    /// The vehicle's protocol.
    #[arg(long, value_enum, default_value = "mavlink")]
    protocol: Protocol,
    /// Arm before holding the override (and disarm at the end).
    #[arg(long)]
    arm: bool,
    /// Set this flight mode first (STABILIZE, ALT_HOLD, LOITER, GUIDED, LAND).
    #[arg(long)]
    mode: Option<FlightMode>,
    /// Hold this RC override, in µs: ROLL,PITCH,THROTTLE,YAW.
    #[arg(long, value_name = "ROLL,PITCH,THROTTLE,YAW")]
    rc: Option<String>,
    /// How long to watch (and hold the override), seconds.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Give up if the vehicle has not answered within this many seconds.
    #[arg(long, default_value_t = 10.0)]
    wait: f64,
    /// MAVLink system id of the vehicle (default: the first one heard).
    #[arg(long)]
    sysid: Option<u8>,
    /// MAVLink 2 signing key (sign and check every frame): a name in the key store (`gcs key
    /// list`) or a key file's path.
    #[arg(long, value_name = "KEY")]
    signing_key: Option<String>,
    /// Record every MAVLink frame in and out to this `.tlog` file.
    #[arg(long, value_name = "FILE")]
    tlog: Option<PathBuf>,
    /// One JSON object per line instead of text.
    #[arg(long)]
    json: bool,
}

fn parse_rc(s: &str, map: &ChannelMap) -> anyhow::Result<Pulses> {
    let v: Vec<u16> = s
        .split(',')
        .map(|x| x.trim().parse::<u16>())
        .collect::<Result<_, _>>()
        .with_context(|| {
            format!("--rc {s:?}: expected four pulse widths in µs, e.g. 1500,1500,1300,1500")
        })?;
    let [roll, pitch, throttle, yaw] = v[..] else {
        bail!(
            "--rc {s:?}: expected four values ROLL,PITCH,THROTTLE,YAW, got {}",
            v.len()
        );
    };
    for (name, us) in [
        ("roll", roll),
        ("pitch", pitch),
        ("throttle", throttle),
        ("yaw", yaw),
    ] {
        if !(map.min_us..=map.max_us).contains(&us) {
            bail!(
                "--rc {name} {us} µs is outside this vehicle's {}–{} µs range",
                map.min_us,
                map.max_us
            );
        }
    }
    Ok(Pulses {
        roll,
        pitch,
        yaw,
        throttle,
    })
}

struct Printer {
    json: bool,
    start: Instant,
}

impl Printer {
    fn event(&self, value: serde_json::Value, text: String) {
        if self.json {
            let mut v = value;
            v["t"] = json!((self.start.elapsed().as_secs_f64() * 1000.0).round() / 1000.0);
            println!("{v}");
        } else {
            println!("[{:6.2} s] {text}", self.start.elapsed().as_secs_f64());
        }
    }

    fn status(&self, v: &dyn VehicleLink) {
        let s = v.status();
        let t = v.telemetry();
        let age = s.last_message_age.map(|a| a.as_secs_f64());
        let value = json!({
            "event": "status",
            "link": s.state.name(),
            "last_message_age_s": age,
            "transport_up": s.transport_up,
            "frames_ok": s.frames_ok,
            "frames_bad": s.frames_bad,
            "armed": t.armed,
            "mode": t.mode,
            "height_m": t.height_m,
            "yaw_deg": t.yaw_rad.map(f32::to_degrees),
            "roll_deg": t.attitude.map(|a| a.roll.to_degrees()),
            "pitch_deg": t.attitude.map(|a| a.pitch.to_degrees()),
            "battery_v": t.battery.map(|b| b.voltage_v),
            "battery_pct": t.battery.and_then(|b| b.remaining_pct),
            "position_m": t.position_m,
        });
        let fmt =
            |x: Option<f32>, unit: &str| x.map_or("-".to_owned(), |x| format!("{x:.2}{unit}"));
        let text = format!(
            "link {} (last message {}), armed {}, mode {}, height {}, yaw {}, battery {}, frames {} ok / {} bad",
            s.state.name(),
            age.map_or("never".into(), |a| format!("{a:.2} s ago")),
            t.armed.map_or("-".into(), |a| a.to_string()),
            t.mode.as_deref().unwrap_or("-"),
            fmt(t.height_m, " m"),
            fmt(t.yaw_rad.map(f32::to_degrees), "°"),
            fmt(t.battery.map(|b| b.voltage_v), " V"),
            s.frames_ok,
            s.frames_bad,
        );
        self.event(value, text);
        for st in v.take_status_texts() {
            self.event(
                json!({"event": "statustext", "severity": st.severity, "text": st.text}),
                format!("vehicle says: {}", st.text),
            );
        }
    }

    fn command(&self, v: &dyn VehicleLink, command: Command) -> anyhow::Result<()> {
        let r = v.command(command);
        self.event(
            json!({"event": "command", "command": command.to_string(), "ok": r.is_ok(), "error": r.as_ref().err().map(|e| e.to_string())}),
            match &r {
                Ok(()) => format!("{command}: done"),
                Err(e) => format!("{command}: {e}"),
            },
        );
        r.map_err(Into::into)
    }
}

/// Runs the probe.
pub fn run(args: &ProbeArgs) -> anyhow::Result<()> {
    let address: Address = args.address.parse()?;
    if !(args.seconds.is_finite()
        && args.seconds >= 0.0
        && args.wait.is_finite()
        && args.wait > 0.0)
    {
        bail!("--seconds must be zero or more and --wait more than zero");
    }
    let map = match args.protocol {
        Protocol::Mavlink => MavlinkConfig::default().channel_map,
        Protocol::Shield => ShieldConfig::default().channel_map,
    };
    // Check all input before touching the vehicle.
    let rc = args.rc.as_deref().map(|s| parse_rc(s, &map)).transpose()?;
    if args.tlog.is_some() && matches!(args.protocol, Protocol::Shield) {
        bail!("--tlog records MAVLink frames; the shield protocol has none");
    }
    let p = Printer {
        json: args.json,
        start: Instant::now(),
    };
    let wait = Duration::from_secs_f64(args.wait);
    let vehicle: Arc<dyn VehicleLink> = match args.protocol {
        Protocol::Mavlink => {
            let mut config = MavlinkConfig::default();
            if let Some(key) = &args.signing_key {
                config.signing = Some(KeyStore::user()?.load(key)?);
            }
            let link = MavlinkLink::connect(&address, config)?;
            if let Some(path) = &args.tlog {
                link.record_to(path).with_context(|| {
                    format!("cannot write the telemetry log {}", path.display())
                })?;
            }
            let vehicle = match args.sysid {
                Some(id) => {
                    let v = link.vehicle(id);
                    wait_until(wait, || v.status().state != LinkState::Connecting);
                    v
                }
                None => match link.wait_for_vehicle(wait) {
                    Some(v) => v,
                    None => bail!(
                        "no MAVLink heartbeat on {address} within {:.0} s: check the address, the baud rate, and that the vehicle is powered",
                        args.wait
                    ),
                },
            };
            Arc::new(vehicle)
        }
        Protocol::Shield => {
            let config = ShieldConfig {
                channel_map: map,
                ..ShieldConfig::default()
            };
            Arc::new(ShieldLink::connect(&address, config)?)
        }
    };
    if !wait_until(wait, || vehicle.status().state == LinkState::Connected) {
        bail!(
            "{} never answered within {:.0} s: check the address, the baud rate, the protocol, and that the vehicle is powered",
            vehicle.name(),
            args.wait
        );
    }
    // Let the first telemetry arrive before the first report.
    std::thread::sleep(Duration::from_millis(300));
    p.event(
        json!({"event": "connected", "vehicle": vehicle.name()}),
        format!("connected to {}", vehicle.name()),
    );
    p.status(vehicle.as_ref());
    if let Some(mode) = args.mode {
        p.command(vehicle.as_ref(), Command::SetMode(mode))?;
    }
    if args.arm {
        p.command(vehicle.as_ref(), Command::Arm)?;
    }
    if let Some(pulses) = rc {
        vehicle.set_sticks(Some(map.sticks(&pulses)));
        p.event(
            json!({"event": "rc", "roll": pulses.roll, "pitch": pulses.pitch, "throttle": pulses.throttle, "yaw": pulses.yaw}),
            format!("holding RC override {pulses:?} for {:.1} s", args.seconds),
        );
    }
    let end = Instant::now() + Duration::from_secs_f64(args.seconds);
    let mut lost = false;
    while Instant::now() < end {
        std::thread::sleep(
            Duration::from_secs(1).min(end.saturating_duration_since(Instant::now())),
        );
        p.status(vehicle.as_ref());
        lost |= vehicle.status().state == LinkState::Lost;
    }
    if rc.is_some() {
        vehicle.set_sticks(None);
        p.event(
            json!({"event": "rc_released"}),
            "RC override released".into(),
        );
    }
    if args.arm {
        p.command(vehicle.as_ref(), Command::Disarm)?;
    }
    // Give the release frames time to go out before the link closes.
    std::thread::sleep(Duration::from_millis(200));
    if lost {
        bail!("the link to {} was lost during the probe", vehicle.name());
    }
    Ok(())
}

fn wait_until(limit: Duration, mut ok: impl FnMut() -> bool) -> bool {
    let until = Instant::now() + limit;
    while Instant::now() < until {
        if ok() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rc_values_are_checked() {
        let m = ChannelMap::ardupilot();
        assert_eq!(
            parse_rc("1500,1400,1300,1600", &m).unwrap(),
            Pulses {
                roll: 1500,
                pitch: 1400,
                throttle: 1300,
                yaw: 1600
            }
        );
        assert!(
            parse_rc("1500,1500,1500", &m)
                .unwrap_err()
                .to_string()
                .contains("got 3")
        );
        assert!(
            parse_rc("1500,x,1500,1500", &m)
                .unwrap_err()
                .to_string()
                .contains("four pulse widths")
        );
        assert!(
            parse_rc("1000,1500,1500,1500", &m)
                .unwrap_err()
                .to_string()
                .contains("outside")
        );
    }
}
