//! The fleet: one card per drone with its link, mode, battery, height and yaw, SLAM state and
//! target, and its controls (the thesis's control-test tab: start, land, disarm, goal height
//! and yaw).

use egui::{Color32, RichText};
use link::LinkState;
use slam::system::RobotState;

use super::Request;
use super::map_view::drone_colour;
use crate::runtime::drone::Phase;
use crate::runtime::{DroneCommand, DroneView, Operator, Snapshot};

/// How long "relocalised" stays next to a drone's SLAM state, seconds.
const RELOCALISED_SHOWN_S: f64 = 30.0;

/// Per-drone state of the panel.
#[derive(Debug, Clone, Copy)]
struct Card {
    /// The goal height typed in, metres.
    height: f64,
    /// The goal yaw typed in, degrees.
    yaw_deg: f64,
    /// The operator changed the goal inputs (until then they follow the drone's goals).
    edited: bool,
    /// The SLAM state seen last.
    slam: RobotState,
    /// When tracking came back after being lost (mission time).
    relocalised_at: Option<f64>,
}

/// The fleet panel.
#[derive(Default)]
pub(super) struct FleetPanel {
    cards: Vec<Card>,
}

impl FleetPanel {
    /// Follows the drones between frames (the goal inputs start at their goals; relocalisation
    /// is a lost → tracking change).
    pub(super) fn observe(&mut self, s: &Snapshot) {
        for d in &s.drones {
            if self.cards.len() <= d.id {
                self.cards.resize(
                    d.id + 1,
                    Card {
                        height: d.height_goal,
                        yaw_deg: wrapped_degrees(d.yaw_goal),
                        edited: false,
                        slam: d.slam,
                        relocalised_at: None,
                    },
                );
            }
            let card = &mut self.cards[d.id];
            if card.slam == RobotState::Lost && d.slam == RobotState::Tracking {
                card.relocalised_at = Some(s.time);
            }
            card.slam = d.slam;
            if !card.edited {
                card.height = d.height_goal;
                card.yaw_deg = wrapped_degrees(d.yaw_goal).round();
            }
        }
    }

    pub(super) fn show(&mut self, ui: &mut egui::Ui, s: &Snapshot, asked: &mut Vec<Request>) {
        ui.heading(format!("Fleet ({})", s.drones.len()));
        for d in &s.drones {
            let Some(card) = self.cards.get_mut(d.id) else {
                continue;
            };
            egui::Frame::group(ui.style()).show(ui, |ui| {
                ui.set_width(ui.available_width());
                status(ui, d, card, s.time);
                egui::CollapsingHeader::new("Control")
                    .id_salt(("control", d.id))
                    .default_open(true)
                    .show(ui, |ui| controls(ui, d, card, asked));
            });
            ui.add_space(4.0);
        }
    }
}

fn status(ui: &mut egui::Ui, d: &DroneView, card: &Card, now: f64) {
    ui.horizontal(|ui| {
        let (rect, _) = ui.allocate_exact_size(egui::vec2(14.0, 14.0), egui::Sense::hover());
        ui.painter().rect_filled(rect, 3.0, drone_colour(d.id));
        ui.label(RichText::new(&d.name).strong().size(16.0));
        ui.label(
            RichText::new(d.phase.name())
                .strong()
                .color(phase_colour(d.phase)),
        );
    });
    // Why it stopped exploring before the end (its battery, its camera, its link, …).
    if let Some(why) = &d.left_mission {
        ui.label(
            RichText::new(format!("left the mission: {why}")).color(Color32::from_rgb(230, 140, 0)),
        );
    }
    // The link, with the age of the last message.
    ui.horizontal(|ui| {
        ui.label("link");
        let (text, colour) = match d.link.state {
            LinkState::Connected => ("connected", Color32::from_rgb(40, 160, 70)),
            LinkState::Degraded => ("degraded", Color32::from_rgb(230, 140, 0)),
            LinkState::Lost => ("link lost", Color32::from_rgb(210, 30, 30)),
            LinkState::Connecting => ("connecting", Color32::GRAY),
        };
        ui.label(RichText::new(text).strong().color(colour));
        match d.link.last_message_age {
            Some(age) => ui.label(format!("last message {:.1} s ago", age.as_secs_f64())),
            None => ui.label("nothing heard yet"),
        };
    });
    let t = &d.telemetry;
    ui.horizontal(|ui| {
        ui.label(format!("mode {}", t.mode.as_deref().unwrap_or("-")));
        ui.label(match t.armed {
            Some(true) => RichText::new("armed").color(Color32::from_rgb(210, 30, 30)),
            Some(false) => RichText::new("disarmed"),
            None => RichText::new("armed: -"),
        });
    });
    // Battery as a bar with its voltage and charge (the autopilot's estimate, or one read off
    // the voltage: "≈"), and the charge it turns home at from where it is: red within 5 % of
    // that, orange within 15 %.
    match t.battery {
        Some(b) => {
            let (charge, read) = match (b.remaining_pct, d.battery_estimate_pct) {
                (Some(p), _) => (Some(f64::from(p)), format!("{p} %")),
                (None, Some(p)) => (Some(p), format!("≈{p:.0} %")),
                (None, None) => (None, String::new()),
            };
            let fraction = charge.map_or(0.0, |p| (p / 100.0) as f32);
            let home_at = d
                .battery_home_at
                .map_or(String::new(), |h| format!(" · home at {h:.0} %"));
            let text = match charge {
                Some(_) => format!("{:.1} V  {read}{home_at}", b.voltage_v),
                None => format!("{:.1} V", b.voltage_v),
            };
            let turn = d.battery_home_at.unwrap_or(25.0);
            let fill = match charge {
                Some(p) if p < turn + 5.0 => Color32::from_rgb(210, 30, 30),
                Some(p) if p < turn + 15.0 => Color32::from_rgb(230, 140, 0),
                _ => Color32::from_rgb(40, 160, 70),
            };
            ui.horizontal(|ui| {
                ui.label("battery");
                ui.add(egui::ProgressBar::new(fraction).fill(fill).text(text));
            });
        }
        None => {
            ui.label("battery: -");
        }
    }
    let height = d
        .pose
        .map(|p| p[2])
        .or(t.height_m.map(f64::from))
        .map_or("-".into(), |h| format!("{h:.2} m"));
    let yaw = d
        .pose
        .map(|p| p[3])
        .or(t.yaw_rad.map(f64::from))
        .map_or("-".into(), |y| format!("{:.0}°", wrapped_degrees(y)));
    ui.label(format!(
        "height {height} (goal {:.2} m) · yaw {yaw} (goal {:.0}°)",
        d.height_goal,
        wrapped_degrees(d.yaw_goal)
    ));
    ui.horizontal(|ui| {
        ui.label("SLAM");
        let colour = match d.slam {
            RobotState::Tracking => Color32::from_rgb(40, 160, 70),
            RobotState::Lost => Color32::from_rgb(210, 30, 30),
            RobotState::Waiting => Color32::GRAY,
        };
        ui.label(RichText::new(d.slam.name()).strong().color(colour));
        if let Some(at) = card.relocalised_at
            && d.slam == RobotState::Tracking
            && now - at < RELOCALISED_SHOWN_S
        {
            ui.label(format!("relocalised {:.0} s ago", now - at));
        }
        if d.pose.is_some() {
            ui.label(format!("σ {:.2} m", d.pose_sigma));
        } else {
            ui.label(RichText::new("no pose").color(Color32::from_rgb(210, 30, 30)));
        }
    });
    ui.label(match d.goal {
        Some([x, y]) => format!("target ({x:.1}, {y:.1}) m"),
        None => "target: none".into(),
    });
}

