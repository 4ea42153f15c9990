//! The operator's window (`gcs gui`): the fleet, the live map, telemetry plots and every command,
//! on top of a running [`Runtime`](crate::runtime::Runtime).
//!
//! The window never waits on the mission: it reads the runtime's latest [`Snapshot`] (an `Arc`
//! swapped under a mutex held for a pointer copy) and sends [`Operator`] commands down a channel.
//! SLAM, planning and I/O run on their own threads, so drawing stays at interactive rates
//! whatever they do.
//!
//! Layout: mission bar on top (state, time, coverage, start / pause / resume and the always
//! visible LAND ALL), the fleet on the left (one card per drone with its controls), the map in
//! the middle, plots and messages at the bottom. Anything that can crash a drone (starting
//! motors, changing its goal height, disarming) asks for confirmation; landing never does.

mod fleet_panel;
mod history;
mod map_view;

pub use map_view::{FREE, OCCUPIED, UNKNOWN, drone_colour};

use std::path::PathBuf;
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use egui::{Color32, RichText};
use sitl::World;

use crate::runtime::{MissionState, Operator, Runtime, Snapshot};
use fleet_panel::FleetPanel;
use history::History;
use map_view::MapView;

/// What the window shows and commands: a running mission.
#[derive(Clone)]
pub struct Station {
    /// The runtime's latest snapshot.
    pub snapshots: Arc<Mutex<Arc<Snapshot>>>,
    /// Where operator commands go.
    pub commands: Sender<Operator>,
    /// The simulated building, when flying in SITL (its walls are drawn over the map, and the
    /// coverage is measured against it).
    pub world: Option<Arc<World>>,
    /// A line for the title bar ("2 drones in SITL 'apartment'").
    pub title: String,
}

impl Station {
    /// The window onto `runtime`.
    pub fn of(runtime: &Runtime, world: Option<Arc<World>>, title: impl Into<String>) -> Self {
        Self {
            snapshots: runtime.snapshots(),
            commands: runtime.commander(),
            world,
            title: title.into(),
        }
    }

