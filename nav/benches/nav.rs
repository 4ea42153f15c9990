//! Navigation benchmarks: `cargo bench -p nav` (`-- --quick` for a short run).
//!
//! * one full mission-planner step (inflation + frontiers + cost matrix + assignment + paths) on
//!   `willow-full` and `building_31`, for 2, 4 and 8 robots, on the part of the building the robots
//!   have explored within 10 m of their starts, on paths alone and with the robots' turns weighed;
//! * the Hungarian algorithm side by side with SciPy's `linear_sum_assignment` on the same random
//!   matrices, 10×10 to 1000×1000 (SciPy from `target/pyenv`: `bash scripts/bench` installs it).

use std::path::Path;
use std::time::Instant;

use nav::assignment::{hungarian, total};
use nav::search::nearest_free;
use nav::{Cell, Grid, PlannerConfig, explored_part, plan};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    println!(
        "nav benchmarks ({} run)\n",
        if quick { "quick" } else { "full" }
    );
    mission_steps(if quick { 3 } else { 15 });
    assignment(quick);
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `n` robot starts spread over the free cells of `world` (deterministic).
fn starts(world: &Grid, n: usize) -> Vec<[f64; 2]> {
    let free: Vec<usize> = (0..world.cells().len())
        .filter(|&i| world.cells()[i] == Cell::Free)
        .collect();
    // Spread along the free cells, then snap to cells with room around them.
    (0..n)
        .filter_map(|k| {
            let c = world.xy(free[(free.len() * (2 * k + 1)) / (2 * n)]);
            nearest_free(world, c, 20).map(|c| world.center_of(c))
        })
        .collect()
}

fn mission_steps(runs: usize) {
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/maps");
    println!("mission planner step (median of {runs}):");
    for file in ["willow-full.yaml", "building_31.yaml"] {
        let Ok(world) = Grid::load(maps.join(file)) else {
            println!("  {file}: not found, skipped");
            continue;
        };
        for n in [2, 4, 8] {
            let seeds = starts(&world, n);
            let known = explored_part(&world, &seeds, 10.0);
            let robots: Vec<Option<[f64; 2]>> = seeds.iter().copied().map(Some).collect();
            // As the runtime plans: every robot's heading known, so each path's turn is weighed.
            let facing = PlannerConfig {
                headings: vec![Some(0.0); n],
                ..PlannerConfig::default()
            };
            let mut times = [vec![], vec![]];
            let mut summary = String::new();
            for _ in 0..runs {
                for (k, config) in [PlannerConfig::default(), facing.clone()]
                    .iter()
                    .enumerate()
                {
                    let t = Instant::now();
                    let p = plan(&known, &robots, config);
                    times[k].push(t.elapsed().as_secs_f64());
                    if let Ok(p) = p {
                        let assigned = p.robots.iter().filter(|r| r.frontier.is_some()).count();
                        summary = format!(
                            "{} frontiers, {assigned}/{n} robots assigned",
                            p.frontiers.len()
                        );
                    }
                }
            }
            let [paths, turns] = times.map(median);
            println!(
                "  {file:<18} {n} robots: {:8.2} ms, {:8.2} ms with turns weighed   ({summary})",
                paths * 1e3,
                turns * 1e3
            );
        }
    }
    println!();
}

/// Deterministic uniform costs in [0, 1000).
fn matrix(n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut x = seed | 1;
    (0..n)
        .map(|_| {
            (0..n)
                .map(|_| {
                    x ^= x >> 12;
                    x ^= x << 25;
                    x ^= x >> 27;
                    (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
                        * 1000.0
                })
                .collect()
        })
        .collect()
}

fn assignment(quick: bool) {
    let sizes: &[usize] = if quick {
        &[10, 100, 300]
    } else {
        &[10, 50, 100, 200, 500, 1000]
    };
    let python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pyenv/bin/python");
    let scipy = python.exists()
        && std::process::Command::new(&python)
            .args(["-c", "import scipy.optimize, numpy"])
            .status()
            .is_ok_and(|s| s.success());
    println!("assignment, random n×n costs (best of runs):");
    println!(
        "  {:>6} {:>14} {:>14} {:>10}  totals agree",
        "n", "hungarian ms", "scipy ms", "ratio"
    );
    let dir = std::env::temp_dir().join(format!("nav-bench-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    for &n in sizes {
        let m = matrix(n, n as u64 * 7919);
        let runs = if n >= 500 { 3 } else { 10 };
        let mut best = f64::MAX;
        let mut ours = 0.0;
        for _ in 0..runs {
            let t = Instant::now();
            let a = hungarian(&m);
            best = best.min(t.elapsed().as_secs_f64());
            ours = total(&m, &a);
        }
        let (scipy_ms, agree) = if scipy {
            let path = dir.join(format!("m{n}.f64"));
            let bytes: Vec<u8> = m.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
            let _ = std::fs::write(&path, bytes);
            let script = format!(
                "import numpy as np, time\nfrom scipy.optimize import linear_sum_assignment\nm = np.fromfile('{}', dtype='<f8').reshape({n}, {n})\nbest = 1e9\nfor _ in range({runs}):\n    t = time.perf_counter(); r, c = linear_sum_assignment(m); best = min(best, time.perf_counter() - t)\nprint(best, m[r, c].sum())",
                path.display()
            );
            match std::process::Command::new(&python)
                .args(["-c", &script])
                .output()
            {
                Ok(o) if o.status.success() => {
                    let text = String::from_utf8_lossy(&o.stdout);
                    let v: Vec<f64> = text
                        .split_whitespace()
                        .filter_map(|x| x.parse().ok())
                        .collect();
                    match v[..] {
                        [s, t] => (
                            Some(s * 1e3),
                            Some((t - ours).abs() <= 1e-6 * t.abs().max(1.0)),
                        ),
                        _ => (None, None),
                    }
                }
                _ => (None, None),
            }
        } else {
            (None, None)
        };
        let fmt = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{x:.3}"));
        println!(
            "  {n:>6} {:>14.3} {:>14} {:>10}  {}",
            best * 1e3,
            fmt(scipy_ms),
            scipy_ms.map_or("-".to_owned(), |s| format!("{:.2}x", best * 1e3 / s)),
            agree.map_or("-", |a| if a { "yes" } else { "NO" })
        );
    }
    if !scipy {
        println!(
            "  (SciPy not found in target/pyenv: run `bash scripts/bench` to install it and compare)"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
