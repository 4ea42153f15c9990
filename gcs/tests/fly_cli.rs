//! `gcs fly --config FLEET.toml` against an external fleet: a simulator serving one MAVLink
//! vehicle and one shield vehicle (thesis wiring) on their own TCP ports, and their cameras on a
//! TCP frame stream — the station reaches them exactly as it would reach hardware.

mod common;

use common::{gcs, serve_fleet};
use sitl::Protocol;

#[test]
fn fly_explores_with_an_external_fleet_over_mavlink_and_the_shield_and_lands() {
    let dir = std::env::temp_dir().join(format!("gcs-fly-{}", std::process::id()));
    let (sitl, fleet) = serve_fleet(&dir, &[Protocol::Mavlink, Protocol::Shield]);
    let out = dir.join("out");
    let run = gcs(&[
        "fly",
        "--config",
        fleet.to_str().expect("utf-8 path"),
        "--timeout",
        "25",
        "--json",
        "--out",
        out.to_str().expect("utf-8 path"),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let summary: serde_json::Value = serde_json::from_slice(&run.stdout).expect("JSON");
    assert_eq!(summary["outcome"], "timed out", "{summary}");
    assert_eq!(summary["drones"][0]["name"], "alpha", "{summary}");
    for d in summary["drones"].as_array().expect("drones") {
        assert_eq!(d["final_phase"], "landed", "{d}");
        assert!(d["path_length_m"].as_f64().unwrap_or(0.0) > 1.0, "{d}");
        assert!(d["camera_frames"].as_u64().unwrap_or(0) > 150, "{d}");
    }
    // The simulator agrees: both are down, disarmed.
    sitl.with_sim(|sim| {
        for k in 0..sim.len() {
            let s = sim.vehicle(k).state();
            assert!(s.landed && !s.armed, "vehicle {k}: {s:?}");
        }
    });
    assert!(nav::grid::Grid::load(out.join("map.yaml")).is_ok());
    let log = std::fs::metadata(out.join("mission.mcap")).expect("mission.mcap");
    assert!(log.len() > 100_000, "{} bytes of log", log.len());
    assert!(out.join("drone1.tlog").exists() && !out.join("drone2.tlog").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_bad_fleet_file_is_refused_with_what_to_fix() {
    let dir = std::env::temp_dir().join(format!("gcs-fly-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let ok = "address = \"tcpout:127.0.0.1:1\"\ncamera = \"tcpout:127.0.0.1:2\"\n";
    for (text, expected) in [
        ("", "a fleet has 1 to 8"),
        ("[[vehicle]]\nprotocol = \"can\"\n", "missing field"),
        (
            &format!("[[vehicle]]\nprotocol = \"can\"\n{ok}") as &str,
            "vehicle 1: protocol \"can\" must be \"mavlink\" or \"shield\"",
        ),
        (
            &format!("[[vehicle]]\nprotocol = \"mavlink\"\n{ok}colour = 3\n"),
            "unknown field `colour`",
        ),
        (
            "[[vehicle]]\nprotocol = \"mavlink\"\naddress = \"tcpout:x\"\ncamera = \"tcpout:127.0.0.1:2\"\n",
            "vehicle 1: address",
        ),
        (
            &format!("[[vehicle]]\nprotocol = \"shield\"\n{ok}channels = \"futaba\"\n"),
            "channels \"futaba\" must be",
        ),
        (
            &format!("[[vehicle]]\nprotocol = \"shield\"\n{ok}altitude = 9.0\n"),
            "altitude 9 must be 0.3 to 2.5 metres",
        ),
    ] {
        let path = dir.join("fleet.toml");
        std::fs::write(&path, text).expect("fleet file");
        let run = gcs(&["fly", "--config", path.to_str().expect("utf-8 path")]);
        assert!(!run.status.success(), "{text}");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains(expected), "{text}: {stderr}");
    }
    let run = gcs(&["fly", "--config", "/nonexistent/fleet.toml"]);
    assert!(String::from_utf8_lossy(&run.stderr).contains("cannot read the fleet file"));
    std::fs::remove_dir_all(&dir).ok();
}