    fn snapshot(&self) -> Arc<Snapshot> {
        self.snapshots
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

/// A command waiting for the operator's confirmation.
struct Confirm {
    question: String,
    command: Operator,
}

/// Scripted use of the real window: a screenshot, an automatic close, frame-time statistics.
#[derive(Debug, Clone, Default)]
pub struct WindowOptions {
    /// Save a PNG of the window here once the mission has run `screenshot_at` seconds.
    pub screenshot: Option<PathBuf>,
    /// Mission seconds before the screenshot.
    pub screenshot_at: f64,
    /// Close the window once the mission has run this long (seconds) and the screenshot, if
    /// any, is written.
    pub quit_after: Option<f64>,
    /// Repaint continuously and print frame-time statistics when the window closes.
    pub frame_stats: bool,
}

/// Frame times, for `--frame-stats`.
#[derive(Debug, Default)]
struct FrameStats {
    /// Time spent building the UI, milliseconds.
    build_ms: Vec<f64>,
    /// Time from one frame to the next (build, tessellation, painting, presenting), ms.
    interval_ms: Vec<f64>,
    last: Option<Instant>,
}

impl FrameStats {
    /// Takes a frame whose UI building began at `started`.
    fn record(&mut self, started: Instant) {
        let now = Instant::now();
        self.build_ms
            .push(now.duration_since(started).as_secs_f64() * 1e3);
        if let Some(last) = self.last.replace(now) {
            self.interval_ms
                .push(now.duration_since(last).as_secs_f64() * 1e3);
        }
    }

    fn report(&self) -> String {
        fn describe(v: &[f64]) -> String {
            if v.is_empty() {
                return "-".into();
            }
            let mut s = v.to_vec();
            s.sort_by(f64::total_cmp);
            let q = |f: f64| s[((s.len() - 1) as f64 * f).round() as usize];
            format!(
                "median {:.2} ms, p95 {:.2} ms, max {:.2} ms",
                q(0.5),
                q(0.95),
                q(1.0)
            )
        }
        format!(
            "{} frames; building the UI: {}; frame to frame: {}",
            self.interval_ms.len(),
            describe(&self.build_ms),
            describe(&self.interval_ms)
        )
    }
}

/// The operator's window.
pub struct GcsApp {
    station: Station,
    map: MapView,
    fleet: FleetPanel,
    history: History,
    confirm: Option<Confirm>,
    /// Which drone the plots show.
    plotted: usize,
    /// A mission start for one drone only (`None`: every drone).
    solo: Option<usize>,
    options: WindowOptions,
    screenshot: Shot,
    stats: FrameStats,
    /// Coverage of the world's reachable free space, computed when the grid changes.
    coverage: Coverage,
}

/// Where the scripted screenshot is.
#[derive(Default)]
enum Shot {
    #[default]
    Waiting,
    Requested(Arc<Mutex<Option<Result<(), String>>>>),
    Done,
}

#[derive(Default)]
struct Coverage {
    reachable: Option<Vec<(i64, i64)>>,
    grid: Option<Arc<nav::grid::Grid>>,
    value: Option<f64>,
}

impl GcsApp {
    /// A window onto `station`.
    pub fn new(station: Station) -> Self {
        Self::with_options(station, WindowOptions::default())
    }

    /// A window onto `station`, scripted by `options`.
    pub fn with_options(station: Station, options: WindowOptions) -> Self {
        let coverage = Coverage {
            reachable: station
                .world
                .as_deref()
                .map(|w| crate::evaluate::reachable_free(w, sitl::VehicleParams::default().radius)),
            ..Coverage::default()
        };
        Self {
            map: MapView::new(station.world.clone()),
            station,
            fleet: FleetPanel::default(),
            history: History::default(),
            confirm: None,
            plotted: 0,
            solo: None,
            options,
            screenshot: Shot::Waiting,
            stats: FrameStats::default(),
            coverage,
        }
    }

    /// Draws the whole window into `ui` (the root of the viewport).
    pub fn show(&mut self, ui: &mut egui::Ui) {
        let started = Instant::now();
        let snapshot = self.station.snapshot();
        self.history.record(&snapshot);
        self.fleet.observe(&snapshot);
        self.update_coverage(&snapshot);
        let mut asked: Vec<Request> = vec![];

        egui::Panel::top("mission").show(ui, |ui| {
            self.mission_bar(ui, &snapshot, &mut asked);
        });
        egui::Panel::left("fleet")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| {
                    self.fleet.show(ui, &snapshot, &mut asked);
                });
            });
        egui::Panel::bottom("telemetry")
            .resizable(true)
            .default_size(210.0)
            .show(ui, |ui| {
                self.telemetry(ui, &snapshot);
            });
        egui::CentralPanel::default().show(ui, |ui| {
            self.map.show(ui, &snapshot);
        });

        for request in asked {
            match request {
                Request::Now(command) => self.send(command),
                Request::Confirm { question, command } => {
                    self.confirm = Some(Confirm { question, command });
                }
            }
        }
        self.confirmation(ui.ctx());
        self.script(ui.ctx(), &snapshot);

