//! `sitl` from the command line: the camera frame stream reaches another process, runs end at
//! `--duration` with a summary, and bad input is refused with a clear message.

mod common;

use std::net::TcpStream;
use std::process::Command;
use std::time::Duration;

use common::SitlProcess;
use link::camera::RgbdFrame;
use tests::free_tcp_port;

fn sitl(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_sitl"))
        .args(args)
        .output()
        .expect("run sitl");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

/// Connects to the camera stream a `sitl run` or `sitl camera` process announced.
fn camera_stream(process: &mut SitlProcess) -> TcpStream {
    let line = process.wait_for("camera stream on tcp", Duration::from_secs(1));
    let addr = line
        .split_once("camera stream on tcp ")
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_owned();
    let stream = TcpStream::connect(&addr).expect("connect to the camera stream");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    stream
}

#[test]
fn the_camera_stream_delivers_timestamped_rgbd_frames_of_every_vehicle() {
    let a = format!("mavlink@tcpin:127.0.0.1:{}", free_tcp_port());
    let b = format!("shield@tcpin:127.0.0.1:{}", free_tcp_port());
    let mut sitl = SitlProcess::start(&[
        "run",
        "--vehicle",
        &a,
        "--vehicle",
        &b,
        "--camera",
        "tcpin:127.0.0.1:0",
        "--camera-hz",
        "5",
        "--speed",
        "4",
        "--duration",
        "60",
    ]);
    let mut stream = camera_stream(&mut sitl);
    let mut last = [None, None];
    for _ in 0..8 {
        let f = RgbdFrame::read_from(&mut stream).expect("a frame");
        assert_eq!((f.width, f.height), (320, 240));
        assert!(f.vehicle < 2, "vehicle {}", f.vehicle);
        let valid = f.depth_mm.iter().filter(|d| **d > 0).count() as f64 / f.depth_mm.len() as f64;
        // On the floor the camera is 5 cm up: the floor right ahead is nearer than 0.4 m.
        assert!(
            valid > 0.3,
            "only {:.0} % of depth pixels valid",
            valid * 100.0
        );
        assert!(
            f.depth_mm
                .iter()
                .all(|d| *d == 0 || (400..=4000).contains(d))
        );
        if let Some(prev) = last[usize::from(f.vehicle)] {
            // 5 Hz of simulated time (within one 10 ms physics tick; a slow reader skips frames).
            assert!(f.stamp > prev, "{:?} after {prev:?}", f.stamp);
            let gap = (f.stamp - prev).as_millis();
            assert!(
                gap % 200 <= 10 || gap % 200 >= 190,
                "{:?} after {prev:?}",
                f.stamp
            );
        }
        last[usize::from(f.vehicle)] = Some(f.stamp);
    }
    assert!(
        last.iter().all(Option::is_some),
        "frames from both vehicles: {last:?}"
    );
}

#[test]
fn a_run_ends_at_its_duration_with_a_summary() {
    let v = format!("mavlink@udpin:127.0.0.1:{}", tests::free_udp_port());
    let mut sitl =
        SitlProcess::start(&["run", "--vehicle", &v, "--speed", "max", "--duration", "5"]);
    assert!(sitl.wait(Duration::from_secs(30)).success());
    let summary = sitl.wait_for(
        "sitl: vehicle 1: at (13.10, 2.10, 0.00), disarmed, 0 collision(s)",
        Duration::from_secs(1),
    );
    assert!(!summary.is_empty());
}

#[test]
fn bad_input_is_refused_with_a_clear_message() {
    let (ok, out) = sitl(&["run", "--vehicle", "tcpin:127.0.0.1:5760"]);
    assert!(!ok);
    assert!(out.contains("expected PROTOCOL@ADDRESS"), "{out}");
    let (ok, out) = sitl(&[
        "run",
        "--vehicle",
        "mavlink@udpin:127.0.0.1:0",
        "--world",
        "nowhere",
    ]);
    assert!(!ok);
    assert!(
        out.contains("no world 'nowhere'") && out.contains("apartment"),
        "{out}"
    );
    let (ok, out) = sitl(&[
        "run",
        "--vehicle",
        "mavlink@udpin:127.0.0.1:0",
        "--speed",
        "0",
    ]);
    assert!(!ok);
    assert!(out.contains("positive factor of real time"), "{out}");
    let (ok, out) = sitl(&[
        "run",
        "--vehicle",
        "mavlink@udpin:127.0.0.1:0",
        "--camera",
        "udpin:127.0.0.1:0",
    ]);
    assert!(!ok);
    assert!(out.contains("give tcpin:HOST:PORT"), "{out}");
    let nine: Vec<String> = (0..9)
        .map(|_| "--vehicle=mavlink@udpin:127.0.0.1:0".to_owned())
        .collect();
    let mut args = vec!["run"];
    args.extend(nine.iter().map(String::as_str));
    let (ok, out) = sitl(&args);
    assert!(!ok);
    assert!(
        out.contains("has room for 8 drones, 9 were asked for"),
        "{out}"
    );
    let dir = std::env::temp_dir().join(format!("sitl-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let bad = dir.join("bad.txt");
    std::fs::write(&bad, "resolution 0.1\n---\n#.?#\n").expect("write");
    let (ok, out) = sitl(&[
        "run",
        "--vehicle",
        "mavlink@udpin:127.0.0.1:0",
        "--world",
        bad.to_str().expect("path"),
    ]);
    assert!(!ok);
    assert!(out.contains("unknown character '?'"), "{out}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn snapshot_writes_colour_and_depth_images() {
    let dir = std::env::temp_dir().join(format!("sitl-snap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let prefix = dir.join("view");
    let (ok, out) = sitl(&[
        "snapshot",
        "--pose",
        "7.0,4.7,1.2,180",
        "--size",
        "160x120",
        "--out",
        prefix.to_str().expect("path"),
    ]);
    assert!(ok, "{out}");
    let rgb = image::open(dir.join("view-rgb.png"))
        .expect("colour image")
        .into_rgb8();
    assert_eq!(rgb.dimensions(), (160, 120));
    let depth = image::open(dir.join("view-depth.png"))
        .expect("depth image")
        .into_luma16();
    // Looking west down the corridor from x = 7 m: the far wall is 6.8 m away, beyond range,
    // while the corridor's side walls and floor near the camera are in range.
    assert_eq!(depth.get_pixel(80, 60)[0], 0);
    assert!(depth.pixels().filter(|p| p[0] > 0).count() > 160 * 120 / 4);
    std::fs::remove_dir_all(&dir).ok();
}

/// The median difference, in millimetres, between a frame's depth and `depth` where both have a
/// reading, and the fraction of pixels whose validity differs.
fn depth_difference(frame: &[u16], depth: &[u16]) -> (u16, f64) {
    let mut d: Vec<u16> = frame
        .iter()
        .zip(depth)
        .filter(|(a, b)| **a > 0 && **b > 0)
        .map(|(a, b)| a.abs_diff(*b))
        .collect();
    d.sort_unstable();
    let differ = frame
        .iter()
        .zip(depth)
        .filter(|(a, b)| (**a > 0) != (**b > 0))
        .count();
    (
        d.get(d.len() / 2).copied().unwrap_or(u16::MAX),
        differ as f64 / frame.len() as f64,
    )
}

#[test]
fn the_camera_bridge_renders_an_autopilot_at_the_pose_it_reports() {
    // An autopilot flown elsewhere (here `sitl run`'s own, on a UDP port that answers every
    // client, as ArduPilot SITL's MAVProxy outputs do), and the bridge listening to it.
    let port = tests::free_udp_port();
    let mut autopilot = SitlProcess::start(&[
        "run",
        "--vehicle",
        &format!("mavlink@udpin:127.0.0.1:{port}"),
        "--duration",
        "60",
    ]);
    let line = autopilot.wait_for("start [", Duration::from_secs(1));
    let start: Vec<f64> = line
        .split_once("start [")
        .and_then(|(_, s)| s.split_once(']'))
        .map(|(s, _)| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_default();
    assert_eq!(start.len(), 3, "{line}");
    let mut bridge = SitlProcess::start(&[
        "camera",
        "--vehicle",
        &format!("udpout:127.0.0.1:{port}"),
        "--camera",
        "tcpin:127.0.0.1:0",
        "--camera-hz",
        "5",
        "--duration",
        "60",
    ]);
    let mut stream = camera_stream(&mut bridge);
    let frame = RgbdFrame::read_from(&mut stream).expect("a frame");
    assert_eq!((frame.vehicle, frame.width, frame.height), (0, 320, 240));

    // The vehicle stands at its start: the frame is the view from there, not from a pose
    // turned by 20° or moved by 0.3 m.
    let world = sitl::World::load("apartment").expect("world");
    let camera = sitl::Camera::kinect(320, 240);
    let view = |x: f64, y: f64, yaw: f64| {
        let v = sitl::Vehicle::new(sitl::VehicleParams::default(), x, y, yaw);
        sitl::render::render(&world, &v.map_from_camera(), &camera, None).1
    };
    let (x, y, yaw) = (start[0], start[1], start[2]);
    let (here, differ) = depth_difference(&frame.depth_mm, &view(x, y, yaw));
    assert!(here <= 10 && differ < 0.02, "{here} mm, {differ}");
    for (name, other) in [
        ("turned", view(x, y, yaw + 20f64.to_radians())),
        ("moved", view(x + 0.3 * yaw.cos(), y + 0.3 * yaw.sin(), yaw)),
    ] {
        let (there, _) = depth_difference(&frame.depth_mm, &other);
        assert!(
            there > 5 * here.max(4),
            "{name}: {there} mm against {here} mm"
        );
    }
}

#[test]
fn the_camera_bridge_refuses_bad_input() {
    for (args, expected) in [
        (
            vec!["camera", "--vehicle", "udpout:127.0.0.1:14551@1,2"],
            "three numbers X,Y,NORTH",
        ),
        (vec!["camera", "--vehicle", "radio:14551"], "radio:14551"),
        (
            vec![
                "camera",
                "--vehicle",
                "udpout:127.0.0.1:14551",
                "--camera",
                "udpin:127.0.0.1:0",
            ],
            "give tcpin:HOST:PORT",
        ),
        (
            vec![
                "camera",
                "--vehicle",
                "udpout:127.0.0.1:14551",
                "--camera-hz",
                "0",
            ],
            "must be above 0",
        ),
    ] {
        let (ok, out) = sitl(&args);
        assert!(!ok, "{args:?}");
        assert!(out.contains(expected), "{args:?}: {out}");
    }
}
