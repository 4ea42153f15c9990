//! `gcs explore` end to end: simulated drones explore the built-in apartment (and a real
//! building's map) through the real link adapters and land, and every output file is readable
//! by the tools that use it.

mod common;

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use common::gcs;

/// Missions run one at a time: two at once on a small machine would starve each other's
/// control loops and measure the machine, not the station.
static ONE_MISSION_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Runs `gcs explore --json --out DIR` with `args`; returns the summary, stderr and DIR.
fn explore(name: &str, args: &[&str]) -> (serde_json::Value, String, PathBuf) {
    let _one = ONE_MISSION_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let out = std::env::temp_dir().join(format!("gcs-explore-{name}-{}", std::process::id()));
    let mut all = vec![
        "explore",
        "--json",
        "--out",
        out.to_str().expect("utf-8 path"),
    ];
    all.extend_from_slice(args);
    let run = gcs(&all);
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    (summary, stderr, out)
}

fn number(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The topics of an MCAP file with their schema names, and the message count.
fn mcap_topics(path: &Path) -> (std::collections::BTreeMap<String, String>, usize) {
    let bytes = std::fs::read(path).expect("mission.mcap");
    let mut topics = std::collections::BTreeMap::new();
    let mut count = 0;
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a readable message");
        let schema = m.channel.schema.as_ref().map_or("", |s| s.name.as_str());
        topics.insert(m.channel.topic.clone(), schema.to_owned());
        count += 1;
    }
    (topics, count)
}

/// The messages of a `foxglove.Log` topic of an MCAP file, as text: protobuf keeps a string's
/// bytes as they are, so the printable runs of each message hold its text.
fn mcap_texts(path: &Path, topic: &str) -> Vec<String> {
    let bytes = std::fs::read(path).expect("mission.mcap");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a readable message"))
        .filter(|m| m.channel.topic == topic)
        .map(|m| String::from_utf8_lossy(&m.data).into_owned())
        .collect()
}

/// The messages of a JSON topic of an MCAP file.
fn mcap_json(path: &Path, topic: &str) -> Vec<serde_json::Value> {
    let bytes = std::fs::read(path).expect("mission.mcap");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a readable message"))
        .filter(|m| m.channel.topic == topic)
        .map(|m| serde_json::from_slice(&m.data).expect("JSON"))
        .collect()
}

