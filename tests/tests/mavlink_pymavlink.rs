//! The MAVLink adapter against a real third-party peer: a pymavlink vehicle, over loopback UDP
//! and TCP.

use std::time::Duration;

use link::mavlink::{MavlinkConfig, MavlinkLink, MavlinkVehicle};
use link::{Command, FlightMode, LinkState, Sticks, Transport, VehicleClock, VehicleLink};
use serde_json::Value;
use tests::{PyVehicle, eventually, free_tcp_port};

const S: Duration = Duration::from_secs(1);

fn first_vehicle(link: &MavlinkLink) -> MavlinkVehicle {
    link.wait_for_vehicle(20 * S)
        .expect("no heartbeat from the pymavlink vehicle")
}

/// Overrides recorded by the vehicle: [t, ch1..ch8, ch9, ch18].
fn overrides(report: &Value) -> Vec<Vec<f64>> {
    report["overrides"]
        .as_array()
        .expect("overrides")
        .iter()
        .map(|o| {
            o.as_array()
                .expect("row")
                .iter()
                .map(|x| x.as_f64().expect("number"))
                .collect()
        })
        .collect()
}

/// Flies the standard probe: mode, arm, sticks for 1.5 s, release, disarm; checks telemetry.
fn fly(v: &MavlinkVehicle) {
    // Every field checked below has arrived (with the legacy REQUEST_DATA_STREAM fallback the
    // streams start one request at a time, so DISTANCE_SENSOR may come after the rest).
    assert!(eventually(5 * S, || {
        let t = v.telemetry();
        t.battery.is_some()
            && t.attitude.is_some()
            && t.height_m.is_some()
            && t.position_m.is_some()
            && t.mode.is_some()
    }));
    let t = v.telemetry();
    let b = t.battery.expect("battery");
    assert!(
        (b.voltage_v - 12.1).abs() < 1e-3 && b.remaining_pct == Some(87),
        "{b:?}"
    );
    assert_eq!(t.height_m, Some(1.5), "DISTANCE_SENSOR 150 cm, downward");
    // NED → map: nose 10° up is pitch -10° in FLU; heading east (+90° NED) is -90° in the map.
    let a = t.attitude.expect("attitude");
    assert!(
        (a.pitch + 0.1745).abs() < 1e-3
            && (a.yaw + std::f32::consts::FRAC_PI_2).abs() < 1e-3
            && (a.roll - 0.05).abs() < 1e-3,
        "{a:?}"
    );
    assert_eq!(t.position_m, Some([2.0, -1.0, 1.5]));
    assert_eq!(t.mode.as_deref(), Some("STABILIZE"));
    // The heading is stamped on the link's clock as it arrives, each new one anew.
    let at = t.heading_at.expect("heading stamped");
    assert!(at <= VehicleClock::wall().now(), "{at:?}");
    assert!(eventually(2 * S, || v
        .telemetry()
        .heading_at
        .is_some_and(|later| later > at)));
    assert!(eventually(2 * S, || v
        .take_status_texts()
        .iter()
        .any(|s| s.text == "fake copter ready")));

    v.command(Command::SetMode(FlightMode::AltHold))
        .expect("set mode");
    assert!(eventually(3 * S, || v.telemetry().mode.as_deref() == Some("ALT_HOLD")));
    v.command(Command::Arm).expect("arm");
    assert!(eventually(3 * S, || v.telemetry().armed == Some(true)));
    v.set_sticks(Some(Sticks {
        roll: 0.5,
        pitch: 1.0,
        yaw: -0.25,
        throttle: 0.2,
    }));
    std::thread::sleep(Duration::from_millis(1500));
    v.set_sticks(None);
    std::thread::sleep(Duration::from_millis(300));
    v.command(Command::Disarm).expect("disarm");
    let s = v.status();
    assert_eq!(s.state, LinkState::Connected);
    assert!(
        s.frames_bad > 0,
        "the boot text must have been skipped and counted"
    );
}

