//! The live map: the occupancy grid the planner used last, the simulated world's walls (in
//! SITL), frontiers, every drone's pose, trajectory, planned path and assigned goal. Drag to
//! pan, scroll to zoom, double-click (or "Fit") to see everything again.

use std::sync::Arc;

use egui::{Color32, ColorImage, Pos2, Rect, Sense, Shape, Stroke, TextureHandle, TextureOptions};
use nav::grid::{Cell, Grid};
use sitl::World;

use crate::runtime::{DroneView, Snapshot};

/// Free cells of the live map (also what the screenshot check looks for).
pub const FREE: Color32 = Color32::from_rgb(236, 236, 228);
/// Occupied cells of the live map.
pub const OCCUPIED: Color32 = Color32::from_rgb(40, 40, 48);
/// Cells not seen yet.
pub const UNKNOWN: Color32 = Color32::from_rgb(128, 132, 140);
/// The world's walls drawn over the map.
const WALLS: Color32 = Color32::from_rgba_premultiplied(120, 40, 0, 120);
/// Frontier goals.
const FRONTIER: Color32 = Color32::from_rgb(250, 200, 0);

/// The colour of drone `k` (nav's robot palette, as in every picture of robots).
pub fn drone_colour(k: usize) -> Color32 {
    let [r, g, b] = nav::render::ROBOT_COLOURS[k % nav::render::ROBOT_COLOURS.len()];
    Color32::from_rgb(r, g, b)
}

/// The map's camera: which map point is at the centre of the view, and the scale.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Camera {
    centre: [f64; 2],
    px_per_m: f64,
}

impl Camera {
    fn screen_from_map(&self, view: Rect, point_in_map: [f64; 2]) -> Pos2 {
        let c = view.center();
        Pos2::new(
            c.x + ((point_in_map[0] - self.centre[0]) * self.px_per_m) as f32,
            c.y - ((point_in_map[1] - self.centre[1]) * self.px_per_m) as f32,
        )
    }

    fn map_from_screen(&self, view: Rect, point_on_screen: Pos2) -> [f64; 2] {
        let c = view.center();
        [
            self.centre[0] + f64::from(point_on_screen.x - c.x) / self.px_per_m,
            self.centre[1] - f64::from(point_on_screen.y - c.y) / self.px_per_m,
        ]
    }

    /// The camera that shows `bounds` (min, max corners in the map) whole in `view`.
    fn fit(view: Rect, min: [f64; 2], max: [f64; 2]) -> Self {
        let (w, h) = ((max[0] - min[0]).max(1.0), (max[1] - min[1]).max(1.0));
        let scale = (f64::from(view.width()) / w).min(f64::from(view.height()) / h) * 0.95;
        Self {
            centre: [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0],
            px_per_m: scale.clamp(2.0, 400.0),
        }
    }
}

/// A grid as a texture, remade when the grid changes.
struct GridTexture {
    source: Arc<Grid>,
    texture: TextureHandle,
}

/// What the map shows.
#[derive(Debug, Clone, Copy)]
struct Layers {
    walls: bool,
    frontiers: bool,
    paths: bool,
    trajectories: bool,
}

/// The map panel.
pub(super) struct MapView {
    world: Option<Arc<World>>,
    world_walls: Option<Arc<Grid>>,
    walls_texture: Option<TextureHandle>,
    grid: Option<GridTexture>,
    /// `None` until the operator pans or zooms: the view follows the map's extent.
    camera: Option<Camera>,
    layers: Layers,
}

impl MapView {
    pub(super) fn new(world: Option<Arc<World>>) -> Self {
        Self {
            world_walls: world.as_deref().map(|w| Arc::new(w.to_grid())),
            world,
            walls_texture: None,
            grid: None,
            camera: None,
            layers: Layers {
                walls: true,
                frontiers: true,
                paths: true,
                trajectories: true,
            },
        }
    }

