//! `gcs plan` as a user runs it, on the real building maps.

mod common;

use common::gcs;

use serde_json::Value;

fn map(name: &str) -> String {
    format!(
        "{}/../../shared/data/maps/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// The least total over every way of giving distinct frontiers to the robots.
fn brute_force(costs: &[Vec<f64>]) -> f64 {
    fn rec(costs: &[Vec<f64>], r: usize, used: &mut Vec<bool>) -> f64 {
        if r == costs.len() {
            return 0.0;
        }
        let mut best = f64::INFINITY;
        for c in 0..used.len() {
            if !used[c] {
                used[c] = true;
                best = best.min(costs[r][c] + rec(costs, r + 1, used));
                used[c] = false;
            }
        }
        best
    }
    rec(costs, 0, &mut vec![false; costs[0].len()])
}

#[test]
fn plans_optimally_on_willow_and_draws_it() {
    let dir = std::env::temp_dir().join(format!("plan-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let png = dir.join("plan.png");
    let out = gcs(&[
        "plan",
        "--map",
        &map("willow-full.yaml"),
        "--robot",
        "12,30",
        "--robot",
        "20,30",
        "--robot",
        "30,22",
        "--explored-radius",
        "12",
        "--min-frontier",
        "20",
        "--json",
        "--png",
        &png.to_string_lossy(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let frontiers = v["frontiers"].as_array().expect("frontiers");
    assert!(frontiers.len() >= 3, "{} frontiers", frontiers.len());
    assert!(
        frontiers
            .iter()
            .all(|f| f["x"].is_f64() && f["y"].is_f64() && f["size"].as_u64().expect("size") >= 20)
    );
    assert_eq!(v["complete"], false);
    let costs: Vec<Vec<f64>> = serde_json::from_value(v["cost_matrix"].clone()).expect("matrix");
    assert_eq!(costs.len(), 3);
    let robots = v["robots"].as_array().expect("robots");
    let mut total = 0.0;
    for r in robots {
        let target = &r["target"];
        let path = r["path"].as_array().expect("path");
        assert!(path.len() >= 2, "{r}");
        // The path ends where the robot will look around from: near its target, not on the
        // frontier's edge (at most 1.5 m away, nav::vantage).
        let last = &path[path.len() - 1];
        let coord = |v: &Value| v.as_f64().expect("a number");
        let off =
            (coord(&last[0]) - coord(&target["x"])).hypot(coord(&last[1]) - coord(&target["y"]));
        assert!(off <= 1.5 + 1e-9, "{r}: {off} m from the target");
        total += r["cost"].as_f64().expect("cost");
    }
    // The assignment is optimal for the cost matrix it printed.
    assert!(
        (total - brute_force(&costs)).abs() < 1e-6,
        "{total} vs {}",
        brute_force(&costs)
    );
    assert!((v["total_cost"].as_f64().expect("total") - total).abs() < 1e-9);
    let img = image::open(&png).expect("a PNG");
    assert!(img.width() >= 1000 && img.height() >= 1000);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

#[test]
fn greedy_is_never_better_and_an_invalid_robot_hovers() {
    let args = |strategy: &str| {
        let out = gcs(&[
            "plan",
            "--map",
            &map("building_31.yaml"),
            "--robot",
            "0,0",
            "--robot",
            "5,2",
            "--robot",
            "none",
            "--explored-radius",
            "10",
            "--strategy",
            strategy,
            "--json",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice::<Value>(&out.stdout).expect("json")
    };
    let h = args("hungarian");
    let g = args("greedy");
    assert!(h["total_cost"].as_f64() <= g["total_cost"].as_f64());
    assert_eq!(h["robots"][2]["target"], Value::Null);
    assert_eq!(h["robots"][2]["hover_reason"], "pose invalid");
}

#[test]
fn text_output_names_every_robot() {
    let out = gcs(&[
        "plan",
        "--map",
        &map("building_31.yaml"),
        "--robot",
        "0,0",
        "--explored-radius",
        "6",
    ]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("robot 0 → frontier"), "{text}");
    assert!(text.contains("total path length"));
}

#[test]
fn a_reader_that_stops_reading_ends_it_quietly() {
    // `gcs plan … | head -1`: the pipe closes before the plan is printed.
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args([
            "plan",
            "--map",
            &map("willow-full.yaml"),
            "--robot",
            "10,10",
        ])
        .args(["--explored-radius", "8"])
        .stdout(writer)
        .output()
        .expect("run gcs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {stderr}", out.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Runs `gcs plan` with `args`, expecting it refused with exit code `code` and a message
/// containing `says`; returns the message.
fn refused(args: &[&str], code: i32, says: &str) -> String {
    let out = gcs(&[&["plan"][..], args].concat());
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
    assert!(stderr.contains(says), "{args:?}: {stderr}");
    stderr
}

#[test]
fn bad_input_gets_clear_errors() {
    let willow = map("willow-full.yaml");
    // A missing map file: named, and why said once.
    let stderr = refused(
        &["--map", "/nonexistent/map.yaml", "--robot", "0,0"],
        1,
        "/nonexistent/map.yaml",
    );
    assert_eq!(stderr.matches("No such file").count(), 1, "{stderr}");
    refused(
        &["--map", &willow, "--robot", "500,0"],
        1,
        "outside the map",
    );
    refused(&["--map", &willow, "--robot", "1;2"], 1, "expected X,Y");
    refused(
        &[
            "--map",
            &willow,
            "--robot",
            "12,30",
            "--region-radius",
            "NaN",
        ],
        1,
        "--region-radius must be",
    );
    refused(
        &["--map", &willow, "--robot", "12,30", "--max-pocket=-1"],
        1,
        "--max-pocket must be",
    );
    refused(&["--map", &willow], 2, "--robot");
    // A decision of a mission log: --at with --log only, and the log must be one.
    refused(&["--log", "/nonexistent/mission.mcap"], 2, "--at");
    refused(
        &["--map", &willow, "--robot", "12,30", "--at", "5"],
        1,
        "with --log",
    );
    refused(&["--log", &willow, "--at", "5"], 1, "is not an MCAP file");
    refused(
        &["--log", "/nonexistent/mission.mcap", "--at", "5"],
        1,
        "cannot read /nonexistent/mission.mcap",
    );
}