#[test]
fn two_drones_explore_the_default_world_land_and_write_their_outputs() {
    // Navigation on the simulator's poses (the SLAM maps on them): the map must be complete.
    let (summary, stderr, out) = explore(
        "truth",
        &[
            "--drones",
            "2",
            "--speed",
            "5",
            "--timeout",
            "400",
            "--poses",
            "truth",
        ],
    );
    assert_eq!(summary["completed"], true, "{summary}");
    assert_eq!(summary["all_landed"], true, "{summary}");
    assert!(number(&summary["coverage"]) >= 0.95, "{summary}");
    assert!(
        number(&summary["wall_error"]["within_0_1_m"]) >= 0.95,
        "{summary}"
    );
    assert!(number(&summary["exploration_time_s"]) < 400.0, "{summary}");
    // On true poses the drones keep off the walls and brake any approach to one faster than
    // can stop short of it (`nav::avoid`), a setpoint that jumps kicks nothing, and a drone
    // holding its spot beside a wall brakes (`nav::control`): no collision in 20 missions at
    // `--speed 5` run one at a time, nor in 20 run two at once (2 in the same 20 without the
    // approach brake). Since drones beside doors are lent frontiers a thinner radius reaches
    // (thinner paths flown more often): none in 10 one at a time, 1 in 10 two at once.
    assert_eq!(summary["collisions"], 0, "{summary}");
    let drones = summary["drones"].as_array().expect("drones");
    assert_eq!(drones.len(), 2);
    for d in drones {
        assert!(number(&d["path_length_m"]) > 3.0, "{d}");
        assert!(number(&d["flight_pose_error_m"]) < 0.1, "{d}");
        // RC overrides reached each autopilot regularly: far inside its 3 s override timeout
        // (in lock-step with the station's SLAM, simulated time can jump a camera period, 0.1 s,
        // between two frames).
        assert!(number(&d["rc_frames"]) > 1000.0, "{d}");
        assert!(number(&d["rc_gap_p99_ms"]) <= 200.0, "{d}");
        assert!(number(&d["rc_gap_max_ms"]) <= 1000.0, "{d}");
    }
    // Progress went to stderr while it ran, and what the vehicles said.
    assert!(stderr.contains("coverage"), "{stderr}");
    assert!(
        stderr.contains("drone 2 (vehicle): Arming motors"),
        "{stderr}"
    );
    // The same summary is on disk; the map loads as a map_server map and knows the apartment's
    // free space; the trajectories are TUM files; the 3D map is a PLY.
    let on_disk: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("summary.json")).expect("summary.json"),
    )
    .expect("summary.json is JSON");
    assert_eq!(on_disk, summary);
    let map = nav::grid::Grid::load(out.join("map.yaml")).expect("map.yaml loads");
    let [free, occupied, _] = map.counts();
    // The apartment has about 100 m² of floor: 40 000 cells of 5 cm.
    assert!(
        free > 30_000 && occupied > 2_000,
        "free {free}, occupied {occupied}"
    );
    for k in 1..=2 {
        for suffix in ["", "-truth"] {
            let t = slam::trajectory::read_tum(out.join(format!("drone{k}{suffix}.tum")))
                .expect("TUM trajectory");
            assert!(t.len() > 100, "drone {k}{suffix}: {} poses", t.len());
        }
    }
    let ply = std::fs::read_to_string(out.join("map.ply")).expect("map.ply");
    assert!(ply.starts_with("ply\nformat ascii 1.0\n"));
    assert!(image::open(out.join("map.png")).is_ok());
    // The log opens, with Foxglove's schemas where Foxglove has one.
    let (topics, messages) = mcap_topics(&out.join("mission.mcap"));
    for (topic, schema) in [
        ("/drone1/camera/color", "foxglove.CompressedImage"),
        ("/drone2/camera/depth", "foxglove.CompressedImage"),
        ("/drone1/camera/calibration", "foxglove.CameraCalibration"),
        ("/drone1/pose", "foxglove.PoseInFrame"),
        ("/tf", "foxglove.FrameTransform"),
        ("/map", "foxglove.Grid"),
        ("/map/points", "foxglove.PointCloud"),
        ("/drone2/state", "gcs.DroneState"),
        ("/plan", "gcs.Plan"),
        ("/setup", "gcs.Setup"),
        ("/drone2/camera/truth", "foxglove.PoseInFrame"),
        // What the autopilots said ("Arming motors").
        ("/drone1/status", "foxglove.Log"),
        ("/drone2/status", "foxglove.Log"),
        // What the station said ("drone 1: armed: taking off").
        ("/station", "foxglove.Log"),
    ] {
        assert_eq!(
            topics.get(topic).map(String::as_str),
            Some(schema),
            "{topic} in {topics:?}"
        );
    }
    assert!(messages > 1000, "{messages} messages");
    // Each decision with the path to each goal: from the drone (or the free cell nearest it,
    // up to a metre off) to where it looks around (within 1.5 m of its goal).
    let goals: Vec<serde_json::Value> = mcap_json(&out.join("mission.mcap"), "/plan")
        .iter()
        .flat_map(|plan| plan["goals"].as_array().cloned().unwrap_or_default())
        .filter(|g| g["goal"].is_array())
        .collect();
    assert!(!goals.is_empty(), "no decision gave a goal");
    let point = |v: &serde_json::Value| [number(&v[0]), number(&v[1])];
    let apart = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    for g in &goals {
        let path = g["path"].as_array().filter(|p| !p.is_empty());
        let path = path.unwrap_or_else(|| panic!("no path to the goal: {g}"));
        let (first, last) = (point(&path[0]), point(&path[path.len() - 1]));
        assert!(apart(first, point(&g["position"])) <= 1.0, "{g}");
        assert!(apart(last, point(&g["goal"])) <= 1.6, "{g}");
    }
    let said = mcap_texts(&out.join("mission.mcap"), "/station");
    for text in [
        "drone 1: armed: taking off",
        "no reachable frontier left after",
    ] {
        assert!(
            said.iter().any(|s| s.contains(text)),
            "{text:?} in {said:?}"
        );
    }
    // MAVLink traffic as .tlog: 8-byte timestamps before each packet, MAVLink 2 frames.
    let tlog = std::fs::read(out.join("drone1.tlog")).expect("drone1.tlog");
    assert!(tlog.len() > 1000 && tlog[8] == 0xFD, "{} bytes", tlog.len());
    replay_reproduces_the_map(&out);
    plan_makes_a_recorded_decision_again(&out);
    std::fs::remove_dir_all(&out).ok();
}