    pub(super) fn show(&mut self, ui: &mut egui::Ui, s: &Snapshot) {
        ui.horizontal(|ui| {
            ui.strong("Map");
            if self.world.is_some() {
                ui.checkbox(&mut self.layers.walls, "world walls");
            }
            ui.checkbox(&mut self.layers.frontiers, "frontiers");
            ui.checkbox(&mut self.layers.paths, "paths and goals");
            ui.checkbox(&mut self.layers.trajectories, "trajectories");
            if ui.button("Fit").clicked() {
                self.camera = None;
            }
            if let Some(g) = &s.grid {
                let [free, occupied, unknown] = g.counts();
                let m2 = g.resolution() * g.resolution();
                ui.label(format!(
                    "{:.0} m² free, {:.0} m² occupied, {:.0} m² unknown; {} frontiers",
                    free as f64 * m2,
                    occupied as f64 * m2,
                    unknown as f64 * m2,
                    s.frontiers.len()
                ));
            }
        });
        let (response, painter) = ui.allocate_painter(ui.available_size(), Sense::click_and_drag());
        let view = response.rect;
        painter.rect_filled(view, 0.0, UNKNOWN);
        let mut camera = self.camera.unwrap_or_else(|| self.fitted(view, s));
        // Pan and zoom.
        if response.dragged() {
            let d = response.drag_delta();
            camera.centre[0] -= f64::from(d.x) / camera.px_per_m;
            camera.centre[1] += f64::from(d.y) / camera.px_per_m;
            self.camera = Some(camera);
        }
        if response.double_clicked() {
            self.camera = None;
            camera = self.fitted(view, s);
        }
        if let Some(cursor) = response.hover_pos() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                let before = camera.map_from_screen(view, cursor);
                camera.px_per_m =
                    (camera.px_per_m * f64::from((scroll * 0.003).exp())).clamp(2.0, 400.0);
                let after = camera.map_from_screen(view, cursor);
                camera.centre[0] += before[0] - after[0];
                camera.centre[1] += before[1] - after[1];
                self.camera = Some(camera);
            }
        }
        // The map and the world.
        if let Some(grid) = &s.grid {
            let texture = self.grid_texture(ui.ctx(), grid);
            painter.image(
                texture.id(),
                grid_rect(&camera, view, grid),
                uv(),
                Color32::WHITE,
            );
        }
        if self.layers.walls
            && let Some(walls) = self.world_walls.clone()
        {
            let texture = self.walls_texture.get_or_insert_with(|| {
                ui.ctx().load_texture(
                    "world walls",
                    picture(&walls, |c| match c {
                        Cell::Occupied => WALLS,
                        _ => Color32::TRANSPARENT,
                    }),
                    TextureOptions::NEAREST,
                )
            });
            painter.image(
                texture.id(),
                grid_rect(&camera, view, &walls),
                uv(),
                Color32::WHITE,
            );
        }
        let to_screen = |p: [f64; 2]| camera.screen_from_map(view, p);
        if self.layers.frontiers {
            for f in &s.frontiers {
                painter.circle(
                    to_screen(*f),
                    4.0,
                    FRONTIER,
                    Stroke::new(1.0, Color32::BLACK),
                );
            }
        }
        for d in &s.drones {
            self.draw_drone(&painter, &to_screen, d, camera.px_per_m);
        }
        // A scale bar.
        let metres = nice_length(120.0 / camera.px_per_m);
        let a = view.left_bottom() + egui::vec2(12.0, -14.0);
        let b = a + egui::vec2((metres * camera.px_per_m) as f32, 0.0);
        painter.line_segment([a, b], Stroke::new(3.0, Color32::BLACK));
        painter.text(
            b + egui::vec2(6.0, 0.0),
            egui::Align2::LEFT_CENTER,
            format!("{metres} m"),
            egui::FontId::proportional(13.0),
            Color32::BLACK,
        );
        if s.grid.is_none() {
            painter.text(
                view.center(),
                egui::Align2::CENTER_CENTER,
                "no map yet: start the mission",
                egui::FontId::proportional(18.0),
                Color32::WHITE,
            );
        }
    }

    fn draw_drone(
        &self,
        painter: &egui::Painter,
        to_screen: &dyn Fn([f64; 2]) -> Pos2,
        d: &DroneView,
        px_per_m: f64,
    ) {
        let colour = drone_colour(d.id);
        if self.layers.trajectories && d.trajectory.len() > 1 {
            let points: Vec<Pos2> = d.trajectory.iter().map(to_screen).collect();
            painter.add(Shape::line(
                points,
                Stroke::new(1.5, colour.gamma_multiply(0.6)),
            ));
        }
        let Some(pose) = d.pose else {
            // No valid pose: where it was last seen, hollow, so the operator still finds it.
            if let Some(last) = d.trajectory.last() {
                let at = to_screen(last);
                painter.circle_stroke(at, 8.0, Stroke::new(2.0, colour));
                painter.text(
                    at + egui::vec2(10.0, -12.0),
                    egui::Align2::LEFT_BOTTOM,
                    format!("{} (no pose)", d.name),
                    egui::FontId::proportional(13.0),
                    Color32::BLACK,
                );
            }
            return;
        };
        let here = to_screen([pose[0], pose[1]]);
        if self.layers.paths {
            if d.path.len() > 1 {
                let points: Vec<Pos2> = d.path.iter().map(|p| to_screen(*p)).collect();
                painter.add(Shape::line(points, Stroke::new(2.5, colour)));
            }
            if let Some(goal) = d.goal {
                // The assignment: which drone goes where.
                let g = to_screen(goal);
                painter.extend(Shape::dashed_line(
                    &[here, g],
                    Stroke::new(1.5, colour),
                    6.0,
                    4.0,
                ));
                painter.circle_stroke(g, 7.0, Stroke::new(2.5, colour));
            }
        }
        // Uncertainty, then the body as a triangle pointing along its heading.
        let sigma = (d.pose_sigma * px_per_m) as f32;
        if sigma > 3.0 {
            painter.circle_stroke(here, sigma, Stroke::new(1.0, colour.gamma_multiply(0.5)));
        }
        let (s, c) = (pose[3].sin() as f32, pose[3].cos() as f32);
        let size = 11.0;
        let at = |fwd: f32, left: f32| {
            here + egui::vec2(fwd * c - left * s, -(fwd * s + left * c)) * size
        };
        painter.add(Shape::convex_polygon(
            vec![at(1.0, 0.0), at(-0.7, 0.6), at(-0.4, 0.0), at(-0.7, -0.6)],
            colour,
            Stroke::new(1.0, Color32::BLACK),
        ));
        painter.text(
            here + egui::vec2(10.0, -12.0),
            egui::Align2::LEFT_BOTTOM,
            &d.name,
            egui::FontId::proportional(13.0),
            Color32::BLACK,
        );
    }

    /// The camera that shows the world (in SITL) or the map whole.
    fn fitted(&self, view: Rect, s: &Snapshot) -> Camera {
        let bounds = |g: &Grid| {
            let o = g.origin();
            let r = g.resolution();
            (
                o,
                [o[0] + g.width() as f64 * r, o[1] + g.height() as f64 * r],
            )
        };
        let (min, max) = match (&self.world_walls, &s.grid) {
            (Some(w), _) => bounds(w),
            (None, Some(g)) => bounds(g),
            (None, None) => ([-5.0, -5.0], [5.0, 5.0]),
        };
        Camera::fit(view, min, max)
    }

    fn grid_texture(&mut self, ctx: &egui::Context, grid: &Arc<Grid>) -> &TextureHandle {
        let image = |g: &Grid| {
            picture(g, |c| match c {
                Cell::Free => FREE,
                Cell::Occupied => OCCUPIED,
                Cell::Unknown => UNKNOWN,
            })
        };
        let t = self.grid.get_or_insert_with(|| GridTexture {
            source: grid.clone(),
            texture: ctx.load_texture("map", image(grid), TextureOptions::NEAREST),
        });
        if !Arc::ptr_eq(&t.source, grid) {
            t.texture.set(image(grid), TextureOptions::NEAREST);
            t.source = grid.clone();
        }
        &t.texture
    }
}

