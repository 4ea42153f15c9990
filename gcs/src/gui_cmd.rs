//! `gcs gui`: the operator's window. With no arguments it starts the built-in simulated fleet
//! (two drones in the default world) and waits for the operator's start; `--config FLEET.toml`
//! flies real or external vehicles instead.

use std::path::PathBuf;
use std::sync::mpsc::Sender;

use anyhow::{anyhow, bail};
use clap::Args;
use gcs::gui::{self, Station, WindowOptions};
use gcs::runtime::Operator;

use crate::explore::{self, ExploreArgs, SimArgs};
use crate::fly::{self, FlyArgs};

/// Arguments of `gcs gui`.
#[derive(Args, Debug, Clone)]
pub struct GuiArgs {
    /// Real or external vehicles listed in a fleet file (as `gcs fly`) instead of the simulated
    /// fleet.
    #[arg(long, conflicts_with_all = ["world", "drones", "link", "speed", "seed", "poses", "strategy"])]
    pub config: Option<PathBuf>,
    /// The simulated fleet.
    #[command(flatten)]
    pub sim: SimArgs,
    /// Give up (and land) this many seconds after the start.
    #[arg(long, default_value_t = 900.0)]
    pub timeout: f64,
    /// Start the mission at once instead of waiting for the operator's start.
    #[arg(long)]
    pub start: bool,
    /// Where to write the map, trajectories, log and summary when the window closes.
    #[arg(long, default_value = "gui-out")]
    pub out: PathBuf,
    /// The mission log.
    #[command(flatten)]
    pub log: LogArgs,
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
                // In the window the operator takes a drone off again after a swap.
                rejoin_after_battery_swap: false,
                log: args.log.clone(),
            },
            Some(window),
        ),
        None => explore::run_with(
            &ExploreArgs {
                sim: args.sim.clone(),
                timeout: args.timeout,
                out: args.out.clone(),
                json: false,
                log: args.log.clone(),
                kill_link: None,
                faults: vec![],
                pose_trace: None,
                gui: true,
                window: args.window.clone(),
            },
            Some(window),
        ),
    }
}

/// What a mission records (`gcs explore`, `gcs fly`, `gcs gui`).
#[derive(Args, Debug, Clone)]
pub struct LogArgs {
    /// Do not record the MCAP log and `.tlog`s.
    #[arg(long)]
    pub no_log: bool,
    /// Record camera frames at most this many times a second per drone (0: none); every frame
    /// by default. Colour and depth at 10 Hz are about 1 MB per drone per second; replay reruns
    /// the SLAM only on the frames recorded.
    #[arg(long, value_name = "HZ")]
    pub log_camera_hz: Option<f64>,
}

impl LogArgs {
    /// Refuses impossible values (before anything starts).
    pub fn validate(&self) -> anyhow::Result<()> {
        if let Some(hz) = self.log_camera_hz
            && !(hz.is_finite() && hz >= 0.0)
        {
            bail!("--log-camera-hz {hz} must be 0 (no frames) or more");
        }
        Ok(())
    }
}

/// How a mission is shown in the window.
pub struct Window {
    /// Wait for the operator's start (`gcs gui`), or start at once (`gcs explore --gui`).
    pub wait_for_start: bool,
    /// Closing the window lands every drone and ends the session (`gcs gui`); otherwise the run
    /// goes on headless (`gcs explore --gui`).
    pub close_ends_session: bool,
    /// Scripted use of the window.
    pub options: WindowOptions,
}

/// Shows `station` in the window on this thread (windows live on the main thread) while
/// `mission` follows the mission to its end on another; returns when both are done.
pub fn beside_window(
    station: Station,
    window: Window,
    commander: Sender<Operator>,
    mission: impl FnOnce() -> anyhow::Result<()> + Send + 'static,
) -> anyhow::Result<()> {
    let worker = std::thread::Builder::new()
        .name("mission watch".into())
        .spawn(mission)?;
    let shown = gui::run_window(station, window.options);
    if window.close_ends_session || shown.is_err() {
        // Everything lands before the session ends.
        let _ = commander.send(Operator::Shutdown);
    } else {
        eprintln!("window closed; the run goes on headless");
    }
    let result = worker
        .join()
        .map_err(|_| anyhow!("the mission thread panicked"))?;
    shown.map_err(|e| {
        anyhow!(
            "cannot show the window: {e} (is there a display? Without one, run under `xvfb-run`)"
        )
    })?;
    result
}