        if self.options.frame_stats {
            self.stats.record(started);
            ui.ctx().request_repaint();
        } else {
            // Snapshots come at the control rate (10 Hz).
            ui.ctx().request_repaint_after(Duration::from_millis(100));
        }
    }

    fn send(&self, command: Operator) {
        if self.station.commands.send(command.clone()).is_err() {
            tracing::warn!("{command:?} not sent: the mission has ended");
        }
    }

    fn update_coverage(&mut self, snapshot: &Snapshot) {
        let (Some(world), Some(reachable), Some(grid)) = (
            self.station.world.as_deref(),
            self.coverage.reachable.as_deref(),
            snapshot.grid.as_ref(),
        ) else {
            return;
        };
        if self
            .coverage
            .grid
            .as_ref()
            .is_some_and(|g| Arc::ptr_eq(g, grid))
        {
            return;
        }
        self.coverage.value = Some(crate::evaluate::coverage(reachable, world, grid));
        self.coverage.grid = Some(grid.clone());
    }

    fn mission_bar(&mut self, ui: &mut egui::Ui, s: &Snapshot, asked: &mut Vec<Request>) {
        ui.horizontal(|ui| {
            ui.heading("gcs");
            ui.label(&self.station.title);
            ui.separator();
            let colour = match s.state {
                MissionState::Exploring => Color32::from_rgb(40, 160, 70),
                MissionState::Paused => Color32::from_rgb(220, 150, 0),
                MissionState::Finishing(_) => Color32::from_rgb(220, 120, 0),
                MissionState::Waiting | MissionState::Done(_) => ui.visuals().text_color(),
            };
            let state = match s.state {
                MissionState::Done(o) | MissionState::Finishing(o) => {
                    format!("{} ({})", s.state.name(), o.name())
                }
                _ => s.state.name().to_owned(),
            };
            ui.label(RichText::new(state).strong().color(colour));
            ui.label(format!("{:.0} s", s.elapsed));
            if let Some(c) = self.coverage.value {
                ui.label(format!("coverage {:.0} %", c * 100.0));
            }
            ui.label(format!(
                "SLAM: {} keyframes, {} loops, {:.0} ms/frame",
                s.slam.stats.keyframes, s.slam.stats.loop_closures, s.slam.ms_per_frame
            ));
            let lost: Vec<&str> = s
                .drones
                .iter()
                .filter(|d| d.link.state == link::LinkState::Lost)
                .map(|d| d.name.as_str())
                .collect();
            if !lost.is_empty() {
                ui.label(
                    RichText::new(format!("LINK LOST: {}", lost.join(", ")))
                        .strong()
                        .color(Color32::WHITE)
                        .background_color(Color32::from_rgb(200, 30, 30)),
                );
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                // Always here, always one click.
                let land = egui::Button::new(
                    RichText::new("LAND ALL")
                        .strong()
                        .size(18.0)
                        .color(Color32::WHITE),
                )
                .fill(Color32::from_rgb(200, 30, 30));
                if ui.add(land).clicked() {
                    asked.push(Request::Now(Operator::LandAll));
                }
                ui.separator();
                match s.state {
                    MissionState::Exploring => {
                        if ui.button("Pause").clicked() {
                            asked.push(Request::Now(Operator::Pause));
                        }
                    }
                    MissionState::Paused => {
                        if ui.button("Resume").clicked() {
                            asked.push(Request::Now(Operator::Resume));
                        }
                    }
                    MissionState::Waiting | MissionState::Done(_) => {
                        if ui.button("Start mission").clicked() {
                            asked.push(self.start_request(s));
                        }
                        let names: Vec<String> = s.drones.iter().map(|d| d.name.clone()).collect();
                        let shown = self
                            .solo
                            .and_then(|k| names.get(k).cloned())
                            .unwrap_or_else(|| "co-op: every drone".into());
                        egui::ComboBox::from_id_salt("who")
                            .selected_text(shown)
                            .show_ui(ui, |ui| {
                                ui.selectable_value(&mut self.solo, None, "co-op: every drone");
                                for (k, n) in names.iter().enumerate() {
                                    ui.selectable_value(
                                        &mut self.solo,
                                        Some(k),
                                        format!("{n} alone"),
                                    );
                                }
                            })
                            .response
                            .on_hover_text("Who flies the mission");
                    }
                    MissionState::Finishing(_) => {}
                }
            });
        });
    }

    fn start_request(&self, s: &Snapshot) -> Request {
        match self.solo.filter(|&k| k < s.drones.len()) {
            Some(k) => Request::Confirm {
                question: format!(
                    "Start {} alone? It arms, starts its motors and takes off.",
                    s.drones[k].name
                ),
                command: Operator::Drone(k, crate::runtime::DroneCommand::TakeOff),
            },
            None => Request::Confirm {
                question: format!(
                    "Start the mission? All {} drones arm, start their motors and take off.",
                    s.drones.len()
                ),
                command: Operator::Start,
            },
        }
    }

    fn telemetry(&mut self, ui: &mut egui::Ui, s: &Snapshot) {
        ui.horizontal(|ui| {
            let label = ui.label("Plots of");
            let shown = s
                .drones
                .get(self.plotted)
                .map_or("-".to_owned(), |d| d.name.clone());
            egui::ComboBox::from_id_salt("plotted")
                .selected_text(shown)
                .show_ui(ui, |ui| {
                    for d in &s.drones {
                        ui.selectable_value(&mut self.plotted, d.id, &d.name);
                    }
                })
                .response
                .labelled_by(label.id);
        });
        let width = ui.available_width();
        ui.horizontal_top(|ui| {
            let plots_width = (width * 0.68).max(200.0);
            ui.allocate_ui(egui::vec2(plots_width, ui.available_height()), |ui| {
                self.history.show(ui, self.plotted);
            });
            ui.separator();
            ui.vertical(|ui| {
                ui.strong("Messages");
                egui::ScrollArea::vertical()
                    .stick_to_bottom(true)
                    .auto_shrink([false, false])
                    .show(ui, |ui| {
                        for (t, text) in &s.messages {
                            ui.label(format!("{t:7.1} s  {text}"));
                        }
                    });
            });
        });
    }

    fn confirmation(&mut self, ctx: &egui::Context) {
        let Some(c) = &self.confirm else {
            return;
        };
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("confirm")).show(ctx, |ui| {
            ui.set_max_width(360.0);
            ui.label(RichText::new(&c.question).strong());
            ui.add_space(8.0);
            ui.horizontal(|ui| {
                if ui.button("Confirm").clicked() {
                    answer = Some(true);
                }
                if ui.button("Cancel").clicked() || ui.input(|i| i.key_pressed(egui::Key::Escape)) {
                    answer = Some(false);
                }
            });
        });
        match answer {
            Some(true) => {
                if let Some(c) = self.confirm.take() {
                    self.send(c.command);
                }
            }
            Some(false) => self.confirm = None,
            None => {}
        }
    }

    /// The scripted screenshot and close.
    fn script(&mut self, ctx: &egui::Context, s: &Snapshot) {
        let started = !matches!(s.state, MissionState::Waiting);
        if let Some(path) = &self.options.screenshot {
            match &self.screenshot {
                Shot::Waiting if started && s.elapsed >= self.options.screenshot_at => {
                    let result = Arc::new(Mutex::new(None));
                    let (slot, path, repaint) = (result.clone(), path.clone(), ctx.clone());
                    ctx.request_screenshot(move |image| {
                        let r = save_png(&path, &image);
                        *slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(r);
                        repaint.request_repaint();
                    });
                    self.screenshot = Shot::Requested(result);
                }
                Shot::Requested(result) => {
                    let r = result.lock().unwrap_or_else(PoisonError::into_inner).take();
                    match r {
                        Some(Ok(())) => {
                            eprintln!("gui: screenshot written to {}", path.display());
                            self.screenshot = Shot::Done;
                        }
                        Some(Err(e)) => {
                            eprintln!("gui: {e}");
                            self.screenshot = Shot::Done;
                        }
                        None => {}
                    }
                }
                _ => {}
            }
        }
        let shot_done = self.options.screenshot.is_none() || matches!(self.screenshot, Shot::Done);
        if let Some(limit) = self.options.quit_after
            && started
            && s.elapsed >= limit
            && shot_done
        {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }
}

