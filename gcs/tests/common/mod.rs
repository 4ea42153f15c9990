//! Shared by the CLI tests: run the `gcs` binary built for this test run, serve it a fleet.

#![allow(dead_code)] // each test binary uses its part

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;

use sitl::{Camera, EndpointSpec, Protocol, SimConfig, Sitl, SitlConfig, World};

/// Held by a test while it flies a mission on the wall clock: one at a time in a test binary.
/// Two such missions at once on a two-core machine starve each other's SLAM, and the bridge
/// test's drone then loses track of frames that arrive late (its bound is on frames lost).
pub fn wall_clock_mission() -> std::sync::MutexGuard<'static, ()> {
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Runs `gcs` with `args` and returns what it did. Its log is at its default level whatever
/// `RUST_LOG` the tests run under: the tests read what the vehicles and the station said.
pub fn gcs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args(args)
        .env("RUST_LOG", "info")
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

/// The local addresses process `pid` accepts connections or datagrams on: its listening TCP
/// sockets and its bound UDP sockets, as `(protocol, hex address)` from `/proc` (Linux).
pub fn open_ports(pid: u32) -> Vec<(String, String)> {
    let inodes: std::collections::HashSet<String> = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .expect("the process's file descriptors")
        .filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
        .filter_map(|target| {
            let t = target.to_string_lossy().into_owned();
            Some(t.strip_prefix("socket:[")?.strip_suffix(']')?.to_owned())
        })
        .collect();
    let mut open = vec![];
    for proto in ["tcp", "tcp6", "udp", "udp6"] {
        let table = std::fs::read_to_string(format!("/proc/{pid}/net/{proto}")).unwrap_or_default();
        for line in table.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            let (Some(local), Some(state), Some(inode)) = (f.get(1), f.get(3), f.get(9)) else {
                continue;
            };
            let accepts = proto.starts_with("udp") || *state == "0A"; // 0A: LISTEN
            if accepts && inodes.contains(*inode) {
                open.push((proto.to_owned(), (*local).to_owned()));
            }
        }
    }
    open
}

/// Whether a `/proc/net` hex address is on the loopback interface (127.0.0.0/8 or ::1).
pub fn is_loopback(hex_address: &str) -> bool {
    let host = hex_address.split(':').next().unwrap_or("");
    match host.len() {
        8 => host.ends_with("7F"),
        32 => host == "00000000000000000000000001000000",
        _ => false,
    }
}