fn controls(ui: &mut egui::Ui, d: &DroneView, card: &mut Card, asked: &mut Vec<Request>) {
    let k = d.id;
    let on_ground = matches!(d.phase, Phase::Idle | Phase::Landed);
    let flying = d.phase.flying();
    ui.horizontal_wrapped(|ui| {
        if ui
            .add_enabled(on_ground, egui::Button::new("Take off"))
            .clicked()
        {
            asked.push(Request::Confirm {
                question: format!(
                    "Take off {}? It arms, starts its motors and climbs to its band.",
                    d.name
                ),
                command: Operator::Drone(k, DroneCommand::TakeOff),
            });
        }
        if ui
            .add_enabled(
                flying || d.phase == Phase::Arming,
                egui::Button::new("Land"),
            )
            .clicked()
        {
            asked.push(Request::Now(Operator::Drone(k, DroneCommand::Land)));
        }
        if ui
            .add_enabled(flying, egui::Button::new("Return home"))
            .clicked()
        {
            asked.push(Request::Now(Operator::Drone(k, DroneCommand::ReturnHome)));
        }
        if ui
            .add_enabled(on_ground, egui::Button::new("Disarm"))
            .clicked()
        {
            asked.push(Request::Confirm {
                question: format!("Disarm {}? Its motors stop.", d.name),
                command: Operator::Drone(k, DroneCommand::Disarm),
            });
        }
    });
    ui.horizontal_wrapped(|ui| {
        ui.label("goal");
        let height = ui
            .add(
                egui::DragValue::new(&mut card.height)
                    .range(0.3..=2.4)
                    .speed(0.01)
                    .fixed_decimals(2)
                    .suffix(" m"),
            )
            .on_hover_text("goal height");
        let yaw = ui
            .add(
                egui::DragValue::new(&mut card.yaw_deg)
                    .range(-180.0..=180.0)
                    .speed(1.0)
                    .fixed_decimals(0)
                    .suffix("°"),
            )
            .on_hover_text("goal yaw");
        card.edited |= height.changed() || yaw.changed();
        if ui.add_enabled(flying, egui::Button::new("Hold")).clicked() {
            card.edited = false;
            asked.push(Request::Confirm {
                question: format!(
                    "{} stops where it is and holds {:.2} m, yaw {:.0}°?",
                    d.name, card.height, card.yaw_deg
                ),
                command: Operator::Drone(
                    k,
                    DroneCommand::Hold {
                        height: card.height,
                        yaw: card.yaw_deg.to_radians(),
                    },
                ),
            });
        }
        if ui
            .add_enabled(d.phase == Phase::Holding, egui::Button::new("Explore"))
            .clicked()
        {
            asked.push(Request::Now(Operator::Drone(k, DroneCommand::Explore)));
        }
    });
}

fn phase_colour(p: Phase) -> Color32 {
    match p {
        Phase::Exploring | Phase::TakingOff => Color32::from_rgb(40, 160, 70),
        Phase::Holding | Phase::Returning | Phase::Arming => Color32::from_rgb(230, 140, 0),
        Phase::Landing => Color32::from_rgb(230, 140, 0),
        Phase::LinkLost => Color32::from_rgb(210, 30, 30),
        Phase::Idle | Phase::Landed => Color32::GRAY,
    }
}

/// An angle in degrees within ±180°.
fn wrapped_degrees(radians: f64) -> f64 {
    let d = radians.to_degrees().rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}