fn check_report(r: &Value) {
    assert_eq!(r["gcs_sysid"], 255);
    assert_eq!(r["gcs_compid"], 190);
    assert!(r["gcs_heartbeats"].as_u64().expect("heartbeats") >= 2);
    assert_eq!(r["armed_history"], serde_json::json!([true, false]));
    assert_eq!(r["mode_history"][0], "ALT_HOLD");
    let o = overrides(r);
    // 20 Hz for 1.5 s.
    assert!((24..=36).contains(&o.len()), "{} overrides", o.len());
    for row in &o {
        // ArduPilot map, from the dead zone's edge (1500 ± 20 µs): roll 0.5 → 1710, pitch forward
        // 1.0 → 1100 (reversed), throttle 0.2 → 1596, yaw -0.25 → 1385; channels 5–8 and 9/18
        // untouched (u16::MAX).
        assert_eq!(
            &row[1..],
            &[
                1710.0, 1100.0, 1596.0, 1385.0, 65535.0, 65535.0, 65535.0, 65535.0, 65535.0,
                65535.0
            ]
        );
    }
    let gaps: Vec<f64> = o.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    let mean = gaps.iter().sum::<f64>() / gaps.len() as f64;
    assert!(
        (0.04..0.06).contains(&mean),
        "mean override period {mean} s"
    );
    assert!(
        r["releases"].as_u64().expect("releases") >= 1,
        "overrides must be released"
    );
    let cmds = r["commands"].as_array().expect("commands");
    let intervals = cmds.iter().filter(|c| c[0] == 511).count();
    assert!(
        intervals >= 7,
        "telemetry requested with SET_MESSAGE_INTERVAL: {cmds:?}"
    );
}

#[test]
fn flies_a_pymavlink_vehicle_over_udp() {
    let transport = Transport::open(&"udpin:127.0.0.1:0".parse().expect("address")).expect("bind");
    let port = transport.local_addr().expect("bound").port();
    let vehicle = PyVehicle::spawn(&format!("udpout:127.0.0.1:{port}"), &["--seconds", "25"]);
    let link = MavlinkLink::start(transport, MavlinkConfig::default());
    let v = first_vehicle(&link);
    assert_eq!(v.system_id(), 1);
    fly(&v);
    check_report(&vehicle.report(10 * S));
}

#[test]
fn flies_a_pymavlink_vehicle_over_tcp_with_legacy_fallbacks() {
    let port = free_tcp_port();
    let vehicle = PyVehicle::spawn(
        &format!("tcpin:127.0.0.1:{port}"),
        &[
            "--seconds",
            "30",
            "--no-do-set-mode",
            "--ignore-message-interval",
            "--sysid",
            "7",
        ],
    );
    // The station keeps trying until the vehicle listens.
    let link = MavlinkLink::connect(
        &format!("tcpout:127.0.0.1:{port}").parse().expect("address"),
        MavlinkConfig::default(),
    )
    .expect("open");
    let v = first_vehicle(&link);
    assert_eq!(v.system_id(), 7);
    // No answer to SET_MESSAGE_INTERVAL: after three attempts the station asks with REQUEST_DATA_STREAM.
    fly(&v);
    let r = vehicle.report(15 * S);
    assert!(
        r["set_mode_messages"].as_u64().expect("n") >= 1,
        "DO_SET_MODE unsupported → SET_MODE: {r}"
    );
    check_report(&r);
    assert!(
        r["data_stream_requests"].as_u64().expect("n") >= 1,
        "REQUEST_DATA_STREAM fallback: {r}"
    );
    let retries = r["commands"]
        .as_array()
        .expect("commands")
        .iter()
        .filter(|c| c[0] == 511 && c[1] == 2)
        .count();
    assert_eq!(
        retries, 7,
        "each SET_MESSAGE_INTERVAL sent three times with confirmation 0, 1, 2"
    );
}

#[test]
fn detects_loss_and_reconnects_when_the_vehicle_returns() {
    let port = free_tcp_port();
    let first = PyVehicle::spawn(&format!("tcpin:127.0.0.1:{port}"), &["--seconds", "30"]);
    let config = MavlinkConfig::default();
    let link = MavlinkLink::connect(
        &format!("tcpout:127.0.0.1:{port}").parse().expect("address"),
        config,
    )
    .expect("open");
    let v = first_vehicle(&link);
    assert!(eventually(3 * S, || v.status().state == LinkState::Connected));
    v.set_sticks(Some(Sticks::CENTRED));
    first.kill();
    // Degraded after 1.5 missed heartbeats, lost after 5.
    assert!(eventually(3 * S, || v.status().state == LinkState::Degraded));
    assert!(eventually(5 * S, || v.status().state == LinkState::Lost));
    assert!(!v.status().transport_up);
    let second = PyVehicle::spawn(&format!("tcpin:127.0.0.1:{port}"), &["--seconds", "6"]);
    assert!(
        eventually(15 * S, || v.status().state == LinkState::Connected),
        "{:?}",
        v.status()
    );
    assert!(v.status().connections >= 2);
    // Overrides resume on the new connection without being asked again.
    let r = second.report(15 * S);
    assert!(
        overrides(&r).len() >= 20,
        "overrides after reconnect: {}",
        overrides(&r).len()
    );
}

