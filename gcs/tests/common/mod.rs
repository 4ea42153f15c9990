//! Shared by the CLI tests: run the `gcs` binary built for this test run, serve it a fleet.

#![allow(dead_code)] // each test binary uses its part

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;

use sitl::{Camera, EndpointSpec, Protocol, SimConfig, Sitl, SitlConfig, World};

/// Runs `gcs` with `args` and returns what it did.
pub fn gcs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args(args)
        .output()
        .expect("run gcs")
}

/// A simulator serving one vehicle per protocol on its own TCP port (the first as "alpha" over
/// ArduPilot channels, shield vehicles with the thesis's wiring) and their cameras on a TCP frame
/// stream, as external vehicles; and the fleet file in `dir` that reaches them.
pub fn serve_fleet(dir: &Path, protocols: &[Protocol]) -> (Sitl, PathBuf) {
    let sitl = Sitl::start(SitlConfig {
        world: Arc::new(World::load("apartment").expect("built-in world")),
        sim: SimConfig {
            camera: Some(Camera::kinect(320, 240)),
            camera_hz: 10.0,
            ..SimConfig::default()
        },
        vehicles: protocols
            .iter()
            .map(|&protocol| EndpointSpec {
                protocol,
                address: "tcpin:127.0.0.1:0".parse().expect("address"),
            })
            .collect(),
        camera: Some("tcpin:127.0.0.1:0".parse().expect("address")),
        speed: 1.0,
        signing_key: None,
    })
    .expect("the simulator starts");
    let camera = sitl.camera_addr().expect("a camera stream").port();
    let mut text = String::new();
    for (k, (addr, start)) in sitl.endpoint_addrs().iter().zip(sitl.starts()).enumerate() {
        let port = addr.expect("a local address").port();
        let (protocol, extra) = match protocols[k] {
            Protocol::Mavlink => ("mavlink", ""),
            Protocol::Shield => ("shield", "channels = \"thesis\"\n"),
        };
        let name = if k == 0 { "name = \"alpha\"\n" } else { "" };
        text += &format!(
            "[[vehicle]]\nprotocol = \"{protocol}\"\naddress = \"tcpout:127.0.0.1:{port}\"\ncamera = \"tcpout:127.0.0.1:{camera}\"\nstart = [{}, {}, {}]\n{name}{extra}",
            start[0], start[1], start[2]
        );
    }
    std::fs::create_dir_all(dir).expect("temp dir");
    let fleet = dir.join("fleet.toml");
    std::fs::write(&fleet, text).expect("fleet file");
    (sitl, fleet)
}
