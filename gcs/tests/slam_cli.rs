//! `gcs slam eval` on the shared TUM data.

use std::process::Command;

fn data(name: &str) -> String {
    format!(
        "{}/../../shared/data/rgbd/tum_fr1_xyz_trajectories/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn eval_reproduces_tums_ate_for_rgbdslam() {
    let out = Command::new(env!("CARGO_BIN_EXE_gcs"))
        .args([
            "slam",
            "eval",
            "--gt",
            &data("freiburg1_xyz-groundtruth.txt"),
            "--est",
            &data("freiburg1_xyz-rgbdslam.txt"),
            "--json",
        ])
        .output()
        .expect("run gcs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(v["pairs"], 786);
    assert!(
        (v["ate_rmse_m"].as_f64().expect("ate") - 0.0135).abs() < 0.00005,
        "{v}"
    );
    assert!(v["rpe_trans_m_per_s"].as_f64().expect("rpe") > 0.0);
    assert!(v["rpe_rot_deg_per_s"].as_f64().expect("rpe") > 0.0);
}

#[test]
fn eval_errors_are_clear() {
    let run = |gt: &str, est: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_gcs"))
            .args(["slam", "eval", "--gt", gt, "--est", est])
            .output()
            .expect("run");
        assert_eq!(out.status.code(), Some(1));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    assert!(
        run("/nonexistent.txt", &data("freiburg1_xyz-rgbdslam.txt")).contains("/nonexistent.txt")
    );
    // A file that is not a trajectory: the error names the line.
    assert!(
        run(
            &data("TUM1_camera.yaml"),
            &data("freiburg1_xyz-rgbdslam.txt")
        )
        .contains("TUM1_camera.yaml:")
    );
}
