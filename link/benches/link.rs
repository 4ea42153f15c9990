//! Link benchmarks: `cargo bench -p link` (add `-- --quick` for a short run).
//!
//! * shield protocol: RPYT encode and receive throughput;
//! * MAVLink: RC_CHANNELS_OVERRIDE encode, and decoding the shared ArduCopter `.tlog`, side by side
//!   with pymavlink on the same file (when `target/pyenv` exists: `bash tests/python/setup.sh`);
//! * RC frame jitter: 8 MAVLink vehicles at 50 Hz over loopback UDP, measured where the frames
//!   arrive.

use std::hint::black_box;
use std::net::UdpSocket;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use link::mavlink::frame::{FrameScanner, encode};
use link::mavlink::{MavMessage, MavlinkConfig, MavlinkLink, MavlinkVersion};
use link::shield::wire::{Event, Receiver, RpytRepr};
use link::tlog::TlogReader;
use link::{LinkState, Pulses, Sticks, VehicleLink};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    println!(
        "link benchmarks ({} run)\n",
        if quick { "quick" } else { "full" }
    );
    shield(quick);
    mavlink_encode(quick);
    tlog(quick);
    rc_jitter(8, 50.0, if quick { 3.0 } else { 10.0 });
}

fn rate(label: &str, n: f64, unit: &str, secs: f64) {
    println!(
        "{label:<48} {:>12.0} {unit}/s   ({n:.0} in {secs:.3} s)",
        n / secs
    );
}

/// The i-th packet of a sweep over every pulse width.
fn packet(i: usize) -> RpytRepr {
    let us = 1000 + (i % 1001) as u16;
    RpytRepr(Pulses {
        roll: us,
        pitch: us,
        yaw: us,
        throttle: us,
    })
}

fn shield(quick: bool) {
    let n = if quick { 200_000 } else { 2_000_000 };
    let mut out = [0u8; 8];
    let t = Instant::now();
    for i in 0..n {
        packet(i).emit(&mut out).ok();
        black_box(&out);
    }
    rate(
        "shield: encode RPYT packets",
        n as f64,
        "packets",
        t.elapsed().as_secs_f64(),
    );

    let mut stream = Vec::with_capacity(n * 8);
    for i in 0..n {
        packet(i).emit(&mut out).ok();
        stream.extend_from_slice(&out);
    }
    let mut r = Receiver::new();
    let mut packets = 0u64;
    let t = Instant::now();
    for &b in &stream {
        if let Some(Event::Pulses(p)) = r.push(b) {
            packets += 1;
            black_box(p);
        }
    }
    let s = t.elapsed().as_secs_f64();
    assert_eq!(packets, n as u64);
    rate("shield: receive RPYT packets", packets as f64, "packets", s);
    println!(
        "{:<48} {:>12.1} MB/s\n",
        "shield: receive throughput",
        stream.len() as f64 / s / 1e6
    );
}

fn mavlink_encode(quick: bool) {
    let n = if quick { 100_000 } else { 1_000_000 };
    let map = link::ChannelMap::ardupilot();
    let ch = map.override_channels(&Sticks {
        roll: 0.1,
        pitch: 0.2,
        yaw: 0.3,
        throttle: 0.4,
    });
    let msg = MavMessage::RC_CHANNELS_OVERRIDE(
        ::mavlink::dialects::ardupilotmega::RC_CHANNELS_OVERRIDE_DATA {
            chan1_raw: ch[0],
            chan2_raw: ch[1],
            chan3_raw: ch[2],
            chan4_raw: ch[3],
            target_system: 1,
            target_component: 1,
            ..Default::default()
        },
    );
    let t = Instant::now();
    for i in 0..n {
        let h = ::mavlink::MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: i as u8,
        };
        black_box(encode(MavlinkVersion::V2, h, &msg, None));
    }
    rate(
        "mavlink: encode RC_CHANNELS_OVERRIDE frames",
        n as f64,
        "frames",
        t.elapsed().as_secs_f64(),
    );
}

fn tlog(quick: bool) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/mavlink/ArduCopter-DynamicNotches-autotest-1746714528149261.tlog");
    let Ok(bytes) = std::fs::read(&path) else {
        println!("tlog: {} not found; skipped\n", path.display());
        return;
    };
    let runs = if quick { 1 } else { 5 };
    let mut best = f64::MAX;
    let mut msgs = 0;
    for _ in 0..runs {
        let t = Instant::now();
        msgs = TlogReader::new(&bytes[..])
            .filter_map(Result::ok)
            .filter(|r| r.frame.decode().is_ok())
            .count();
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!(
        "{:<48} {:>12.0} msgs/s   ({msgs} messages, {:.1} MB in {best:.3} s, best of {runs})",
        "tlog: read + decode (this crate)",
        msgs as f64 / best,
        bytes.len() as f64 / 1e6
    );
    // The same file through pymavlink, in the same run.
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pyenv/bin/python");
    if !python.exists() {
        println!("tlog: pymavlink reference skipped (run `bash tests/python/setup.sh`)\n");
        return;
    }
    let script = r#"
import sys, time
from pymavlink import mavutil
t = time.perf_counter()
m = mavutil.mavlink_connection(sys.argv[1], dialect='ardupilotmega')
n = 0
while True:
    msg = m.recv_msg()
    if msg is None:
        break
    if msg.get_type() != 'BAD_DATA':
        n += 1
print(n, time.perf_counter() - t)
"#;
    match std::process::Command::new(&python)
        .args(["-c", script, &path.to_string_lossy()])
        .output()
    {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            let mut it = text.split_whitespace();
            let (n, s): (f64, f64) = (
                it.next().and_then(|x| x.parse().ok()).unwrap_or(0.0),
                it.next().and_then(|x| x.parse().ok()).unwrap_or(f64::NAN),
            );
            println!(
                "{:<48} {:>12.0} msgs/s   ({n:.0} messages in {s:.3} s)",
                "tlog: read + decode (pymavlink 2.4.50)",
                n / s
            );
            println!(
                "{:<48} {:>12.1}x\n",
                "tlog: speed-up over pymavlink",
                (msgs as f64 / best) / (n / s)
            );
        }
        Ok(out) => println!(
            "tlog: pymavlink failed: {}\n",
            String::from_utf8_lossy(&out.stderr)
        ),
        Err(e) => println!("tlog: pymavlink could not run: {e}\n"),
    }
}

