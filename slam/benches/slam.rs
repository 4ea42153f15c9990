//! Pose-graph optimisation, side by side with GTSAM's Levenberg–Marquardt: `cargo bench -p slam`
//! (`bash scripts/bench` installs GTSAM into `target/pyenv`).
//!
//! Both start from the same estimate (written to a g2o file: the file's vertices, chained odometry
//! for manhattan, the chordal initialisation for torus3D) and stop on the same rule (relative
//! decrease below 1e-5, GTSAM's default). Our χ² is twice GTSAM's error.

use std::path::Path;
use std::time::Instant;

use slam::optimize::{Options, chordal_init, optimize};
use slam::posegraph::{AnyGraph, read_g2o, se_sync_objective, write_g2o};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/posegraph");
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pyenv/bin/python");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/gtsam_lm.py");
    let gtsam = python.exists()
        && std::process::Command::new(&python)
            .args(["-c", "import gtsam"])
            .status()
            .is_ok_and(|s| s.success());
    let tmp = std::env::temp_dir().join(format!("slam-bench-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&tmp);
    let runs = if quick { 1 } else { 3 };
    println!(
        "pose-graph optimisation, Levenberg–Marquardt (best of {runs}; GTSAM 4.3 in the same run)\n"
    );
    println!(
        "  {:<16} {:<8} {:>10} {:>14} {:>10} {:>14} {:>8} {:>12} {:>9}",
        "graph",
        "start",
        "ours ms",
        "ours χ²",
        "gtsam ms",
        "gtsam χ²",
        "speed-up",
        "F (ours)",
        "F*"
    );
    let cases = [
        ("intel.g2o", false, 52.35),
        ("manhattan.g2o", false, 6432.0),
        ("parking-garage.g2o", false, 1.263),
        ("sphere2500.g2o", false, 1687.0),
        ("torus3D.g2o", true, 24230.0),
    ];
    for (file, chordal, f_star) in cases {
        let Ok(mut start) = read_g2o(dir.join(file)) else {
            println!("  {file}: not found, skipped");
            continue;
        };
        if chordal && let AnyGraph::Se3(g) = &mut start {
            let _ = chordal_init(g);
        }
        let start_file = tmp.join(file);
        let _ = write_g2o(&start_file, &start);
        let options = Options {
            relative_tolerance: 1e-5,
            ..Options::default()
        };
        let mut best = f64::MAX;
        let mut ours = (0.0, 0.0);
        for _ in 0..runs {
            let mut g = start.clone();
            let t = Instant::now();
            let r = match &mut g {
                AnyGraph::Se2(g) => optimize(g, &options),
                AnyGraph::Se3(g) => optimize(g, &options),
            };
            best = best.min(t.elapsed().as_secs_f64());
            if let Ok(r) = r {
                ours = (r.final_cost, se_sync_objective(&g));
            }
        }
        let dim = if matches!(start, AnyGraph::Se2(_)) {
            "2"
        } else {
            "3"
        };
        let reference = if gtsam {
            std::process::Command::new(&python)
                .args([script.as_os_str(), start_file.as_os_str(), dim.as_ref()])
                .output()
                .ok()
                .filter(|o| o.status.success())
                .and_then(|o| {
                    let text = String::from_utf8_lossy(&o.stdout).into_owned();
                    let field = |k: &str| {
                        text.split(&format!("\"{k}\": "))
                            .nth(1)?
                            .split([',', '}'])
                            .next()?
                            .trim()
                            .parse::<f64>()
                            .ok()
                    };
                    Some((field("time_s")?, 2.0 * field("final_error")?))
                })
        } else {
            None
        };
        let (g_ms, g_chi2, speed) = match reference {
            Some((s, c)) => (
                format!("{:.1}", s * 1e3),
                format!("{c:.4}"),
                format!("{:.1}x", s / best),
            ),
            None => ("-".into(), "-".into(), "-".into()),
        };
        println!(
            "  {:<16} {:<8} {:>10.1} {:>14.4} {:>10} {:>14} {:>8} {:>12.4} {:>9}",
            file.trim_end_matches(".g2o"),
            if chordal { "chordal" } else { "file" },
            best * 1e3,
            ours.0,
            g_ms,
            g_chi2,
            speed,
            ours.1,
            f_star
        );
    }
    if !gtsam {
        println!(
            "\n  (GTSAM not found in target/pyenv: run `bash scripts/bench` to install it and compare)"
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
