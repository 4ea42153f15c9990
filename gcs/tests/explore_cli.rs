//! `gcs explore` end to end: two simulated drones explore the built-in apartment over MAVLink and
//! land, and every output file is readable by the tools that use it.

mod common;

use common::gcs;

#[test]
fn two_drones_explore_the_default_world_land_and_write_their_outputs() {
    // Navigation alone, on the simulator's poses: the map must be complete.
    let out = std::env::temp_dir().join(format!("gcs-explore-{}", std::process::id()));
    let run = gcs(&[
        "explore",
        "--drones",
        "2",
        "--speed",
        "5",
        "--timeout",
        "400",
        "--poses",
        "truth",
        "--json",
        "--out",
        out.to_str().expect("utf-8 path"),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    assert_eq!(summary["completed"], true, "{summary}");
    assert_eq!(summary["all_landed"], true, "{summary}");
    let coverage = summary["coverage"].as_f64().unwrap_or(0.0);
    assert!(coverage > 0.9, "coverage {coverage}: {summary}");
    let time = summary["exploration_time_s"].as_f64().unwrap_or(f64::MAX);
    assert!(time < 400.0, "{summary}");
    let drones = summary["drones"].as_array().expect("drones");
    assert_eq!(drones.len(), 2);
    for d in drones {
        assert!(d["path_length_m"].as_f64().unwrap_or(0.0) > 3.0, "{d}");
    }
    // Progress went to stderr while it ran.
    assert!(stderr.contains("coverage"), "{stderr}");
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
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn two_drones_explore_on_their_own_visual_odometry_and_land() {
    // The product as it is: every pose from the drones' cameras (no ground truth in the loop).
    let out = std::env::temp_dir().join(format!("gcs-explore-slam-{}", std::process::id()));
    let run = gcs(&[
        "explore",
        "--drones",
        "2",
        "--speed",
        "3",
        "--timeout",
        "300",
        "--json",
        "--out",
        out.to_str().expect("utf-8 path"),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    assert!(
        summary["pose_source"]
            .as_str()
            .unwrap_or("")
            .starts_with("slam"),
        "{summary}"
    );
    assert_eq!(summary["all_landed"], true, "{summary}");
    // Without loop closure the odometry drifts: the map is partial but real.
    assert!(
        summary["coverage"].as_f64().unwrap_or(0.0) > 0.4,
        "{summary}"
    );
    for d in summary["drones"].as_array().expect("drones") {
        let ate = d["ate_rmse_m"]
            .as_f64()
            .expect("an ATE against the simulator");
        assert!(ate < 0.6, "{d}");
        assert!(d["path_length_m"].as_f64().unwrap_or(0.0) > 3.0, "{d}");
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn bad_explore_arguments_are_refused_before_anything_starts() {
    for (args, expected) in [
        (vec!["explore", "--drones", "9"], "must be 1 to 8"),
        (vec!["explore", "--drones", "0"], "must be 1 to 8"),
        (vec!["explore", "--speed", "100"], "between 0.1 and 20"),
        (
            vec!["explore", "--timeout=-5"],
            "positive number of simulated seconds",
        ),
        (
            vec!["explore", "--world", "atlantis"],
            "no world 'atlantis'",
        ),
    ] {
        let run = gcs(&args);
        assert!(!run.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}