#[test]
fn two_vehicles_on_one_udp_port_are_told_apart_by_system_id() {
    let transport = Transport::open(&"udpin:127.0.0.1:0".parse().expect("address")).expect("bind");
    let port = transport.local_addr().expect("bound").port();
    let one = PyVehicle::spawn(
        &format!("udpout:127.0.0.1:{port}"),
        &["--sysid", "1", "--seconds", "25"],
    );
    let two = PyVehicle::spawn(
        &format!("udpout:127.0.0.1:{port}"),
        &["--sysid", "2", "--seconds", "25"],
    );
    let link = MavlinkLink::start(transport, MavlinkConfig::default());
    assert!(
        eventually(20 * S, || link.vehicles() == vec![1, 2]),
        "{:?}",
        link.vehicles()
    );
    let (a, b) = (link.vehicle(1), link.vehicle(2));
    a.command(Command::Arm).expect("arm 1");
    b.command(Command::Arm).expect("arm 2");
    a.set_sticks(Some(Sticks {
        roll: 0.5,
        ..Sticks::CENTRED
    }));
    b.set_sticks(Some(Sticks {
        roll: -0.5,
        ..Sticks::CENTRED
    }));
    std::thread::sleep(S);
    a.set_sticks(None);
    b.set_sticks(None);
    std::thread::sleep(Duration::from_millis(300));
    a.command(Command::Disarm).expect("disarm 1");
    b.command(Command::Disarm).expect("disarm 2");
    for (report, roll) in [(one.report(10 * S), 1710.0), (two.report(10 * S), 1290.0)] {
        let o = overrides(&report);
        assert!(o.len() >= 15, "{} overrides", o.len());
        assert!(
            o.iter().all(|row| row[1] == roll),
            "each vehicle gets only its own sticks"
        );
        assert_eq!(report["armed_history"], serde_json::json!([true, false]));
    }
}

const KEY: &str = "6b4a9e1f0c3d5e7a8b9c0d1e2f3a4b5c6d7e8f90a1b2c3d4e5f60718293a4b5c";

fn signed_config(hex: &str) -> MavlinkConfig {
    MavlinkConfig {
        signing: Some(link::mavlink::SigningKey::from_hex(hex).expect("key")),
        ..MavlinkConfig::default()
    }
}

#[test]
fn signing_lets_the_key_holder_fly_and_keeps_others_out() {
    // Same key on both sides: flies.
    let transport = Transport::open(&"udpin:127.0.0.1:0".parse().expect("address")).expect("bind");
    let port = transport.local_addr().expect("bound").port();
    let vehicle = PyVehicle::spawn(
        &format!("udpout:127.0.0.1:{port}"),
        &["--seconds", "20", "--signing-key", KEY],
    );
    let link = MavlinkLink::start(transport, signed_config(KEY));
    let v = first_vehicle(&link);
    v.command(Command::Arm).expect("signed arm");
    v.command(Command::Disarm).expect("signed disarm");
    assert_eq!(
        vehicle.report(10 * S)["armed_history"],
        serde_json::json!([true, false])
    );
    assert_eq!(link.rejected_signatures(), 0);
    drop(link);

    // A station with another key hears nothing it trusts.
    let transport = Transport::open(&"udpin:127.0.0.1:0".parse().expect("address")).expect("bind");
    let port = transport.local_addr().expect("bound").port();
    let _vehicle = PyVehicle::spawn(
        &format!("udpout:127.0.0.1:{port}"),
        &["--seconds", "10", "--signing-key", KEY],
    );
    let wrong = KEY.replace('6', "7");
    let link = MavlinkLink::start(transport, signed_config(&wrong));
    assert!(link.wait_for_vehicle(4 * S).is_none());
    assert!(
        link.rejected_signatures() > 10,
        "{}",
        link.rejected_signatures()
    );
    drop(link);

    // A station that does not sign is ignored by the signing vehicle.
    let transport = Transport::open(&"udpin:127.0.0.1:0".parse().expect("address")).expect("bind");
    let port = transport.local_addr().expect("bound").port();
    let vehicle = PyVehicle::spawn(
        &format!("udpout:127.0.0.1:{port}"),
        &["--seconds", "8", "--signing-key", KEY],
    );
    let link = MavlinkLink::start(transport, MavlinkConfig::default());
    let v = first_vehicle(&link);
    assert!(matches!(
        v.command(Command::Arm),
        Err(link::CommandError::Timeout { attempts: 3, .. })
    ));
    let r = vehicle.report(15 * S);
    assert_eq!(r["armed_history"], serde_json::json!([]));
    assert_eq!(
        r["gcs_heartbeats"], 0,
        "unsigned heartbeats must be rejected"
    );
}
