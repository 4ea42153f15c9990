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
    /// Absolute and relative trajectory error of an estimate against ground truth (TUM rules).
    Eval(EvalArgs),
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

/// Runs a `gcs slam` command.
pub fn run(command: &SlamCommand) -> anyhow::Result<()> {
    match command {
        SlamCommand::Eval(args) => eval(args),
    }
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
