//! Pictures of a plan for people: the map, frontier cells, robots, their targets and paths.

use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_circle_mut, draw_hollow_circle_mut, draw_line_segment_mut};

use crate::frontier::is_frontier_cell;
use crate::grid::Grid;
use crate::mission::Plan;

/// Colours of robots 0, 1, 2, … (cycled), in every picture of robots.
pub const ROBOT_COLOURS: [[u8; 3]; 8] = [
    [220, 40, 40],
    [40, 90, 220],
    [20, 160, 60],
    [230, 140, 0],
    [150, 50, 200],
    [0, 170, 170],
    [200, 60, 140],
    [110, 110, 20],
];

/// Draws `plan` over `map` at about `target_px` pixels on the longer side.
pub fn draw_plan(map: &Grid, plan: &Plan, robots: &[Option<[f64; 2]>], target_px: u32) -> RgbImage {
    let longest = map.width().max(map.height()) as u32;
    let scale = target_px.div_ceil(longest.max(1)).max(1);
    let mut img = map.render(scale);
    let to_px = |p: [f64; 2]| -> (f32, f32) {
        let o = map.origin();
        let x = (p[0] - o[0]) / map.resolution() * f64::from(scale);
        let y = (map.height() as f64 - (p[1] - o[1]) / map.resolution()) * f64::from(scale);
        (x as f32, y as f32)
    };
    // Inflated obstacles a light red, frontier cells cyan.
    for i in 0..plan.inflated.cells().len() {
        let c = plan.inflated.xy(i);
        let colour = if is_frontier_cell(&plan.inflated, c) {
            Some(Rgb([0, 200, 230]))
        } else if plan.inflated.cells()[i] == crate::Cell::Occupied
            && map.cells()[i] == crate::Cell::Free
        {
            Some(Rgb([255, 205, 205]))
        } else {
            None
        };
        if let Some(colour) = colour {
            let (px, py) = to_px(map.center_of(c));
            let half = scale as f32 / 2.0;
            for dy in 0..scale {
                for dx in 0..scale {
                    let (x, y) = (
                        (px - half) as i64 + i64::from(dx),
                        (py - half) as i64 + i64::from(dy),
                    );
                    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
                        img.put_pixel(x as u32, y as u32, colour);
                    }
                }
            }
        }
    }
    let r = (scale as i32 * 3).max(4);
    for f in &plan.frontiers {
        let (x, y) = to_px(map.center_of(f.goal));
        draw_hollow_circle_mut(&mut img, (x as i32, y as i32), r, Rgb([0, 120, 160]));
    }
    for (i, (rp, pos)) in plan.robots.iter().zip(robots).enumerate() {
        let colour = Rgb(ROBOT_COLOURS[i % ROBOT_COLOURS.len()]);
        for w in rp.path.windows(2) {
            let (a, b) = (to_px(w[0]), to_px(w[1]));
            for d in [-1.0f32, 0.0, 1.0] {
                draw_line_segment_mut(&mut img, (a.0 + d, a.1), (b.0 + d, b.1), colour);
                draw_line_segment_mut(&mut img, (a.0, a.1 + d), (b.0, b.1 + d), colour);
            }
        }
        if let Some(last) = rp.path.last() {
            let (x, y) = to_px(*last);
            draw_filled_circle_mut(&mut img, (x as i32, y as i32), r, colour);
        }
        if let Some(p) = pos {
            let (x, y) = to_px(*p);
            draw_filled_circle_mut(&mut img, (x as i32, y as i32), r + 2, Rgb([0, 0, 0]));
            draw_filled_circle_mut(&mut img, (x as i32, y as i32), r, colour);
        }
    }
    img
}