/// What a click asks for.
enum Request {
    /// Send at once.
    Now(Operator),
    /// Ask first.
    Confirm {
        /// The question.
        question: String,
        /// Sent on "Confirm".
        command: Operator,
    },
}

fn save_png(path: &std::path::Path, image: &egui::ColorImage) -> Result<(), String> {
    let [w, h] = image.size;
    let bytes: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
    let picture = image::RgbaImage::from_raw(w as u32, h as u32, bytes)
        .ok_or_else(|| format!("screenshot of {w}×{h} pixels has the wrong size"))?;
    picture
        .save(path)
        .map_err(|e| format!("cannot write the screenshot {}: {e}", path.display()))
}

impl eframe::App for GcsApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }

    fn on_exit(&mut self, _gl: Option<&eframe::glow::Context>) {
        if self.options.frame_stats {
            eprintln!("gui: {}", self.stats.report());
        }
    }
}

/// Opens the window on `station` and returns when it is closed (printing the frame-time
/// statistics then, if asked).
pub fn run_window(station: Station, options: WindowOptions) -> Result<(), eframe::Error> {
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title(format!("gcs — {}", station.title))
            .with_inner_size([1400.0, 860.0]),
        ..eframe::NativeOptions::default()
    };
    eframe::run_native(
        "gcs",
        native,
        Box::new(move |_cc| Ok(Box::new(GcsApp::with_options(station, options)))),
    )
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc::{Receiver, channel};
    use std::time::Duration;

    use egui_kittest::Harness;
    use egui_kittest::kittest::Queryable;
    use link::{Battery, LinkState, LinkStatus, Telemetry};
    use nav::grid::{Cell, Grid};
    use slam::system::RobotState;

    use super::*;
    use crate::runtime::drone::Phase;
    use crate::runtime::trail::Trail;
    use crate::runtime::{DroneCommand, DroneView};

    fn drone(id: usize, phase: Phase, link: LinkState) -> DroneView {
        DroneView {
            id,
            name: format!("drone {}", id + 1),
            phase,
            left_mission: None,
            link: LinkStatus {
                state: link,
                last_message_age: Some(Duration::from_millis(if link == LinkState::Lost {
                    4200
                } else {
                    100
                })),
                transport_up: link != LinkState::Lost,
                connections: 1,
                frames_ok: 100,
                frames_bad: 0,
            },
            telemetry: Telemetry {
                height_m: Some(0.9),
                yaw_rad: Some(0.5),
                battery: Some(Battery {
                    voltage_v: 11.8 - id as f32 * 0.4,
                    remaining_pct: Some(76 - id as u8 * 30),
                }),
                armed: Some(phase.flying()),
                mode: Some("ALT_HOLD".into()),
                ..Telemetry::default()
            },
            battery_home_at: Some(38.4),
            battery_estimate_pct: None,
            pose: Some([1.0 + id as f64, 2.0, 0.9, 0.5]),
            pose_sigma: 0.05,
            slam: RobotState::Tracking,
            goal: Some([4.0, 3.0]),
            path: vec![[1.0, 2.0], [2.5, 2.5], [4.0, 3.0]],
            trajectory: Trail::from_points([[0.5, 2.0], [1.0, 2.0]]),
            setpoint: [1.2, 2.1],
            inliers: Some(120),
            height_goal: 0.9,
            yaw_goal: 0.5,
            sticks: None,
        }
    }

    fn snapshot(state: MissionState, drones: Vec<DroneView>) -> Snapshot {
        let mut grid = Grid::new(60, 40, 0.1, [0.0, 0.0], Cell::Free);
        grid.set((10, 10), Cell::Occupied);
        Snapshot {
            time: 42.0,
            elapsed: 40.0,
            state,
            drones,
            grid: Some(Arc::new(grid)),
            frontiers: vec![[4.0, 3.0]],
            slam: Arc::default(),
            messages: vec![(41.0, "drone 2: link lost".into())],
        }
    }

    /// A window onto a scripted snapshot; the commands it sends come out of the receiver.
    fn window(s: Snapshot) -> (Harness<'static, GcsApp>, Receiver<Operator>) {
        let (tx, rx) = channel();
        let station = Station {
            snapshots: Arc::new(Mutex::new(Arc::new(s))),
            commands: tx,
            world: None,
            title: "test fleet".into(),
        };
        let harness = Harness::builder()
            .with_size(egui::vec2(1400.0, 900.0))
            .build_ui_state(|ui, app: &mut GcsApp| app.show(ui), GcsApp::new(station));
        (harness, rx)
    }

    fn step(h: &mut Harness<'_, GcsApp>) {
        h.run_steps(3);
        h.check_accessibility();
    }

    #[test]
    fn panels_show_what_the_runtime_reports() {
        let mut d2 = drone(1, Phase::LinkLost, LinkState::Lost);
        d2.slam = RobotState::Lost;
        d2.pose = None;
        d2.left_mission = Some("link lost".into());
        d2.battery_home_at = None;
        let (mut h, _rx) = window(snapshot(
            MissionState::Exploring,
            vec![drone(0, Phase::Exploring, LinkState::Connected), d2],
        ));
        step(&mut h);
        // The mission: state (bar and drone 1), time, the lost link as a banner.
        assert_eq!(h.get_all_by_label("exploring").count(), 2);
        h.get_by_label("40 s");
        h.get_by_label("LINK LOST: drone 2");
        // Drone 1: link, mode, armed, battery with its voltage, SLAM, target.
        h.get_by_label("connected");
        h.get_by_label("last message 0.1 s ago");
        assert_eq!(h.get_all_by_label("mode ALT_HOLD").count(), 2);
        h.get_by_label("armed");
        h.get_by_label_contains("11.8 V  76 % · home at 38 %");
        h.get_by_label("tracking");
        h.get_by_label("σ 0.05 m");
        assert_eq!(h.get_all_by_label("target (4.0, 3.0) m").count(), 2);
        // Drone 2: the lost link with the age of its last message, lost tracking, no pose.
        assert_eq!(h.get_all_by_label("link lost").count(), 2, "phase and link");
        h.get_by_label("last message 4.2 s ago");
        h.get_by_label("lost");
        h.get_by_label("no pose");
        // Its link lost, nothing says when it turns home.
        h.get_by_label_contains("11.4 V  46 %");
        assert_eq!(h.get_all_by_label_contains("home at").count(), 1);
        // Why drone 2 left the mission; drone 1 has not.
        h.get_by_label("left the mission: link lost");
        assert_eq!(h.get_all_by_label_contains("left the mission").count(), 1);
        // Messages.
        h.get_by_label_contains("drone 2: link lost");
        // A drone over the shield over the shield, which reports only the voltage: the charge read off it.
        let mut d3 = drone(2, Phase::Exploring, LinkState::Connected);
        d3.telemetry.battery = Some(Battery {
            voltage_v: 11.2,
            remaining_pct: None,
        });
        d3.battery_estimate_pct = Some(41.6);
        let (mut h, _rx) = window(snapshot(MissionState::Exploring, vec![d3]));
        step(&mut h);
        h.get_by_label_contains("11.2 V  ≈42 % · home at 38 %");
    }

    #[test]
    fn land_all_is_one_click_in_every_state() {
        for state in [
            MissionState::Waiting,
            MissionState::Exploring,
            MissionState::Paused,
            MissionState::Finishing(crate::runtime::Outcome::TimedOut),
        ] {
            let (mut h, rx) = window(snapshot(
                state,
                vec![drone(0, Phase::Exploring, LinkState::Connected)],
            ));
            step(&mut h);
            h.get_by_label("LAND ALL").click();
            step(&mut h);
            assert_eq!(rx.try_recv().ok(), Some(Operator::LandAll), "{state:?}");
            assert!(h.query_by_label("Confirm").is_none(), "no question asked");
        }
    }

    #[test]
    fn mission_start_asks_first() {
        let (mut h, rx) = window(snapshot(
            MissionState::Waiting,
            vec![
                drone(0, Phase::Idle, LinkState::Connected),
                drone(1, Phase::Idle, LinkState::Connected),
            ],
        ));
        step(&mut h);
        h.get_by_label("Start mission").click();
        step(&mut h);
        assert!(rx.try_recv().is_err(), "nothing sent before the answer");
        h.get_by_label_contains("All 2 drones arm");
        h.get_by_label("Cancel").click();
        step(&mut h);
        assert!(rx.try_recv().is_err(), "cancelled");
        assert!(h.query_by_label("Confirm").is_none());
        h.get_by_label("Start mission").click();
        step(&mut h);
        h.get_by_label("Confirm").click();
        step(&mut h);
        assert_eq!(rx.try_recv().ok(), Some(Operator::Start));
        assert!(rx.try_recv().is_err(), "once");
    }

    #[test]
    fn pause_and_resume_follow_the_mission() {
        let (mut h, rx) = window(snapshot(
            MissionState::Exploring,
            vec![drone(0, Phase::Exploring, LinkState::Connected)],
        ));
        step(&mut h);
        assert!(h.query_by_label("Start mission").is_none());
        h.get_by_label("Pause").click();
        step(&mut h);
        assert_eq!(rx.try_recv().ok(), Some(Operator::Pause));
        let (mut h, rx) = window(snapshot(
            MissionState::Paused,
            vec![drone(0, Phase::Holding, LinkState::Connected)],
        ));
        step(&mut h);
        h.get_by_label("Resume").click();
        step(&mut h);
        assert_eq!(rx.try_recv().ok(), Some(Operator::Resume));
    }

    #[test]
    fn drone_controls_send_their_commands() {
        let (mut h, rx) = window(snapshot(
            MissionState::Exploring,
            vec![
                drone(0, Phase::Idle, LinkState::Connected),
                drone(1, Phase::Exploring, LinkState::Connected),
            ],
        ));
        step(&mut h);
        // Take off (drone 1 on the ground) asks first.
        let take_off = h.get_all_by_label("Take off").next();
        take_off.expect("drone 1's take-off button").click();
        step(&mut h);
        assert!(rx.try_recv().is_err());
        h.get_by_label_contains("Take off drone 1?");
        h.get_by_label("Confirm").click();
        step(&mut h);
        assert_eq!(
            rx.try_recv().ok(),
            Some(Operator::Drone(0, DroneCommand::TakeOff))
        );
        // Land (drone 2 flying) does not; drone 1's is disabled.
        for b in h.get_all_by_label("Land") {
            b.click();
        }
        step(&mut h);
        assert_eq!(
            rx.try_recv().ok(),
            Some(Operator::Drone(1, DroneCommand::Land))
        );
        assert!(rx.try_recv().is_err(), "a drone on the ground has no land");
        // Return home: at once.
        for b in h.get_all_by_label("Return home") {
            b.click();
        }
        step(&mut h);
        assert_eq!(
            rx.try_recv().ok(),
            Some(Operator::Drone(1, DroneCommand::ReturnHome))
        );
        // Hold at the goal height and yaw typed in, after the question.
        for b in h.get_all_by_label("Hold") {
            b.click();
        }
        step(&mut h);
        h.get_by_label_contains("holds 0.90 m, yaw 29°");
        h.get_by_label("Confirm").click();
        step(&mut h);
        match rx.try_recv() {
            Ok(Operator::Drone(1, DroneCommand::Hold { height, yaw })) => {
                assert!((height - 0.9).abs() < 1e-9 && (yaw - 0.5).abs() < 0.01);
            }
            other => panic!("expected drone 2 to hold, got {other:?}"),
        }
        // Disarm (drone 1 on the ground) asks first.
        for b in h.get_all_by_label("Disarm") {
            b.click();
        }
        step(&mut h);
        h.get_by_label("Confirm").click();
        step(&mut h);
        assert_eq!(
            rx.try_recv().ok(),
            Some(Operator::Drone(0, DroneCommand::Disarm))
        );
        assert!(rx.try_recv().is_err());
    }
}
