//! `gcs fly --config FLEET.toml` against an external fleet: a simulator serving one MAVLink
//! vehicle and one shield vehicle (thesis wiring) on their own TCP ports, and their cameras on a
//! TCP frame stream — the station reaches them exactly as it would reach hardware; and an
//! autopilot flown elsewhere whose camera the bridge renders (the ArduPilot SITL setup).

mod common;

use std::path::Path;
use std::sync::Arc;

use common::{gcs, serve_fleet, wall_clock_mission};
use sitl::bridge::{BridgeConfig, BridgedVehicle, CameraBridge};
use sitl::{EndpointSpec, Protocol, SimConfig, Sitl, SitlConfig, World};

/// Runs `gcs fly` on `fleet` for 25 s into `out` and returns its summary.
fn fly(fleet: &Path, out: &Path) -> serde_json::Value {
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
    serde_json::from_slice(&run.stdout).expect("JSON")
}

#[test]
fn fly_explores_with_an_external_fleet_over_mavlink_and_the_shield_and_lands() {
    let _alone = wall_clock_mission();
    let dir = std::env::temp_dir().join(format!("gcs-fly-{}", std::process::id()));
    let (sitl, fleet) = serve_fleet(&dir, &[Protocol::Mavlink, Protocol::Shield]);
    let out = dir.join("out");
    let summary = fly(&fleet, &out);
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
            "altitude 9 must be 0.25 to 2.0 metres",
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

#[test]
fn fly_explores_with_an_autopilot_whose_camera_the_bridge_renders_at_its_reported_pose() {
    // As with ArduPilot SITL: the autopilot flies its own physics and knows nothing of cameras;
    // the bridge listens to it beside the station (both on the autopilot's UDP port, as on
    // MAVProxy's two outputs) and renders the building at the pose it reports.
    let _alone = wall_clock_mission();
    let dir = std::env::temp_dir().join(format!("gcs-fly-bridge-{}", std::process::id()));
    let sitl = Sitl::start(SitlConfig {
        world: Arc::new(World::load("apartment").expect("built-in world")),
        // No camera of its own: the bridge renders it.
        sim: SimConfig {
            camera: None,
            ..SimConfig::default()
        },
        vehicles: vec![EndpointSpec {
            protocol: Protocol::Mavlink,
            address: "udpin:127.0.0.1:0".parse().expect("address"),
        }],
        camera: None,
        speed: 1.0,
        signing_key: None,
    })
    .expect("the simulator starts");
    let port = sitl.endpoint_addrs()[0].expect("a local address").port();
    let autopilot: link::Address = format!("udpout:127.0.0.1:{port}").parse().expect("address");
    let bridge = CameraBridge::start(BridgeConfig::new(
        Arc::new(World::load("apartment").expect("built-in world")),
        vec![BridgedVehicle {
            address: autopilot.clone(),
            map_from_local: [0.0; 3],
        }],
        Some("tcpin:127.0.0.1:0".parse().expect("address")),
    ))
    .expect("the bridge starts");
    let camera = bridge.camera_addr().expect("a camera stream").port();
    let [x, y, yaw] = sitl.starts()[0];
    std::fs::create_dir_all(&dir).expect("temp dir");
    let fleet = dir.join("fleet.toml");
    std::fs::write(
        &fleet,
        format!(
            "[[vehicle]]\nprotocol = \"mavlink\"\naddress = \"{autopilot}\"\ncamera = \"tcpout:127.0.0.1:{camera}\"\nstart = [{x}, {y}, {yaw}]\n"
        ),
    )
    .expect("fleet file");
    let out = dir.join("out");
    let summary = fly(&fleet, &out);
    let d = &summary["drones"][0];
    assert_eq!(d["final_phase"], "landed", "{summary}");
    assert!(d["path_length_m"].as_f64().unwrap_or(0.0) > 1.0, "{d}");
    assert!(d["camera_frames"].as_u64().unwrap_or(0) > 150, "{d}");
    // Frames rendered at the last pose reported (10 Hz here) showed the past, and the station
    // lost track of them within seconds (over 220 of some 270 frames lost).
    assert!(d["lost_frames"].as_u64().unwrap_or(u64::MAX) < 50, "{d}");
    // The station tracked the rendered camera where the vehicle really flew: its last camera
    // pose is where the simulator has the vehicle (landed there since).
    let tum = std::fs::read_to_string(out.join("drone1.tum")).expect("drone1.tum");
    let last: Vec<f64> = tum
        .lines()
        .rfind(|l| !l.starts_with('#') && !l.trim().is_empty())
        .expect("a pose")
        .split_whitespace()
        .filter_map(|v| v.parse().ok())
        .collect();
    let truth = sitl.with_sim(|sim| sim.vehicle(0).map_from_camera());
    let off =
        ((last[1] - truth.translation.x).powi(2) + (last[2] - truth.translation.y).powi(2)).sqrt();
    assert!(
        off < 0.3,
        "last SLAM camera pose {off:.2} m from the truth: {last:?}"
    );
    sitl.with_sim(|sim| {
        let s = sim.vehicle(0).state();
        assert!(s.landed && !s.armed, "{s:?}");
    });
    drop(bridge);
    std::fs::remove_dir_all(&dir).ok();
}