/// A grid as a picture, row 0 (the map's lowest y) at the bottom.
fn picture(grid: &Grid, colour: impl Fn(Cell) -> Color32) -> ColorImage {
    let (w, h) = (grid.width(), grid.height());
    let mut pixels = Vec::with_capacity(w * h);
    for row in (0..h).rev() {
        for col in 0..w {
            pixels.push(colour(grid.get((col, row))));
        }
    }
    ColorImage::new([w, h], pixels)
}

/// Where `grid` lies on the screen.
fn grid_rect(camera: &Camera, view: Rect, grid: &Grid) -> Rect {
    let o = grid.origin();
    let r = grid.resolution();
    let top_left = camera.screen_from_map(view, [o[0], o[1] + grid.height() as f64 * r]);
    let bottom_right = camera.screen_from_map(view, [o[0] + grid.width() as f64 * r, o[1]]);
    Rect::from_min_max(top_left, bottom_right)
}

fn uv() -> Rect {
    Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0))
}

/// 1, 2 or 5 times a power of ten, near `m`.
fn nice_length(m: f64) -> f64 {
    let p = 10f64.powf(m.max(1e-3).log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|k| k * p)
        .min_by(|a, b| (a - m).abs().total_cmp(&(b - m).abs()))
        .unwrap_or(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_round_trips_and_keeps_y_up() {
        let view = Rect::from_min_max(Pos2::new(0.0, 0.0), Pos2::new(800.0, 600.0));
        let camera = Camera::fit(view, [0.0, 0.0], [10.0, 5.0]);
        let p = [3.0, 4.0];
        let q = camera.map_from_screen(view, camera.screen_from_map(view, p));
        assert!(
            (q[0] - p[0]).abs() < 1e-4 && (q[1] - p[1]).abs() < 1e-4,
            "{q:?}"
        );
        // Up in the map is up on the screen.
        let low = camera.screen_from_map(view, [5.0, 0.0]);
        let high = camera.screen_from_map(view, [5.0, 5.0]);
        assert!(high.y < low.y);
        // The whole extent is inside the view.
        for corner in [[0.0, 0.0], [10.0, 5.0]] {
            assert!(
                view.contains(camera.screen_from_map(view, corner)),
                "{corner:?}"
            );
        }
    }

    #[test]
    fn picture_puts_the_first_row_at_the_bottom() {
        let mut g = Grid::new(3, 2, 0.1, [0.0, 0.0], Cell::Unknown);
        g.set((0, 0), Cell::Occupied);
        g.set((2, 1), Cell::Free);
        let p = picture(&g, |c| match c {
            Cell::Free => FREE,
            Cell::Occupied => OCCUPIED,
            Cell::Unknown => UNKNOWN,
        });
        assert_eq!(p.size, [3, 2]);
        assert_eq!(p.pixels[3], OCCUPIED, "row 0 is the picture's last row");
        assert_eq!(p.pixels[2], FREE);
        assert_eq!(p.pixels[0], UNKNOWN);
    }

    #[test]
    fn scale_bar_lengths_are_round() {
        assert_eq!(nice_length(0.9), 1.0);
        assert_eq!(nice_length(1.6), 2.0);
        assert_eq!(nice_length(4.0), 5.0);
        assert_eq!(nice_length(0.23), 0.2);
    }
}
