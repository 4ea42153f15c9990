//! `gcs slam …`: tools on trajectories and pose graphs.

use std::path::PathBuf;

use anyhow::bail;
use clap::{Args, Subcommand, ValueEnum};
use serde_json::json;
use slam::eval::{Alignment, Delta, ate, rpe};
use slam::trajectory::read_tum;

/// `gcs slam` subcommands.
#[derive(Subcommand, Debug)]
pub enum SlamCommand {
    /// Optimise a pose graph (g2o) and write every optimised vertex.
    Optimize(OptimizeArgs),
    /// Absolute and relative trajectory error of an estimate against ground truth (TUM rules).
    Eval(EvalArgs),
    /// Run the SLAM (front end and back end) on recorded RGB-D sequences and write the
    /// trajectories.
    Run(RunArgs),
}

/// Arguments of `gcs slam run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// A TUM RGB-D folder (associations.txt, rgb/, depth/) or a Redwood / ICL-NUIM folder
    /// (rgbd.match, color/, depth/, camera_primesense.json). Repeat it for several cameras:
    /// each is one robot of one graph, frames interleaved by time.
    #[arg(long, required = true)]
    dataset: Vec<PathBuf>,
    /// Write the camera trajectory here (TUM format, camera to map); with several datasets,
    /// robot k's goes to FILE-robotK (before the extension).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the final pose graph here (g2o).
    #[arg(long)]
    graph: Option<PathBuf>,
    /// Process at most this many frames.
    #[arg(long)]
    max_frames: Option<usize>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

/// Alignment on the command line.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum AlignArg {
    /// Rotation + translation (stereo / RGB-D).
    Se3,
    /// Rotation + translation + scale (monocular).
    Sim3,
}

/// Arguments of `gcs slam eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Ground truth, TUM format.
    #[arg(long)]
    gt: PathBuf,
    /// Estimate, TUM format.
    #[arg(long)]
    est: PathBuf,
    /// Alignment before measuring the absolute error.
    #[arg(long, value_enum, default_value = "se3")]
    align: AlignArg,
    /// Largest time difference for two poses to be paired, seconds (TUM: 0.02).
    #[arg(long, default_value_t = 0.02)]
    max_difference: f64,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Initial guess for `gcs slam optimize`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum InitArg {
    /// The file's vertices (or chained odometry when it has none).
    File,
    /// Chordal relaxation of the rotations, then translations (3D graphs).
    Chordal,
}