/// `gcs plan --log` makes a decision of the mission again, on the map it was made on and from
/// where the drones were, and gives the goals the mission gave; `--robot` moves the drones.
fn plan_makes_a_recorded_decision_again(out: &Path) {
    let log = out.join("mission.mcap");
    let plan = |extra: &[&str]| -> serde_json::Value {
        let run = gcs(&[
            &[
                "plan",
                "--log",
                log.to_str().expect("utf-8 path"),
                "--at",
                "20",
                "--json",
            ],
            extra,
        ]
        .concat());
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        serde_json::from_slice(&run.stdout).expect("JSON")
    };
    let p = plan(&[]);
    let decision = &p["decision"];
    assert!(number(&decision["t"]) >= 20.0, "{decision}");
    assert_eq!(decision["map_t"], decision["t"], "the map it was made on");
    assert_eq!(decision["positions"], "log");
    let drones = decision["drones"].as_array().expect("drones");
    let robots = p["robots"].as_array().expect("robots");
    assert_eq!(drones.len(), robots.len());
    assert!(
        drones.iter().any(|d| d["goal"].is_object()),
        "a drone had a goal at 20 s: {decision}"
    );
    for (d, r) in drones.iter().zip(robots) {
        assert_eq!(d["position"], r["position"], "{p}");
        assert_eq!(d["goal"], r["target"], "{p}");
    }
    // The positions given instead: drone 1 where it was, drone 2 without a pose.
    assert_eq!(drones.len(), 2, "both drones explored at 20 s: {decision}");
    let at = &drones[0]["position"];
    let at = format!("{},{}", number(&at["x"]), number(&at["y"]));
    let moved = plan(&["--robot", &at, "--robot", "none"]);
    assert_eq!(moved["decision"]["positions"], "--robot");
    assert_eq!(
        moved["robots"][1]["hover_reason"], "pose invalid",
        "{moved}"
    );
    assert!(moved["robots"][0]["target"].is_object(), "{moved}");
}

/// `gcs replay` on the mission's log maps the recorded frames on the recorded true poses again
/// and gets the mission's map and its planner decisions; a log cut short (a crash) still replays; a file that is no log
/// is refused with a reason.
fn replay_reproduces_the_map(out: &Path) {
    let log = out.join("mission.mcap");
    let replay = |log: &Path, dir: &str| {
        let dir = out.join(dir);
        let run = gcs(&[
            "replay",
            log.to_str().expect("utf-8 path"),
            "--truth-poses",
            "--json",
            "--out",
            dir.to_str().expect("utf-8 path"),
        ]);
        let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
        (run.status.success(), run.stdout, stderr, dir)
    };
    let (ok, stdout, stderr, dir) = replay(&log, "replay");
    assert!(ok, "{stderr}");
    let r: serde_json::Value = serde_json::from_slice(&stdout).expect("JSON");
    assert_eq!(r["truncated"], false, "{r}");
    assert!(number(&r["frames"]) > 1000.0, "{r}");
    assert!(number(&r["map"]["agreement"]) >= 0.99, "{r}");
    // The planner, run again at every recorded decision on the replayed map, gives the drones
    // the goals the mission gave them.
    assert!(number(&r["navigation"]["decisions"]) > 30.0, "{r}");
    assert!(number(&r["navigation"]["same_goal"]) >= 0.95, "{r}");
    assert!(nav::grid::Grid::load(dir.join("map.yaml")).is_ok());
    // The first 60 % of the file, as a writer killed mid-mission leaves it.
    let bytes = std::fs::read(&log).expect("mission.mcap");
    let cut = out.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).expect("write");
    let (ok, stdout, stderr, _) = replay(&cut, "replay-cut");
    assert!(ok, "{stderr}");
    let r: serde_json::Value = serde_json::from_slice(&stdout).expect("JSON");
    assert_eq!(r["truncated"], true, "{r}");
    assert!(number(&r["frames"]) > 100.0, "{r}");
    // Not a log at all.
    let (ok, _, stderr, _) = replay(&out.join("map.yaml"), "replay-bad");
    assert!(!ok);
    assert!(stderr.contains("is not an MCAP file"), "{stderr}");
}

