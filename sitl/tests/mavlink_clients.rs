//! Third-party MAVLink ground stations from PyPI fly `sitl run`'s ArduCopter-like vehicles over
//! real sockets: a plain pymavlink script, and MAVProxy driven at its prompt.

mod common;

use std::io::{Read, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::SitlProcess;
use tests::{free_tcp_port, python, root};

#[test]
fn a_pymavlink_script_sets_alt_hold_arms_climbs_holds_and_lands() {
    let port = free_tcp_port();
    let address = format!("mavlink@tcpin:127.0.0.1:{port}");
    let mut sitl = SitlProcess::start(&[
        "run",
        "--vehicle",
        &address,
        "--gust",
        "0.05",
        "--duration",
        "60",
    ]);
    sitl.wait_for("system id 1", Duration::from_secs(1));
    let out = Command::new(python())
        .arg(root().join("tests/python/fly_copter.py"))
        .args(["--connect", &format!("tcp:127.0.0.1:{port}")])
        .stderr(Stdio::inherit())
        .output()
        .expect("run fly_copter.py");
    let text = String::from_utf8_lossy(&out.stdout);
    let report: serde_json::Value =
        serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("report {text:?}: {e}"));
    assert!(out.status.success(), "the flight failed: {report}");
    // It saw an ArduPilot quadrotor, and every stage happened as the script measured it.
    assert_eq!(report["autopilot"], 3, "{report}");
    assert_eq!(report["vehicle_type"], 2, "{report}");
    assert!(
        report["alt_after_climb"].as_f64().unwrap_or(0.0) > 1.0,
        "{report}"
    );
    let held = report["alt_hold_end"].as_f64().unwrap_or(f64::NAN)
        - report["alt_hold_start"].as_f64().unwrap_or(f64::NAN);
    assert!(held.abs() < 0.2, "{report}");
    assert_eq!(report["disarmed_after_land"], true, "{report}");
    let texts: Vec<&str> = report["texts"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|t| t.as_str())
        .collect();
    assert!(texts.contains(&"Land complete: disarming"), "{texts:?}");
}

#[test]
fn mavproxy_sets_alt_hold_arms_climbs_holds_and_lands() {
    let port = free_tcp_port();
    let address = format!("mavlink@tcpin:127.0.0.1:{port}");
    let _sitl = SitlProcess::start(&[
        "run",
        "--vehicle",
        &address,
        "--gust",
        "0.05",
        "--duration",
        "90",
    ]);
    let workdir = std::env::temp_dir().join(format!("sitl-mavproxy-{}", std::process::id()));
    std::fs::create_dir_all(&workdir).expect("work directory");
    let mut mavproxy = Command::new(python().with_file_name("mavproxy.py"))
        .args(["--master", &format!("tcp:127.0.0.1:{port}"), "--nowait"])
        .current_dir(&workdir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start MAVProxy");
    let mut stdin = mavproxy.stdin.take().expect("MAVProxy stdin");
    let mut stdout = mavproxy.stdout.take().expect("MAVProxy stdout");
    let output = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    // What an operator types, with the pauses an operator leaves.
    let script: [(f64, &str); 9] = [
        (6.0, "mode ALT_HOLD"),
        (2.0, "arm throttle"),
        (2.0, "rc 3 1800"),
        (2.5, "rc 3 1500"),
        (1.0, "status GLOBAL_POSITION_INT"),
        (3.0, "status GLOBAL_POSITION_INT"),
        (0.5, "mode LAND"),
        (9.0, "status GLOBAL_POSITION_INT"),
        (1.0, "exit"),
    ];
    for (pause, line) in script {
        std::thread::sleep(Duration::from_secs_f64(pause));
        writeln!(stdin, "{line}").expect("type into MAVProxy");
    }
    drop(stdin); // MAVProxy exits at the end of its input
    let until = Instant::now() + Duration::from_secs(20);
    while mavproxy.try_wait().expect("MAVProxy status").is_none() {
        assert!(Instant::now() < until, "MAVProxy did not exit");
        std::thread::sleep(Duration::from_millis(100));
    }
    let out = output.join().expect("MAVProxy output");
    std::fs::remove_dir_all(&workdir).ok();
    for expected in [
        "Detected vehicle 1:1",
        "Mode ALT_HOLD",
        "COMPONENT_ARM_DISARM: ACCEPTED",
        "ARMED",
        "Mode LAND",
        "Land complete: disarming",
        "DISARMED",
    ] {
        assert!(
            out.contains(expected),
            "MAVProxy never showed '{expected}':\n{out}"
        );
    }
    // The heights MAVProxy printed: climbed, held, landed.
    let heights: Vec<f64> = out
        .split("relative_alt : ")
        .skip(1)
        .filter_map(|s| {
            s.split(|c: char| !(c.is_ascii_digit() || c == '-'))
                .next()?
                .parse::<f64>()
                .ok()
        })
        .map(|mm| mm / 1000.0)
        .collect();
    assert_eq!(heights.len(), 3, "{out}");
    assert!(heights[0] > 1.0, "climbed to {:?}", heights);
    assert!((heights[1] - heights[0]).abs() < 0.2, "held {:?}", heights);
    assert!(heights[2] < 0.1, "landed {:?}", heights);
}
