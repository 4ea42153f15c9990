//! Failures of the station itself: it is killed mid-mission (the vehicles land on their own and
//! what it wrote stays readable), and what it exposes to the network (loopback only).

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{is_loopback, open_ports, serve_fleet};
use sitl::Protocol;

fn eventually(limit: Duration, mut ok: impl FnMut() -> bool) -> bool {
    let until = Instant::now() + limit;
    while Instant::now() < until {
        if ok() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    ok()
}

#[test]
fn a_killed_station_leaves_readable_logs_and_its_vehicles_land_themselves() {
    let dir = std::env::temp_dir().join(format!("gcs-killed-{}", std::process::id()));
    let (sitl, fleet) = serve_fleet(&dir, &[Protocol::Mavlink, Protocol::Shield]);
    let out = dir.join("out");
    let mut station = Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args(["fly", "--config"])
        .arg(&fleet)
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start gcs fly");
    let airborne = |sitl: &sitl::Sitl| {
        sitl.with_sim(|sim| (0..sim.len()).all(|k| sim.vehicle(k).state().position[2] > 0.5))
    };
    assert!(
        eventually(Duration::from_secs(60), || airborne(&sitl)),
        "both drones must take off"
    );
    // The station reaches its vehicles and cameras by connecting out: it accepts nothing.
    let open = open_ports(station.id());
    assert!(open.is_empty(), "gcs fly listens on {open:?}");
    std::thread::sleep(Duration::from_secs(5));

    station.kill().expect("kill the station"); // SIGKILL: no clean-up runs
    station.wait().expect("reap it");
    let killed = Instant::now();
    // The MAVLink vehicle lands on its GCS failsafe (5 s without a heartbeat), the shield on its
    // link-loss failsafe (1 s without a command); both disarm on the ground.
    assert!(
        eventually(Duration::from_secs(60), || sitl.with_sim(|sim| {
            (0..sim.len()).all(|k| {
                let s = sim.vehicle(k).state();
                s.landed && !s.armed
            })
        })),
        "the vehicles must land and disarm on their own"
    );
    eprintln!(
        "both down and disarmed {:?} after the kill",
        killed.elapsed()
    );

    // The log reads up to its last flush (at most a second before the kill).
    let log = gcs::mission_log::load(&out.join("mission.mcap")).expect("the log reads");
    assert!(log.messages > 100, "{} messages", log.messages);
    assert!(log.frames.len() > 20, "{} camera frames", log.frames.len());
    assert!(
        log.states.iter().all(|s| !s.is_empty()),
        "every drone's states"
    );
    let tlog = link::tlog::TlogReader::open(out.join("drone1.tlog")).expect("the tlog opens");
    let records = tlog.filter(Result::is_ok).count();
    assert!(records > 100, "{records} MAVLink frames in the tlog");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn gcs_explore_accepts_connections_on_loopback_only() {
    let out = std::env::temp_dir().join(format!("gcs-ports-{}", std::process::id()));
    let mut station = Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args([
            "explore",
            "--poses",
            "truth",
            "--timeout",
            "30",
            "--no-log",
            "--out",
        ])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start gcs explore");
    let mut open = vec![];
    assert!(eventually(Duration::from_secs(30), || {
        open = open_ports(station.id());
        open.len() >= 2 // the simulator's two vehicle endpoints
    }));
    let _ = station.kill();
    let _ = station.wait();
    let exposed: Vec<_> = open.iter().filter(|(_, a)| !is_loopback(a)).collect();
    assert!(
        exposed.is_empty(),
        "reachable from the network: {exposed:?}"
    );
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn ctrl_c_lands_every_drone_and_the_outputs_are_still_written() {
    use std::io::{BufRead, BufReader, Read};
    let out = std::env::temp_dir().join(format!("gcs-ctrl-c-{}", std::process::id()));
    let mut station = Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args([
            "explore",
            "--poses",
            "truth",
            "--speed",
            "5",
            "--timeout",
            "600",
            "--no-log",
            "--json",
            "--out",
        ])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start gcs explore");
    let stderr = station.stderr.take().expect("stderr");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    // Exploring for a while, then the operator presses Ctrl-C.
    let mut lines = vec![];
    let until = Instant::now() + Duration::from_secs(120);
    while Instant::now() < until {
        let Ok(line) = rx.recv_timeout(Duration::from_secs(1)) else {
            continue;
        };
        lines.push(line);
        if lines
            .iter()
            .filter(|l| l.contains("1: exploring, 2: exploring"))
            .count()
            >= 2
        {
            break;
        }
    }
    assert!(Instant::now() < until, "never explored: {lines:#?}");
    let interrupted = Command::new("kill")
        .args(["-INT", &station.id().to_string()])
        .status()
        .expect("kill -INT");
    assert!(interrupted.success());
    let ended = eventually(Duration::from_secs(90), || {
        matches!(station.try_wait(), Ok(Some(_)))
    });
    assert!(ended, "gcs explore did not end after Ctrl-C");
    let status = station.wait().expect("exit status");
    lines.extend(rx.try_iter());
    let stderr = lines.join("\n");
    assert!(status.success(), "{stderr}");
    assert!(
        stderr.contains("explore: Ctrl-C: landing every drone"),
        "{stderr}"
    );
    let mut stdout = String::new();
    station
        .stdout
        .take()
        .expect("stdout")
        .read_to_string(&mut stdout)
        .expect("read stdout");
    let summary: serde_json::Value =
        serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    assert_eq!(summary["completed"], false, "{summary}");
    assert_eq!(summary["all_landed"], true, "{summary}");
    assert!(out.join("map.pgm").is_file() && out.join("summary.json").is_file());
    std::fs::remove_dir_all(&out).ok();
}
