//! The operator's window on a real mission: the simulator in-process, two drones over MAVLink on
//! loopback sockets, the mission runtime, and the window driven headless by `egui_kittest`
//! (buttons → runtime → vehicles, and what the vehicles do back on the panels); then the real
//! window under Xvfb with Mesa's software OpenGL, screenshotted and checked.
mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use gcs::fleet::{LinkKind, SimFleet, SimFleetConfig};
use gcs::gui::{GcsApp, Station};
use gcs::runtime::{Runtime, RuntimeConfig};
use sitl::World;
use slam::system::{Slam, SlamConfig};

/// Steps the window until `done` holds, failing with `what` after `limit` of wall time.
fn wait_for(
    h: &mut Harness<'_, GcsApp>,
    limit: Duration,
    what: &str,
    mut done: impl FnMut(&Harness<'_, GcsApp>) -> bool,
) {
    let start = Instant::now();
    loop {
        h.run_steps(1);
        if done(h) {
            return;
        }
        assert!(start.elapsed() < limit, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Every simulated vehicle's (armed, height).
fn vehicles(fleet_sitl: &sitl::Sitl) -> Vec<(bool, f64)> {
    fleet_sitl.with_sim(|sim| {
        (0..sim.len())
            .map(|k| {
                let s = sim.vehicle(k).state();
                (s.armed, s.position[2])
            })
            .collect()
    })
}

#[test]
fn window_buttons_fly_the_simulated_fleet_and_show_a_lost_link() {
    let world = Arc::new(World::load("apartment").expect("built-in world"));
    let fleet = SimFleet::start(&SimFleetConfig {
        world: world.clone(),
        drones: 2,
        link: LinkKind::Mavlink,
        speed: 3.0,
        seed: 1,
        flight_time_s: 720.0,
        battery_swap_s: None,
        tlog_dir: None,
        lowest_band_m: gcs::fleet::LOWEST_BAND_M,
    })
    .expect("the simulated fleet starts");
    let SimFleet {
        sitl,
        drones,
        frames,
        setups,
        clock,
    } = fleet;
    let runtime = Runtime::start(
        RuntimeConfig {
            auto_start: false,
            exit_when_done: false,
            ..RuntimeConfig::default()
        },
        drones,
        // Ground-truth poses: this test is about the window, not the SLAM.
        Slam::new(
            SlamConfig {
                known_poses: true,
                ..SlamConfig::default()
            },
            setups,
        ),
        frames,
        clock,
        None,
    )
    .expect("the runtime starts");
    let app = GcsApp::new(Station::of(&runtime, Some(world), "test"));
    let mut h = Harness::builder()
        .with_size(egui::vec2(1400.0, 900.0))
        .build_ui_state(|ui, app: &mut GcsApp| app.show(ui), app);
    let minute = Duration::from_secs(60);

    // Waiting, both connected, on the ground.
    wait_for(&mut h, minute, "both links connected", |h| {
        h.query_all_by_label("connected").count() == 2
    });
    h.get_by_label("waiting for start");
    assert!(vehicles(&sitl).iter().all(|(armed, _)| !armed));

    // Start, confirmed: both arm and climb, and the panels say so.
    h.get_by_label("Start mission").click();
    h.run_steps(2);
    h.get_by_label("Confirm").click();
    wait_for(&mut h, minute, "both drones airborne", |_| {
        vehicles(&sitl).iter().all(|&(armed, z)| armed && z > 0.5)
    });
    wait_for(&mut h, minute, "the panels to show both armed", |h| {
        h.query_all_by_label("armed").count() == 2
    });

    // Drone 2's link dies: shown at once (banner and card); its own failsafe will land it.
    sitl.kill_endpoint(1);
    wait_for(&mut h, minute, "the lost link on the panels", |h| {
        h.query_by_label("LINK LOST: drone 2").is_some()
            && h.query_all_by_label("link lost").count() >= 2
    });

    // LAND ALL: drone 1 lands on the station's command, drone 2 by its failsafe.
    h.get_by_label("LAND ALL").click();
    wait_for(&mut h, Duration::from_secs(90), "both drones down", |_| {
        vehicles(&sitl).iter().all(|&(armed, z)| !armed && z < 0.1)
    });
    wait_for(&mut h, minute, "the panel to show drone 1 landed", |h| {
        h.query_by_label("landed").is_some()
    });
    drop(runtime);
}

/// `gcs` in a virtual X server (Xvfb, Mesa's software OpenGL) of 1400×900 pixels.
fn under_xvfb() -> Command {
    if Command::new("xvfb-run").arg("--help").output().is_err() {
        panic!(
            "xvfb-run is missing: install it (Debian: apt-get install xvfb) to test the real window"
        );
    }
    let mut c = Command::new("xvfb-run");
    c.args(["-a", "-s", "-screen 0 1400x900x24"])
        .arg(env!("CARGO_BIN_EXE_gcs"));
    c
}

/// The process whose command line holds `argument` (the `gcs` that `xvfb-run` started).
fn process_with_argument(argument: &str) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.find_map(|e| {
        let pid: u32 = e.ok()?.file_name().to_str()?.parse().ok()?;
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
        let is_gcs = cmdline
            .split(|b| *b == 0)
            .next()
            .is_some_and(|exe| exe.ends_with(b"gcs"));
        (is_gcs && cmdline.split(|b| *b == 0).any(|a| a == argument.as_bytes())).then_some(pid)
    })
}

/// The window itself, under Xvfb with software OpenGL, exploring; its screenshot must show the
/// map. Writes `target/gui-screenshot.png` (the README's picture is made the same way).
#[test]
fn real_window_under_xvfb_shows_the_map() {
    let target = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target");
    let shot = target.join("gui-screenshot.png");
    let out = std::env::temp_dir().join(format!("gcs-gui-{}", std::process::id()));
    let _ = std::fs::remove_file(&shot);
    let run = under_xvfb()
        .args([
            "gui",
            "--start",
            "--poses",
            "truth",
            "--speed",
            "4",
            "--screenshot-at",
            "30",
            "--quit-after",
            "30",
            "--no-log",
        ])
        .arg("--screenshot")
        .arg(&shot)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run xvfb-run");
    // While it flies: the window and its simulator accept connections on loopback only.
    let until = Instant::now() + Duration::from_secs(30);
    let mut open = vec![];
    while open.len() < 2 && Instant::now() < until {
        if let Some(pid) = process_with_argument(&out.to_string_lossy()) {
            open = common::open_ports(pid);
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        open.len() >= 2,
        "the simulator's two vehicle endpoints never showed: {open:?}"
    );
    let exposed: Vec<_> = open
        .iter()
        .filter(|(_, a)| !common::is_loopback(a))
        .collect();
    assert!(
        exposed.is_empty(),
        "gcs gui is reachable from the network: {exposed:?}"
    );
    let run = run.wait_with_output().expect("wait for xvfb-run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "gcs gui failed:\n{stderr}");
    assert!(stderr.contains("screenshot written"), "{stderr}");
    let picture = image::open(&shot)
        .expect("the screenshot is a PNG")
        .to_rgb8();
    assert!(picture.width() >= 1000 && picture.height() >= 700);
    // Not blank: many colours.
    let mut colours: Vec<[u8; 3]> = picture.pixels().map(|p| p.0).collect();
    colours.sort_unstable();
    colours.dedup();
    assert!(colours.len() > 50, "{} colours: blank?", colours.len());
    // The map is visible: explored free space in the map's own colour, and both drones.
    let count = |c: egui::Color32| {
        picture
            .pixels()
            .filter(|p| p.0 == [c.r(), c.g(), c.b()])
            .count()
    };
    let free = count(gcs::gui::FREE);
    assert!(free > 20_000, "only {free} pixels of explored free space");
    for k in 0..2 {
        let n = count(gcs::gui::drone_colour(k));
        assert!(n > 30, "drone {} is {n} pixels", k + 1);
    }
    // The summary of the session was written when the window closed.
    assert!(out.join("summary.json").exists(), "{stderr}");
    let _ = std::fs::remove_dir_all(&out);
}

/// Runs `gcs` with `args` and no display.
fn gcs_headless(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("run gcs")
}

#[test]
fn bad_window_arguments_and_no_display_are_explained() {
    let out = gcs_headless(&["gui", "--screenshot", "shot.jpg"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("name it FILE.png"), "{err}");

    let out = gcs_headless(&["gui", "--quit-after=-3"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--quit-after -3"), "{err}");

    let out = gcs_headless(&["gui", "--config", "fleet.toml", "--drones", "3"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot be used with"), "{err}");

    // No display: the simulated fleet starts, nothing takes off, and the error says what to do.
    let dir = std::env::temp_dir().join(format!("gcs-gui-nodisplay-{}", std::process::id()));
    let out = gcs_headless(&[
        "gui",
        "--no-log",
        "--out",
        dir.to_str().expect("utf-8 path"),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot show the window"), "{err}");
    assert!(err.contains("xvfb-run"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `gcs gui --config`: the window on external vehicles (a simulator serving a MAVLink vehicle
/// and its camera over TCP, as hardware would be), started from the command line, shown under
/// Xvfb, and everything landed when it closes.
#[test]
fn window_on_a_fleet_file_flies_and_lands_the_external_vehicle() {
    let dir = std::env::temp_dir().join(format!("gcs-gui-fleet-{}", std::process::id()));
    let (sitl, fleet) = common::serve_fleet(&dir, &[sitl::Protocol::Mavlink]);
    let shot = dir.join("fleet.png");
    let run = under_xvfb()
        .args([
            "gui",
            "--start",
            "--screenshot-at",
            "12",
            "--quit-after",
            "12",
            "--no-log",
        ])
        .arg("--config")
        .arg(&fleet)
        .arg("--screenshot")
        .arg(&shot)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .expect("run xvfb-run");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "gcs gui --config failed:\n{stderr}");
    // It flew (the mission ran 12 s) and the window's closing landed it.
    let picture = image::open(&shot).expect("the screenshot").to_rgb8();
    let c = gcs::gui::drone_colour(0);
    let drone = picture
        .pixels()
        .filter(|p| p.0 == [c.r(), c.g(), c.b()])
        .count();
    assert!(drone > 30, "the drone is {drone} pixels");
    sitl.with_sim(|sim| {
        let s = sim.vehicle(0).state();
        assert!(s.landed && !s.armed, "{s:?}");
    });
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/summary.json")).expect("summary.json"))
            .expect("JSON");
    assert_eq!(summary["outcome"], "land all", "{summary}");
    assert_eq!(summary["drones"][0]["name"], "alpha", "{summary}");
    assert_eq!(summary["drones"][0]["final_phase"], "landed", "{summary}");
    assert!(
        summary["drones"][0]["path_length_m"]
            .as_f64()
            .unwrap_or(0.0)
            > 0.5,
        "{summary}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
