//! `gcs gui`: the operator's window. With no arguments it starts the built-in simulated fleet
//! (two drones in the default world) and waits for the operator's start; `--config FLEET.toml`
//! flies real or external vehicles instead.

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;
use gcs::fleet::LinkKind;
use gcs::gui::WindowOptions;

use crate::explore::{self, ExploreArgs, PoseSource, StrategyArg, Window};
use crate::fly::{self, FlyArgs};

/// Arguments of `gcs gui`.
#[derive(Args, Debug, Clone)]
pub struct GuiArgs {
    /// Real or external vehicles listed in a fleet file (as `gcs fly`) instead of the simulated
    /// fleet.
    #[arg(long, conflicts_with_all = ["world", "drones", "link", "speed", "seed", "poses", "strategy"])]
    pub config: Option<PathBuf>,
    /// A built-in world (apartment) or a world file (.txt, map_server .yaml, HouseExpo .json).
    #[arg(long, default_value = sitl::world::DEFAULT_WORLD)]
    pub world: String,
    /// Number of simulated drones (1–8).
    #[arg(long, default_value_t = 2)]
    pub drones: usize,
    /// How the station talks to the simulated drones.
    #[arg(long, value_enum, default_value_t = LinkKind::Mavlink)]
    pub link: LinkKind,
    /// How frontiers are assigned.
    #[arg(long, value_enum, default_value_t = StrategyArg::Hungarian)]
    pub strategy: StrategyArg,
    /// Simulated seconds per real second (0.1–20).
    #[arg(long, default_value_t = 2.0)]
    pub speed: f64,
    /// Seed of the simulator's noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where the drones' poses come from.
    #[arg(long, value_enum, default_value_t = PoseSource::Slam)]
    pub poses: PoseSource,
    /// Give up (and land) this many seconds after the start.
    #[arg(long, default_value_t = 900.0)]
    pub timeout: f64,
    /// Start the mission at once instead of waiting for the operator's start.
    #[arg(long)]
    pub start: bool,
    /// Where to write the map, trajectories, log and summary when the window closes.
    #[arg(long, default_value = "gui-out")]
    pub out: PathBuf,
    /// Do not record the MCAP log and `.tlog`s.
    #[arg(long)]
    pub no_log: bool,
    /// Scripted use of the window.
    #[command(flatten)]
    pub window: WindowArgs,
}

/// Scripted use of the window: screenshots, automatic close, frame-time statistics.
#[derive(Args, Debug, Clone)]
pub struct WindowArgs {
    /// Save a PNG of the window once the mission has run `--screenshot-at` seconds.
    #[arg(long, value_name = "FILE.png")]
    pub screenshot: Option<PathBuf>,
    /// Mission seconds before the screenshot.
    #[arg(long, default_value_t = 30.0, value_name = "S")]
    pub screenshot_at: f64,
    /// Close the window once the mission has run this many seconds (after the screenshot).
    #[arg(long, value_name = "S")]
    pub quit_after: Option<f64>,
    /// Repaint continuously and print frame-time statistics when the window closes.
    #[arg(long)]
    pub frame_stats: bool,
}

impl WindowArgs {
    /// The window's options.
    pub fn options(&self) -> WindowOptions {
        WindowOptions {
            screenshot: self.screenshot.clone(),
            screenshot_at: self.screenshot_at,
            quit_after: self.quit_after,
            frame_stats: self.frame_stats,
            size: None,
        }
    }

    /// Refuses impossible values.
    pub fn validate(&self) -> anyhow::Result<()> {
        for (name, v) in [
            ("--screenshot-at", Some(self.screenshot_at)),
            ("--quit-after", self.quit_after),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0)
            {
                bail!("{name} {v} must be a number of seconds, 0 or more");
            }
        }
        if let Some(p) = &self.screenshot
            && p.extension().and_then(|e| e.to_str()) != Some("png")
        {
            bail!(
                "--screenshot {}: the screenshot is written as PNG; name it FILE.png",
                p.display()
            );
        }
        Ok(())
    }
}

/// Runs `gcs gui`.
pub fn run(args: &GuiArgs) -> anyhow::Result<()> {
    args.window.validate()?;
    let window = Window {
        wait_for_start: !args.start,
        close_ends_session: true,
        options: args.window.options(),
    };
    match &args.config {
        Some(config) => fly::run_with(
            &FlyArgs {
                config: config.clone(),
                timeout: args.timeout,
                out: args.out.clone(),
                json: false,
                no_log: args.no_log,
            },
            Some(window),
        ),
        None => explore::run_with(
            &ExploreArgs {
                world: args.world.clone(),
                drones: args.drones,
                link: args.link,
                strategy: args.strategy,
                speed: args.speed,
                seed: args.seed,
                timeout: args.timeout,
                out: args.out.clone(),
                json: false,
                poses: args.poses,
                no_log: args.no_log,
                kill_link: None,
                gui: true,
                window: args.window.clone(),
            },
            Some(window),
        ),
    }
}