/// Arguments of `gcs slam optimize`.
#[derive(Args, Debug)]
pub struct OptimizeArgs {
    /// The graph, g2o format (VERTEX_SE2/EDGE_SE2 or VERTEX_SE3:QUAT/EDGE_SE3:QUAT).
    #[arg(long)]
    input: PathBuf,
    /// Where to write the optimised graph (g2o).
    #[arg(long)]
    output: PathBuf,
    /// Initial guess.
    #[arg(long, value_enum, default_value = "file")]
    init: InitArg,
    /// Gauss–Newton instead of Levenberg–Marquardt.
    #[arg(long)]
    gauss_newton: bool,
    /// Robust kernel against false loop closures: huber:DELTA or cauchy:C (on √χ² of an edge).
    #[arg(long, value_name = "KIND:WIDTH")]
    kernel: Option<String>,
    /// After converging, drop loop closures with χ² above this and optimise again
    /// (e.g. 16.27 = 99.9 % for 3 degrees of freedom, 22.46 for 6).
    #[arg(long, value_name = "CHI2")]
    reject_chi2: Option<f64>,
    /// At most this many iterations.
    #[arg(long, default_value_t = 100)]
    max_iterations: usize,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs a `gcs slam` command.
pub fn run(command: &SlamCommand) -> anyhow::Result<()> {
    match command {
        SlamCommand::Eval(args) => eval(args),
        SlamCommand::Optimize(args) => optimize(args),
        SlamCommand::Run(args) => run_dataset(args),
    }
}

/// Runs the SLAM on one or several recorded sequences (one robot each).
fn run_dataset(args: &RunArgs) -> anyhow::Result<()> {
    use slam::dataset::Dataset;
    use slam::system::{Frame, RobotSetup, Slam, SlamConfig, Tracking};
    use slam::trajectory::write_tum;
    let sets: Vec<Dataset> = args
        .dataset
        .iter()
        .map(|d| Dataset::open(d))
        .collect::<Result<_, _>>()?;
    // Every frame of every sequence, in time order: (stamp, robot, index).
    let mut order: Vec<(f64, usize, usize)> = sets
        .iter()
        .enumerate()
        .flat_map(|(k, ds)| {
            let n = args
                .max_frames
                .map_or(ds.frames.len(), |m| m.min(ds.frames.len()));
            (0..n).map(move |i| (ds.frames[i].stamp, k, i))
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let n = order.len();
    if n == 0 {
        bail!("no frames to process in {:?}", args.dataset);
    }
    // Hand-held cameras: no start, no vehicle sensors; each sequence maps in its own frame
    // until an inter-camera match anchors it.
    let setups = sets
        .iter()
        .map(|_| RobotSetup {
            body_from_camera: nalgebra::Isometry3::identity(),
            start: None,
        })
        .collect();
    let mut system = Slam::new(
        SlamConfig {
            background: false,
            ..SlamConfig::default()
        },
        setups,
    );
    let started = std::time::Instant::now();
    let mut slam_s = 0.0;
    for (done, &(stamp, k, i)) in order.iter().enumerate() {
        let ds = &sets[k];
        let (grey, depth) = ds.load(i)?;
        let t = std::time::Instant::now();
        let report = system.process(Frame::images_only(
            k,
            stamp,
            grey,
            depth,
            ds.depth_scale,
            ds.camera,
        ))?;
        slam_s += t.elapsed().as_secs_f64();
        if let Tracking::Lost(why) = &report.tracking {
            tracing::warn!("camera {} frame {i}: tracking lost: {why}", k + 1);
        }
        if !args.json && ((done + 1) % 50 == 0 || done + 1 == n) {
            let s = system.stats();
            eprintln!(
                "[{}/{n}] {} keyframes, {} loop closures, {} merges",
                done + 1,
                s.keyframes,
                s.loop_closures,
                s.merges
            );
        }
    }
    system.finish();
    let stats = system.stats();
    let mut robots = vec![];
    for (k, ds) in sets.iter().enumerate() {
        let trajectory = system.trajectory(k);
        let estimate = system.estimate(k).expect("robot set up");
        if let Some(out) = &args.out {
            let path = if sets.len() == 1 {
                out.clone()
            } else {
                robot_path(out, k + 1)
            };
            write_tum(&path, &trajectory)?;
        }
        let ate = ds
            .ground_truth
            .as_ref()
            .and_then(|gt| ate(gt, &trajectory, Alignment::Se3, 0.02));
        robots.push(json!({
            "dataset": ds.dir.display().to_string(),
            "frames": estimate.frames,
            "tracked": trajectory.len(),
            "lost": estimate.lost_frames,
            "keyframes": estimate.keyframes,
            "in_map": estimate.in_map,
            "ate_rmse_m": ate.map(|a| a.rmse_m),
            "ate_pairs": ate.map(|a| a.pairs),
        }));
    }
    if let Some(g) = &args.graph {
        slam::posegraph::write_g2o(g, &slam::posegraph::AnyGraph::Se3(system.graph()))?;
    }
    let per_frame_ms = slam_s / n as f64 * 1e3;
    let fps = n as f64 / started.elapsed().as_secs_f64();
    if args.json {
        println!(
            "{}",
            json!({
                "frames": n,
                "slam_ms_per_frame": per_frame_ms,
                "frames_per_second": fps,
                "keyframes": stats.keyframes,
                "loop_closures": stats.loop_closures,
                "rejected_loop_closures": stats.rejected_loop_closures,
                "merges": stats.merges,
                "robots": robots,
            })
        );
    } else {
        println!(
            "{n} frames: {} keyframes, {} loop closures, {} merges; SLAM {per_frame_ms:.1} ms/frame, {fps:.1} frames/s with image loading",
            stats.keyframes, stats.loop_closures, stats.merges
        );
        for (k, r) in robots.iter().enumerate() {
            println!(
                "camera {}: {} of {} frames tracked, {} keyframes{}; {}",
                k + 1,
                r["tracked"],
                r["frames"],
                r["keyframes"],
                if r["in_map"] == true {
                    ""
                } else {
                    " (not anchored in the map)"
                },
                match r["ate_rmse_m"].as_f64() {
                    Some(a) => format!(
                        "ATE RMSE {a:.4} m over {} poses (SE(3) alignment, against the folder's ground truth)",
                        r["ate_pairs"]
                    ),
                    None => "no ground truth to compare with".into(),
                }
            );
        }
    }
    Ok(())
}

/// `traj.txt` → `traj-robot2.txt`.
fn robot_path(path: &std::path::Path, k: usize) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(|| "trajectory".into(), |s| s.to_string_lossy().into_owned());
    let name = match path.extension() {
        Some(e) => format!("{stem}-robot{k}.{}", e.to_string_lossy()),
        None => format!("{stem}-robot{k}"),
    };
    path.with_file_name(name)
}

fn optimize(args: &OptimizeArgs) -> anyhow::Result<()> {
    use slam::optimize::{Kernel, Options, chordal_init, optimize};
    use slam::posegraph::{AnyGraph, read_g2o, se_sync_objective, write_g2o};
    let kernel = match args.kernel.as_deref() {
        None => Kernel::None,
        Some(k) => {
            let parsed = k.split_once(':').and_then(|(kind, w)| {
                let w: f64 = w.parse().ok().filter(|w: &f64| w.is_finite() && *w > 0.0)?;
                match kind {
                    "huber" => Some(Kernel::Huber(w)),
                    "cauchy" => Some(Kernel::Cauchy(w)),
                    _ => None,
                }
            });
            parsed.ok_or_else(|| anyhow::anyhow!("--kernel {k:?}: expected huber:DELTA or cauchy:C with a positive width, e.g. cauchy:1"))?
        }
    };
    if args
        .reject_chi2
        .is_some_and(|c| !(c.is_finite() && c > 0.0))
    {
        bail!("--reject-chi2 must be a positive number");
    }
    let mut graph = read_g2o(&args.input)?;
    let options = Options {
        kernel,
        outlier_chi2: args.reject_chi2,
        gauss_newton: args.gauss_newton,
        max_iterations: args.max_iterations,
        ..Options::default()
    };
    let (vertices, edges) = match &graph {
        AnyGraph::Se2(g) => (g.poses.len(), g.edges.len()),
        AnyGraph::Se3(g) => (g.poses.len(), g.edges.len()),
    };
    let init_start = std::time::Instant::now();
    match (&mut graph, args.init) {
        (_, InitArg::File) => {}
        (AnyGraph::Se3(g), InitArg::Chordal) => chordal_init(g)?,
        (AnyGraph::Se2(_), InitArg::Chordal) => {
            bail!("--init chordal is implemented for 3D graphs only; use --init file")
        }
    }
    let init_s = init_start.elapsed().as_secs_f64();
    let report = match &mut graph {
        AnyGraph::Se2(g) => optimize(g, &options)?,
        AnyGraph::Se3(g) => optimize(g, &options)?,
    };
    write_g2o(&args.output, &graph)?;
    let f = se_sync_objective(&graph);
    let time_s = report.time_s + init_s;
    if args.json {
        println!(
            "{}",
            json!({
                "initial_cost": report.initial_cost,
                "final_cost": report.final_cost,
                "iterations": report.iterations,
                "time_s": time_s,
                "se_sync_objective": f,
                "rejected_edges": report.rejected_edges,
                "vertices": vertices,
                "edges": edges,
            })
        );
    } else {
        println!("{vertices} vertices, {edges} edges");
        println!("initial_cost  {:.6}", report.initial_cost);
        println!(
            "final_cost    {:.6}   ({}; SE-Sync objective F = {f:.6})",
            report.final_cost,
            if matches!(kernel, Kernel::None) {
                "χ²"
            } else {
                "Σ ρ(χ²) with the kernel"
            }
        );
        println!("iterations    {}", report.iterations);
        if report.rejected_edges > 0 {
            println!("rejected      {} loop closures", report.rejected_edges);
        }
        println!("time_s        {time_s:.3}");
        println!("wrote {}", args.output.display());
    }
    Ok(())
}

fn eval(args: &EvalArgs) -> anyhow::Result<()> {
    if !(args.max_difference.is_finite() && args.max_difference > 0.0) {
        bail!("--max-difference must be more than zero seconds");
    }
    let gt = read_tum(&args.gt)?;
    let est = read_tum(&args.est)?;
    let alignment = match args.align {
        AlignArg::Se3 => Alignment::Se3,
        AlignArg::Sim3 => Alignment::Sim3,
    };
    let Some(a) = ate(&gt, &est, alignment, args.max_difference) else {
        bail!(
            "fewer than 3 poses of {} are within {} s of a pose of {}: are the timestamps in the same clock?",
            args.est.display(),
            args.max_difference,
            args.gt.display()
        );
    };
    let per_s = rpe(&gt, &est, Delta::Seconds(1.0), args.max_difference);
    let per_frame = rpe(&gt, &est, Delta::Frames(1), args.max_difference);
    if args.json {
        println!(
            "{}",
            json!({
                "ate_rmse_m": a.rmse_m,
                "ate_mean_m": a.mean_m,
                "ate_max_m": a.max_m,
                "scale": a.scale,
                "rpe_trans_m_per_s": per_s.map(|r| r.trans_rmse_m),
                "rpe_rot_deg_per_s": per_s.map(|r| r.rot_rmse_deg),
                "rpe_trans_m_per_frame": per_frame.map(|r| r.trans_rmse_m),
                "rpe_rot_deg_per_frame": per_frame.map(|r| r.rot_rmse_deg),
                "pairs": a.pairs,
            })
        );
    } else {
        println!("pairs                 {}", a.pairs);
        println!(
            "ATE RMSE              {:.4} m (mean {:.4} m, max {:.4} m{})",
            a.rmse_m,
            a.mean_m,
            a.max_m,
            if matches!(alignment, Alignment::Sim3) {
                format!(", scale {:.4}", a.scale)
            } else {
                String::new()
            }
        );
        match per_s {
            Some(r) => println!(
                "RPE per second        {:.4} m/s, {:.3} °/s ({} intervals)",
                r.trans_rmse_m, r.rot_rmse_deg, r.pairs
            ),
            None => println!("RPE per second        - (the trajectories are shorter than 1 s)"),
        }
        if let Some(r) = per_frame {
            println!(
                "RPE per frame         {:.4} m, {:.3} °",
                r.trans_rmse_m, r.rot_rmse_deg
            );
        }
    }
    Ok(())
}
