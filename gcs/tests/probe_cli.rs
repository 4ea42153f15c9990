//! `gcs link probe` as a user runs it, against real peers: a pymavlink vehicle over UDP and TCP,
//! the shield emulator over a pseudo-terminal.

mod common;

use common::gcs;

use std::process::{Command, Output};
use std::time::Duration;

use link::shield::{EmulatorConfig, EmulatorServer};
use link::{ChannelMap, Pulses};
use serde_json::Value;
use tests::{PyVehicle, free_tcp_port, free_udp_port, pty_pair};

fn json_lines(out: &Output) -> Vec<Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON: {l:?}: {e}")))
        .collect()
}

fn assert_flew(out: &Output) -> Vec<Value> {
    assert!(
        out.status.success(),
        "gcs failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines = json_lines(out);
    let events: Vec<&str> = lines
        .iter()
        .map(|l| l["event"].as_str().expect("event"))
        .collect();
    for e in ["connected", "status", "command", "rc", "rc_released"] {
        assert!(events.contains(&e), "no {e} event in {events:?}");
    }
    let commands: Vec<(&str, bool)> = lines
        .iter()
        .filter(|l| l["event"] == "command")
        .map(|l| {
            (
                l["command"].as_str().expect("name"),
                l["ok"].as_bool().expect("ok"),
            )
        })
        .collect();
    assert!(
        commands.contains(&("arm", true)) && commands.contains(&("disarm", true)),
        "{commands:?}"
    );
    lines
}

fn probe_pymavlink(station: &str, vehicle: &str) {
    let v = PyVehicle::spawn(vehicle, &["--seconds", "25"]);
    let out = gcs(&[
        "link",
        "probe",
        station,
        "--mode",
        "ALT_HOLD",
        "--arm",
        "--rc",
        "1500,1400,1600,1500",
        "--seconds",
        "2",
        "--json",
    ]);
    let lines = assert_flew(&out);
    let status = lines
        .iter()
        .find(|l| l["event"] == "status")
        .expect("status");
    assert_eq!(status["link"], "connected");
    assert_eq!(
        status["battery_v"].as_f64().map(|v| (v * 10.0).round()),
        Some(121.0)
    );
    let r = v.report(Duration::from_secs(10));
    let overrides = r["overrides"].as_array().expect("overrides");
    assert!(
        overrides.len() >= 30,
        "{} overrides in 2 s",
        overrides.len()
    );
    assert!(
        overrides
            .iter()
            .all(|o| o[1] == 1500 && o[2] == 1400 && o[3] == 1600 && o[4] == 1500)
    );
    assert!(r["releases"].as_u64().expect("n") >= 1);
    assert_eq!(r["armed_history"], serde_json::json!([true, false]));
}

#[test]
fn probe_flies_a_pymavlink_vehicle_over_udp() {
    let port = free_udp_port();
    probe_pymavlink(
        &format!("udpin:127.0.0.1:{port}"),
        &format!("udpout:127.0.0.1:{port}"),
    );
}

#[test]
fn probe_records_a_tlog_that_pymavlink_reads() {
    let port = free_udp_port();
    let dir = std::env::temp_dir().join(format!("probe-tlog-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let tlog = dir.join("session.tlog");
    let v = PyVehicle::spawn(&format!("udpout:127.0.0.1:{port}"), &["--seconds", "25"]);
    let out = gcs(&[
        "link",
        "probe",
        &format!("udpin:127.0.0.1:{port}"),
        "--arm",
        "--rc",
        "1500,1500,1500,1500",
        "--seconds",
        "1",
        "--tlog",
        &tlog.to_string_lossy(),
        "--json",
    ]);
    assert_flew(&out);
    drop(v);
    let mut ours = std::collections::BTreeMap::new();
    for rec in link::tlog::TlogReader::open(&tlog).expect("open tlog") {
        let rec = rec.expect("record");
        let name = rec
            .frame
            .decode()
            .map(|m| ::mavlink::Message::message_name(&m))
            .unwrap_or("?");
        *ours
            .entry((rec.frame.header().system_id, name))
            .or_insert(0u32) += 1;
    }
    assert!(
        ours[&(255, "HEARTBEAT")] >= 1 && ours[&(1, "HEARTBEAT")] >= 1,
        "{ours:?}"
    );
    assert!(ours[&(255, "RC_CHANNELS_OVERRIDE")] >= 15, "{ours:?}");
    assert!(
        ours[&(255, "COMMAND_LONG")] >= 2 && ours[&(1, "COMMAND_ACK")] >= 2,
        "{ours:?}"
    );
    let total: u32 = ours.values().sum();
    let script = "import sys\nfrom pymavlink import mavutil\nm = mavutil.mavlink_connection(sys.argv[1])\nn = 0\nwhile m.recv_msg() is not None: n += 1\nprint(n)";
    let py = Command::new(tests::python())
        .args(["-c", script, &tlog.to_string_lossy()])
        .output()
        .expect("pymavlink");
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let theirs: u32 = String::from_utf8_lossy(&py.stdout)
        .trim()
        .parse()
        .expect("count");
    assert_eq!(theirs, total, "pymavlink reads every record we wrote");
    std::fs::remove_dir_all(&dir).expect("clean up");
}

#[test]
fn probe_flies_a_pymavlink_vehicle_over_tcp() {
    let port = free_tcp_port();
    probe_pymavlink(
        &format!("tcpout:127.0.0.1:{port}"),
        &format!("tcpin:127.0.0.1:{port}"),
    );
}

#[test]
fn probe_flies_the_shield_emulator_over_a_pseudo_terminal() {
    let (path, conn, _line) = pty_pair();
    let emulator = EmulatorServer::spawn_on(conn, EmulatorConfig::default());
    let out = gcs(&[
        "link",
        "probe",
        &format!("serial:{path}:115200"),
        "--protocol",
        "shield",
        "--arm",
        "--rc",
        "1500,1500,1000,1500",
        "--seconds",
        "1",
        "--json",
    ]);
    assert_flew(&out);
    let history = emulator.with(|e| e.history().to_vec());
    let held = Pulses {
        roll: 1500,
        pitch: 1500,
        throttle: 1000,
        yaw: 1500,
    };
    assert!(history.contains(&held), "the shield never output {held:?}");
    // After release the sticks centre (the shield has no radio to hand back to).
    let centred = ChannelMap::thesis_naza().pulses(&link::Sticks::CENTRED);
    assert!(
        history
            .iter()
            .skip_while(|p| **p != held)
            .any(|p| *p == centred)
    );
    assert!(!emulator.with(|e| e.flags().armed));
}

#[test]
fn probe_says_so_when_nothing_answers() {
    let port = free_udp_port();
    let out = gcs(&[
        "link",
        "probe",
        &format!("udpin:127.0.0.1:{port}"),
        "--wait",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no MAVLink heartbeat") && err.contains("within 1 s"),
        "{err}"
    );

    let (path, _conn, _line) = pty_pair(); // a line with nobody on the other end
    let out = gcs(&[
        "link",
        "probe",
        &format!("serial:{path}:115200"),
        "--protocol",
        "shield",
        "--wait",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("never answered"));
}

#[test]
fn probe_rejects_bad_input_clearly() {
    let out = gcs(&["link", "probe", "udp:127.0.0.1:14550"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown scheme \"udp\""));
    let port = free_udp_port();
    let started = std::time::Instant::now();
    let out = gcs(&[
        "link",
        "probe",
        &format!("udpin:127.0.0.1:{port}"),
        "--rc",
        "1500,1500",
        "--wait",
        "5",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("got 2"));
    assert!(
        started.elapsed() < Duration::from_secs(4),
        "bad input must be reported before connecting"
    );
    let out = gcs(&["link", "probe", "udpin:127.0.0.1:1", "--mode", "HOVER"]);
    assert_eq!(out.status.code(), Some(2), "clap usage error");
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown flight mode"));
}