/// A minimal vehicle on a UDP socket: answers with heartbeats, timestamps RC overrides.
fn fake_vehicle(socket: UdpSocket, sysid: u8, stop: Arc<AtomicBool>) -> Vec<Instant> {
    socket.set_read_timeout(Some(Duration::from_millis(5))).ok();
    let mut buf = [0u8; 2048];
    let mut peer = None;
    let mut next_hb = Instant::now();
    let mut arrivals = Vec::new();
    let hb = MavMessage::HEARTBEAT(::mavlink::dialects::ardupilotmega::HEARTBEAT_DATA {
        mavtype: ::mavlink::dialects::ardupilotmega::MavType::MAV_TYPE_QUADROTOR,
        autopilot: ::mavlink::dialects::ardupilotmega::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: ::mavlink::dialects::ardupilotmega::MavModeFlag::empty(),
        ..Default::default()
    });
    while !stop.load(Ordering::Relaxed) {
        if let Ok((n, from)) = socket.recv_from(&mut buf) {
            let now = Instant::now();
            peer = Some(from);
            let mut s = FrameScanner::new();
            s.push(&buf[..n]);
            while let Some(f) = s.next_frame() {
                if f.message_id() == 70 {
                    arrivals.push(now);
                }
            }
        }
        if let Some(p) = peer
            && Instant::now() >= next_hb
        {
            let h = ::mavlink::MavHeader {
                system_id: u32::from(sysid),
                component_id: 1,
                sequence: 0,
            };
            socket
                .send_to(&encode(MavlinkVersion::V2, h, &hb, None), p)
                .ok();
            next_hb += Duration::from_secs(1);
        }
    }
    arrivals
}

fn rc_jitter(vehicles: usize, hz: f64, seconds: f64) {
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = vec![];
    let mut links = vec![];
    for i in 0..vehicles {
        let Ok(socket) = UdpSocket::bind("127.0.0.1:0") else {
            return;
        };
        let Ok(port) = socket.local_addr().map(|a| a.port()) else {
            return;
        };
        let st = stop.clone();
        threads.push(std::thread::spawn(move || {
            fake_vehicle(socket, i as u8 + 1, st)
        }));
        let config = MavlinkConfig {
            rc_rate_hz: hz,
            ..MavlinkConfig::default()
        };
        let Ok(address) = format!("udpout:127.0.0.1:{port}").parse() else {
            return;
        };
        let Ok(link) = MavlinkLink::connect(&address, config) else {
            return;
        };
        links.push(link);
    }
    let vs: Vec<_> = links
        .iter()
        .enumerate()
        .map(|(i, l)| l.vehicle(i as u8 + 1))
        .collect();
    let until = Instant::now() + Duration::from_secs(5);
    while vs.iter().any(|v| v.status().state != LinkState::Connected) && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(10));
    }
    for v in &vs {
        v.set_sticks(Some(Sticks::CENTRED));
    }
    std::thread::sleep(Duration::from_secs_f64(seconds));
    stop.store(true, Ordering::Relaxed);
    drop(vs);
    drop(links);
    let period = 1.0 / hz;
    let mut gaps = vec![];
    let mut frames = 0;
    for t in threads {
        let arrivals = t.join().unwrap_or_default();
        // Skip the first second (start-up) and the release frames at the end.
        let start = arrivals.first().copied();
        let steady: Vec<Instant> = arrivals
            .into_iter()
            .filter(|a| start.is_some_and(|s| a.duration_since(s).as_secs_f64() > 1.0))
            .collect();
        frames += steady.len();
        gaps.extend(
            steady
                .windows(2)
                .map(|w| w[1].duration_since(w[0]).as_secs_f64()),
        );
    }
    gaps.truncate(gaps.len().saturating_sub(vehicles * 3));
    if gaps.is_empty() {
        println!("rc jitter: no frames arrived");
        return;
    }
    gaps.sort_by(f64::total_cmp);
    let pct = |p: f64| gaps[((gaps.len() - 1) as f64 * p) as usize] * 1e3;
    let mean = gaps.iter().sum::<f64>() / gaps.len() as f64;
    let dev: Vec<f64> = gaps.iter().map(|g| (g - period).abs() * 1e3).collect();
    let max_dev = dev.iter().copied().fold(0.0, f64::max);
    let sd =
        (gaps.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / gaps.len() as f64).sqrt() * 1e3;
    println!(
        "rc jitter: {vehicles} vehicles at {hz} Hz over loopback UDP for {seconds} s ({frames} frames measured)"
    );
    println!(
        "  interval ms: mean {:.3}  sd {sd:.3}  p1 {:.3}  p50 {:.3}  p99 {:.3}  max |dev| {max_dev:.3} (nominal {:.1})",
        mean * 1e3,
        pct(0.01),
        pct(0.5),
        pct(0.99),
        period * 1e3
    );
}