#[test]
fn two_drones_on_slam_poses_over_the_shield_protocol_map_and_land_safely() {
    // The product as it is: every pose from the drones' cameras (no ground truth in the loop),
    // the vehicles behind the thesis's I/O shield. Tracking is still lost too often in flight
    // for the map to be complete every time (issue 7 stays open on it: coverage 57–97 % over
    // seeds); what must hold already: the drones come down safely whatever their tracking did,
    // the map's walls are where the world's are, and each drone flew on a pose within half a
    // metre of the truth (RMS; 0.07–0.31 m seen — it was 0.6–1.2 m while the camera queues
    // held 0.7 s of frames).
    let (summary, _, out) = explore(
        "slam",
        &[
            "--drones",
            "2",
            "--link",
            "shield",
            "--speed",
            "3",
            "--timeout",
            "300",
            "--no-log",
        ],
    );
    assert_eq!(summary["pose_source"], "slam", "{summary}");
    assert_eq!(summary["link"], "shield", "{summary}");
    assert_eq!(summary["all_landed"], true, "{summary}");
    assert!(number(&summary["keyframes"]) > 50.0, "{summary}");
    // A mission that ends "completed" short of the whole building says what stopped it.
    let left = number(&summary["frontiers_out_of_reach"]) + number(&summary["goals_given_up"]);
    assert!(left.is_finite(), "{summary}");
    if summary["completed"] == true && number(&summary["coverage"]) < 0.9 {
        assert!(left > 0.0, "{summary}");
    }
    // Goals never looked at (every look there lost the map) are some of those given up.
    assert!(
        number(&summary["goals_never_seen"]) <= number(&summary["goals_given_up"]),
        "{summary}"
    );
    assert!(number(&summary["wall_error"]["cells"]) > 100.0, "{summary}");
    assert!(
        number(&summary["wall_error"]["within_0_1_m"]) >= 0.8,
        "{summary}"
    );
    // Look-alike places matched turned: 0–10 per run (mean 3.8 over 11) before closures were
    // checked against the IMU headings, 0–2 (mean 0.4 over 7) after.
    assert!(number(&summary["loop_closures_wrong"]) <= 3.0, "{summary}");
    for d in summary["drones"].as_array().expect("drones") {
        assert!(number(&d["ate_rmse_m"]).is_finite(), "{d}");
        assert!(number(&d["path_length_m"]) > 3.0, "{d}");
        assert!(number(&d["flight_pose_error_m"]) <= 0.5, "{d}");
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn two_drones_keep_exploring_the_open_hall_of_a_real_building() {
    // The Willow Garage map: the drones start in a hall wider than the camera reaches, so the
    // first frontier is one ring around them. Its goal used to be the ring's centroid, where the
    // drones already were: both gave it up, and the mission "completed" after 30 s with 1.6 % of
    // the building seen. Two simulated minutes must leave them still exploring, well out. They
    // fly the altitude bands asked for: drone 1 at 1.2 m, drone 2 0.15 m above it.
    let map = format!(
        "{}/../../shared/data/maps/willow-full.yaml",
        env!("CARGO_MANIFEST_DIR")
    );
    let (summary, _, out) = explore(
        "willow",
        &[
            "--world",
            &map,
            "--drones",
            "2",
            "--poses",
            "truth",
            "--speed",
            "20",
            "--timeout",
            "120",
            "--altitude",
            "1.2",
            "--no-log",
        ],
    );
    assert_eq!(summary["outcome"], "timed out", "{summary}");
    assert!(number(&summary["coverage"]) > 0.05, "{summary}");
    assert_eq!(summary["all_landed"], true, "{summary}");
    for d in summary["drones"].as_array().expect("drones") {
        assert!(number(&d["path_length_m"]) > 20.0, "{d}");
    }
    for (k, band) in [(1, 1.2), (2, 1.35)] {
        let truth = slam::trajectory::read_tum(out.join(format!("drone{k}-truth.tum")))
            .expect("TUM trajectory");
        let mut z: Vec<f64> = truth.iter().map(|p| p.pose.translation.z).collect();
        z.sort_by(f64::total_cmp);
        let median = z.get(z.len() / 2).copied().unwrap_or(f64::NAN);
        assert!((median - band).abs() < 0.05, "drone {k} flew at {median} m");
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn two_drones_map_all_of_a_real_house_through_its_doors() {
    // HouseExpo's room 0000: four rooms, the west half behind a 0.74 m door. The simulator drew
    // an outline of wall inside the plan's polygon, which made that door 0.64 m, and the map's
    // walls (0.59 m) left no way through at the planner's narrowest margin: the mission
    // "completed" with the west half out of reach (55 %). Doors now keep the plan's width.
    let house = format!(
        "{}/../../shared/data/maps/house_expo_room_0000.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let (summary, _, out) = explore(
        "house",
        &[
            "--world",
            &house,
            "--drones",
            "2",
            "--poses",
            "truth",
            "--speed",
            "10",
            "--timeout",
            "400",
            "--no-log",
        ],
    );
    assert_eq!(summary["outcome"], "completed", "{summary}");
    assert!(number(&summary["coverage"]) >= 0.95, "{summary}");
    assert!(
        number(&summary["wall_error"]["within_0_1_m"]) >= 0.95,
        "{summary}"
    );
    assert_eq!(summary["all_landed"], true, "{summary}");
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn an_end_with_frontiers_out_of_reach_waits_for_the_map_to_settle_before_landing() {
    // Two rooms 3 m square; the drones start in the west one and see into the east one
    // through a slit 0.4 m wide, too narrow to fly: its frontiers stay out of reach.
    let dir = std::env::temp_dir().join(format!("gcs-slit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let world = dir.join("slit.txt");
    let mut rows = vec!["#".repeat(33)];
    for y in 1..16 {
        let mut row: Vec<char> = "#...............#...............#".chars().collect();
        if y == 8 || y == 9 {
            row[16] = '.';
        }
        if y == 12 {
            (row[4], row[8]) = ('1', '2');
        }
        rows.push(row.into_iter().collect());
    }
    rows.push("#".repeat(33));
    std::fs::write(
        &world,
        format!("resolution 0.2\nceiling 2.6\n---\n{}\n", rows.join("\n")),
    )
    .expect("the world file");
    let (summary, stderr, out) = explore(
        "slit",
        &[
            "--world",
            world.to_str().expect("utf-8 path"),
            "--poses",
            "truth",
            "--speed",
            "10",
            "--timeout",
            "200",
            "--no-log",
        ],
    );
    assert_eq!(summary["outcome"], "completed", "{summary}");
    assert!(
        number(&summary["frontiers_out_of_reach"]) >= 1.0,
        "{summary}"
    );
    assert_eq!(summary["all_landed"], true, "{summary}");
    // "no reachable frontier left after T s": first to hover, then, 5 s on, to land.
    let after = |tail: &str| {
        stderr
            .lines()
            .filter(|l| l.contains(tail))
            .find_map(|l| {
                let (_, rest) = l.split_once("no reachable frontier left after ")?;
                rest.split_once(" s")?.0.parse::<f64>().ok()
            })
            .unwrap_or_else(|| panic!("no \"{tail}\" in {stderr}"))
    };
    let hovered = after("for the map to settle before landing");
    let landed = after("): landing");
    assert!(landed - hovered >= 4.0, "{hovered} s, {landed} s");
    std::fs::remove_dir_all(&out).ok();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_drone_whose_link_dies_is_landed_by_its_failsafe_and_the_other_finishes_the_map() {
    let (summary, stderr, out) = explore(
        "kill",
        &[
            "--drones",
            "2",
            "--speed",
            "5",
            "--timeout",
            "500",
            "--poses",
            "truth",
            "--kill-link",
            "2@40",
            "--no-log",
        ],
    );
    assert!(stderr.contains("killing drone 2's link"), "{stderr}");
    assert_eq!(summary["completed"], true, "{summary}");
    assert!(number(&summary["coverage"]) >= 0.95, "{summary}");
    assert_eq!(
        summary["drones"][1]["final_phase"], "link lost",
        "{summary}"
    );
    assert_eq!(
        summary["drones"][1]["left_mission"], "link lost",
        "{summary}"
    );
    assert!(summary["drones"][0]["left_mission"].is_null(), "{summary}");
    // The vehicle landed itself (GCS-heartbeat failsafe), the other landed when done.
    assert_eq!(summary["all_landed"], true, "{summary}");
    assert!(!out.join("mission.mcap").exists());
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn a_drone_whose_camera_dies_and_one_whose_battery_runs_low_go_home_and_the_third_finishes() {
    let (summary, stderr, out) = explore(
        "faults",
        &[
            "--drones",
            "3",
            "--speed",
            "5",
            "--timeout",
            "500",
            "--poses",
            "truth",
            "--fault",
            "camera:2@40",
            "--fault",
            "battery:3@40",
            "--no-log",
        ],
    );
    assert!(stderr.contains("killing drone 2's camera"), "{stderr}");
    assert!(
        stderr.contains("drone 2: no camera frame for 5 s: returning to its start"),
        "{stderr}"
    );
    // 20 % is above the reserve, but a pack that lost 80 % in 40 s needs more than that to
    // come home from anywhere: sized to its way home, it is low.
    assert!(
        stderr.contains("drone 3: battery at 20 %: returning to its start"),
        "{stderr}"
    );
    assert!(
        stderr
            .lines()
            .any(|l| l.contains("drone 3: battery at 20 %: ")
                && l.contains(" m from its start: about ")),
        "{stderr}"
    );
    assert!(stderr.contains("drone 3: home: landing"), "{stderr}");
    assert_eq!(summary["completed"], true, "{summary}");
    assert!(number(&summary["coverage"]) >= 0.95, "{summary}");
    assert_eq!(summary["all_landed"], true, "{summary}");
    for d in summary["drones"].as_array().expect("drones") {
        assert_eq!(d["final_phase"], "landed", "{d}");
    }
    let left: Vec<&serde_json::Value> = summary["drones"]
        .as_array()
        .expect("drones")
        .iter()
        .map(|d| &d["left_mission"])
        .collect();
    assert!(left[0].is_null(), "{summary}");
    assert_eq!(left[1], "no camera frame for 5 s", "{summary}");
    assert_eq!(left[2], "battery at 20 %", "{summary}");
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn a_drone_home_for_its_battery_gets_a_charged_one_and_rejoins_the_exploration() {
    // MAVLink reports the charge left; the shield only the pack's voltage, from which the
    // station reads the charge.
    for (link, low, charged) in [
        ("mavlink", "battery at 20 %", "(100 %)"),
        ("shield", "battery at 1", " V)"),
    ] {
        let (summary, stderr, out) = explore(
            &format!("swap-{link}"),
            &[
                "--link",
                link,
                "--drones",
                "2",
                "--speed",
                "5",
                "--timeout",
                "500",
                "--poses",
                "truth",
                "--fault",
                "battery:2@40",
                "--battery-swap",
                "10",
                "--no-log",
            ],
        );
        let said = |what: &str| {
            stderr
                .find(what)
                .unwrap_or_else(|| panic!("{link}: {what}: {stderr}"))
        };
        said(&format!("drone 2: {low}"));
        if link == "shield" {
            // The charge read off the voltage as it fell (a pack that loses that much so fast
            // is low before the reading is down to 20 %).
            let reading = &stderr[said("drone 2: battery at 1") + "drone 2: ".len()..];
            let reading = &reading[..reading.find(": ").unwrap_or(reading.len())];
            assert!(
                reading.contains(" V (about ") && reading.ends_with(" %)"),
                "{reading}"
            );
        }
        said("returning to its start");
        said("drone 2: landed: waiting for a charged battery to rejoin");
        let replaced = stderr
            .to_lowercase()
            .find("drone 2 (vehicle): battery replaced");
        assert!(replaced.is_some(), "{link}: {stderr}");
        let rejoined = said("taking off in 5 s to rejoin");
        assert!(
            stderr[..rejoined].ends_with(&format!("{charged}: ")),
            "{link}: {stderr}"
        );
        // It flew again: taking off a second time, after the swap.
        assert!(
            stderr[rejoined..].contains("drone 2: armed: taking off"),
            "{link}: {stderr}"
        );
        assert_eq!(summary["completed"], true, "{link}: {summary}");
        assert!(number(&summary["coverage"]) >= 0.95, "{link}: {summary}");
        assert_eq!(summary["all_landed"], true, "{link}: {summary}");
        let drones = summary["drones"].as_array().expect("drones");
        assert_eq!(drones[0]["battery_swaps"], 0, "{link}: {summary}");
        assert_eq!(drones[1]["battery_swaps"], 1, "{link}: {summary}");
        for d in drones {
            assert!(d["left_mission"].is_null(), "{link}: {d}");
            assert_eq!(d["final_phase"], "landed", "{link}: {d}");
        }
        std::fs::remove_dir_all(&out).ok();
    }
}

#[test]
fn drones_whose_battery_runs_down_turn_home_in_time_over_either_link() {
    // Two minutes of flight on a pack (the two drones explore the apartment in about two): the
    // drones turn home when what is left would only just bring them back, read off the
    // autopilot's charge over MAVLink and off the voltage over the shield, and land at their
    // starts with more than the reserve left and not much more than the way home's margin.
    for link in ["mavlink", "shield"] {
        let (summary, stderr, out) = explore(
            &format!("flight-time-{link}"),
            &[
                "--link",
                link,
                "--speed",
                "5",
                "--timeout",
                "300",
                "--poses",
                "truth",
                "--flight-time",
                "2",
                "--no-log",
            ],
        );
        assert_eq!(summary["all_landed"], true, "{link}: {summary}");
        assert!(
            stderr.contains(" m from its start: about "),
            "{link}: the return was not sized to a way home: {stderr}"
        );
        for d in summary["drones"].as_array().expect("drones") {
            let why = d["left_mission"].as_str().unwrap_or_default();
            assert!(why.starts_with("battery at "), "{link}: {d}");
            assert_eq!(why.contains(" V (about "), link == "shield", "{link}: {d}");
            assert_eq!(d["final_phase"], "landed", "{link}: {d}");
            let left = number(&d["battery_left_pct"]);
            assert!((15.0..=45.0).contains(&left), "{link}: {d}");
        }
        assert!(
            stderr.matches(": home: landing").count() == 2,
            "{link}: {stderr}"
        );
        std::fs::remove_dir_all(&out).ok();
    }
}

#[test]
fn bad_explore_arguments_are_refused_before_anything_starts() {
    for (args, expected) in [
        (vec!["explore", "--drones", "9"], "must be 1 to 8"),
        (vec!["explore", "--drones", "0"], "must be 1 to 8"),
        (vec!["explore", "--speed", "100"], "between 0.1 and 20"),
        (
            vec!["explore", "--drones", "8", "--altitude", "1.2"],
            "puts drone 8 at 2.25 m, above the 2.0 m",
        ),
        (
            vec!["explore", "--altitude", "0.2"],
            "--altitude 0.2 must be 0.25 metres or more",
        ),
        (
            vec!["explore", "--altitude", "NaN"],
            "--altitude NaN must be 0.25 metres or more",
        ),
        (
            vec!["explore", "--log-camera-hz=-2"],
            "must be 0 (no frames) or more",
        ),
        (
            vec!["explore", "--flight-time", "0.5"],
            "between 1 and 600 minutes",
        ),
        (
            vec!["explore", "--battery-swap=-1"],
            "must be between 0 and 3600 seconds",
        ),
        (
            vec!["explore", "--region-radius=-1"],
            "must be between 0 (off) and 50 metres",
        ),
        (
            vec!["explore", "--hold-margin", "NaN"],
            "must be between 0 (off) and 50 metres",
        ),
        (
            vec!["explore", "--unknown-comfort=-0.2"],
            "--unknown-comfort -0.2 must be between 0 (off) and 5 metres",
        ),
        (
            vec!["explore", "--unknown-comfort", "inf"],
            "must be between 0 (off) and 5 metres",
        ),
        (
            vec!["explore", "--max-pocket=-0.5"],
            "must be between 0 (off) and 100 square metres",
        ),
        (
            vec!["explore", "--timeout=-5"],
            "positive number of simulated seconds",
        ),
        (
            vec!["explore", "--world", "atlantis"],
            "no world 'atlantis'",
        ),
        (vec!["explore", "--kill-link", "3@10"], "expected K@T"),
        (
            vec!["explore", "--fault", "smoke:1@10"],
            "expected KIND:K@T with KIND link, camera or battery",
        ),
        (
            vec!["explore", "--fault", "camera:1@-3"],
            "expected KIND:K@T",
        ),
    ] {
        let run = gcs(&args);
        assert!(!run.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}
