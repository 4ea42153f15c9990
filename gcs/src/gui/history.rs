//! Telemetry history for the plots: per drone, height and yaw, goal against actual (the thesis's
//! base-station plots, 000 §4.3).

use std::collections::VecDeque;

use egui::Color32;
use egui_plot::{Legend, Line, LineStyle, Plot, PlotPoints};

use crate::runtime::Snapshot;

/// Seconds of history kept.
const KEEP_S: f64 = 120.0;

/// One drone at one moment.
#[derive(Debug, Clone, Copy)]
struct Sample {
    t: f64,
    height: Option<f64>,
    height_goal: f64,
    yaw_deg: Option<f64>,
    yaw_goal_deg: f64,
}

/// The plotted history of every drone.
#[derive(Default)]
pub(super) struct History {
    drones: Vec<VecDeque<Sample>>,
    last: Option<f64>,
}

impl History {
    /// Takes the snapshot's values (once per snapshot).
    pub(super) fn record(&mut self, s: &Snapshot) {
        if self.last.is_some_and(|t| t >= s.time) {
            return;
        }
        self.last = Some(s.time);
        self.drones.resize_with(s.drones.len(), VecDeque::new);
        for (d, samples) in s.drones.iter().zip(&mut self.drones) {
            let height = d.pose.map(|p| p[2]).or(d.telemetry.height_m.map(f64::from));
            let yaw = d.pose.map(|p| p[3]).or(d.telemetry.yaw_rad.map(f64::from));
            samples.push_back(Sample {
                t: s.time,
                height,
                height_goal: d.height_goal,
                yaw_deg: yaw.map(f64::to_degrees),
                yaw_goal_deg: d.yaw_goal.to_degrees(),
            });
            while samples.front().is_some_and(|f| s.time - f.t > KEEP_S) {
                samples.pop_front();
            }
        }
    }

    /// Height and yaw plots of drone `k`, side by side.
    pub(super) fn show(&self, ui: &mut egui::Ui, k: usize) {
        let Some(samples) = self.drones.get(k) else {
            ui.label("no telemetry yet");
            return;
        };
        let now = samples.back().map_or(0.0, |s| s.t);
        let series = |f: &dyn Fn(&Sample) -> Option<f64>| -> Vec<[f64; 2]> {
            samples
                .iter()
                .filter_map(|s| f(s).map(|v| [s.t - now, v]))
                .collect()
        };
        let height = series(&|s| s.height);
        let height_goal = series(&|s| Some(s.height_goal));
        // Yaw wraps at ±180°: unwrap it so a turn through south is one line.
        let yaw = unwrap_degrees(series(&|s| s.yaw_deg));
        let yaw_goal = unwrap_degrees(series(&|s| Some(s.yaw_goal_deg)));
        let w = (ui.available_width() - 8.0) / 2.0;
        let h = ui.available_height().max(80.0);
        ui.horizontal_top(|ui| {
            two_lines(ui, "height", "height [m]", height, height_goal, [w, h]);
            two_lines(ui, "yaw", "yaw [°]", yaw, yaw_goal, [w, h]);
        });
    }
}

fn two_lines(
    ui: &mut egui::Ui,
    id: &str,
    axis: &str,
    actual: Vec<[f64; 2]>,
    goal: Vec<[f64; 2]>,
    [w, h]: [f32; 2],
) {
    Plot::new(id)
        .width(w)
        .height(h)
        .legend(Legend::default())
        .x_axis_label("s")
        .y_axis_label(axis)
        .allow_scroll(false)
        .show(ui, |plot| {
            plot.line(
                Line::new("goal", PlotPoints::from(goal))
                    .color(Color32::from_rgb(230, 140, 0))
                    .style(LineStyle::dashed_loose()),
            );
            plot.line(
                Line::new("actual", PlotPoints::from(actual)).color(Color32::from_rgb(40, 90, 220)),
            );
        });
}

/// Removes the ±360° jumps of an angle series, the latest value kept within ±180°.
fn unwrap_degrees(mut points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let mut offset = 0.0;
    for i in 1..points.len() {
        let step = points[i][1] + offset - points[i - 1][1];
        if step > 180.0 {
            offset -= 360.0;
        } else if step < -180.0 {
            offset += 360.0;
        }
        points[i][1] += offset;
    }
    if let Some(last) = points.last() {
        let shift = -360.0 * ((last[1] + 180.0) / 360.0).floor();
        for p in &mut points {
            p[1] += shift;
        }
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwrapping_joins_a_turn_through_south() {
        let p = unwrap_degrees(vec![
            [0.0, 170.0],
            [1.0, -175.0],
            [2.0, -160.0],
            [3.0, 175.0],
        ]);
        let y: Vec<f64> = p.iter().map(|q| q[1]).collect();
        assert_eq!(y, vec![170.0, 185.0, 200.0, 175.0]);
        // Ending past 180°, the whole line shifts so the latest value reads as the drone's yaw.
        let p = unwrap_degrees(vec![[0.0, 170.0], [1.0, -170.0]]);
        let y: Vec<f64> = p.iter().map(|q| q[1]).collect();
        assert_eq!(y, vec![-190.0, -170.0]);
    }
}
