//! What the depth camera will see from a pose, by the map: headings that give the SLAM something
//! to track.
//!
//! A depth camera returns nothing beyond its range (the simulated Kinect: 4 m) or nearer than its
//! minimum, and RGB-D tracking needs features *with depth*. Facing down a corridor longer than
//! the range, or through a door into a room deeper than it, the SLAM loses the map. In two-drone
//! missions on the apartment (seeds 0–7), the camera's view at the start of every loss that lasted
//! over half a second had a median of 43–48 % of its rays meeting a wall within range, against
//! 81 % over the frames the SLAM tracked; 67–70 % of those losses began under 60 %, against 11 % of
//! tracked frames. [`view_score`] estimates that fraction on the 2D map; [`facing`] picks a
//! heading near the one a path asks for whose view is better, and the look around turns back
//! before a heading whose view is known to be empty.

use crate::grid::{Cell, Grid};
use crate::local::wrap_angle;

/// The depth camera as the map sees it: a fan of rays across its horizontal field of view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthView {
    /// Horizontal field of view, radians.
    pub hfov_rad: f64,
    /// Nearest depth the camera returns, metres.
    pub min_range_m: f64,
    /// Farthest depth the camera returns, metres.
    pub max_range_m: f64,
    /// Rays cast across the field of view (at least 2).
    pub rays: usize,
    /// What a ray that runs into unknown space within range counts (0 nothing in range, 1 a
    /// wall): the map cannot say, and unknown space near a drone is mostly space the camera has
    /// not faced yet.
    pub unknown: f64,
}

impl Default for DepthView {
    /// The simulated Kinect at 320×240 (fx 262.5: 62.7°), 0.4–4 m.
    fn default() -> Self {
        Self {
            hfov_rad: 2.0 * (160.0f64 / 262.5).atan(),
            min_range_m: 0.4,
            max_range_m: 4.0,
            rays: 13,
            unknown: 0.5,
        }
    }
}

/// The expected fraction of the camera's rays that return depth from `position` facing `yaw`
/// (map frame), in [0, 1]: a ray meeting an occupied cell within range counts 1, one meeting it
/// nearer than the minimum or running through free cells past the range counts 0, one running
/// into unknown space (or off the map) within range counts [`DepthView::unknown`]. A position
/// off the map or not finite scores as unknown.
pub fn view_score(map: &Grid, position: [f64; 2], yaw: f64, view: &DepthView) -> f64 {
    let rays = view.rays.max(2);
    if !(position.iter().all(|v| v.is_finite()) && yaw.is_finite())
        || map.cell_of(position).is_none()
    {
        return view.unknown;
    }
    let sum: f64 = (0..rays)
        .map(|i| {
            let a = yaw + view.hfov_rad * (i as f64 / (rays - 1) as f64 - 0.5);
            ray(map, position, a, view)
        })
        .sum();
    sum / rays as f64
}

/// What one ray from `position` along heading `a` returns (see [`view_score`]).
fn ray(map: &Grid, position: [f64; 2], a: f64, view: &DepthView) -> f64 {
    let step = map.resolution() / 2.0;
    let (c, s) = (a.cos(), a.sin());
    let mut d = 0.0;
    while d <= view.max_range_m {
        match map.cell_of([position[0] + d * c, position[1] + d * s]) {
            None => return view.unknown,
            Some(xy) => match map.get(xy) {
                Cell::Occupied if d < view.min_range_m => return 0.0,
                Cell::Occupied => return 1.0,
                Cell::Unknown => return view.unknown,
                Cell::Free => {}
            },
        }
        d += step;
    }
    0.0
}

/// How a drone following a path chooses where to face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Facing {
    /// Below this score the heading the path asks for is worth changing…
    pub poor: f64,
    /// …to one at most this far off it, radians…
    pub max_offset_rad: f64,
    /// …tried in steps of this, radians…
    pub step_rad: f64,
    /// …that scores at least this much better.
    pub gain: f64,
}

impl Default for Facing {
    fn default() -> Self {
        Self {
            poor: 0.5,
            max_offset_rad: 60f64.to_radians(),
            step_rad: 15f64.to_radians(),
            gain: 0.2,
        }
    }
}

/// The heading to face at `position` when a path asks for `heading`, for a camera seeing as
/// `view`: `heading` itself unless its view scores under [`Facing::poor`]; then the heading within [`Facing::max_offset_rad`] of it
/// with the best view, nearer ones first on a tie, if it scores [`Facing::gain`] better. A
/// drone under position control flies its path whichever way it faces; the path keeps it in
/// known free space.
pub fn facing(
    map: &Grid,
    position: [f64; 2],
    heading: f64,
    view: &DepthView,
    config: &Facing,
) -> f64 {
    let here = view_score(map, position, heading, view);
    if here >= config.poor || !config.step_rad.is_finite() || config.step_rad <= 0.0 {
        return heading;
    }
    let steps = (config.max_offset_rad / config.step_rad).floor() as i64;
    let mut best = (here, heading);
    for k in 1..=steps {
        for sign in [1.0, -1.0] {
            let h = wrap_angle(heading + sign * k as f64 * config.step_rad);
            let score = view_score(map, position, h, view);
            if score > best.0 + 1e-9 {
                best = (score, h);
            }
        }
    }
    if best.0 >= here + config.gain {
        best.1
    } else {
        heading
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    /// A free room `w × h` metres walled round (5 cm cells, origin at 0).
    fn room(w: f64, h: f64) -> Grid {
        let (cw, ch) = ((w / 0.05) as usize, (h / 0.05) as usize);
        let mut g = Grid::new(cw, ch, 0.05, [0.0, 0.0], Cell::Free);
        for x in 0..cw {
            g.set((x, 0), Cell::Occupied);
            g.set((x, ch - 1), Cell::Occupied);
        }
        for y in 0..ch {
            g.set((0, y), Cell::Occupied);
            g.set((cw - 1, y), Cell::Occupied);
        }
        g
    }

    #[test]
    fn a_wall_within_range_is_seen_one_beyond_it_or_too_near_is_not() {
        let view = DepthView::default();
        // A hall 10 m long and 4 m wide: along it, little in range; across it, the wall 2 m off.
        let g = room(10.0, 4.0);
        let along = view_score(&g, [1.0, 2.0], 0.0, &view);
        let across = view_score(&g, [1.0, 2.0], FRAC_PI_2, &view);
        assert!(across > 0.99, "{across}");
        // Only the rays at the edge of the fan meet the side walls within 4 m.
        assert!(along < 0.5, "{along}");
        // The end wall 2 m ahead is in range.
        assert!(view_score(&g, [7.9, 2.0], 0.0, &view) > 0.99);
        // A wall 0.2 m ahead is too near for the camera.
        assert!(view_score(&g, [9.75, 2.0], 0.0, &view) < 0.01);
    }

    #[test]
    fn unknown_space_counts_as_the_configured_guess() {
        let view = DepthView::default();
        let g = Grid::new(100, 100, 0.05, [0.0, 0.0], Cell::Unknown);
        assert_eq!(view_score(&g, [2.5, 2.5], 0.3, &view), view.unknown);
        // Off the map, or not a number: the same guess, no panic.
        assert_eq!(view_score(&g, [-3.0, 2.5], 0.3, &view), view.unknown);
        assert_eq!(view_score(&g, [f64::NAN, 2.5], 0.3, &view), view.unknown);
        assert_eq!(
            view_score(&g, [2.5, 2.5], f64::INFINITY, &view),
            view.unknown
        );
    }

    #[test]
    fn a_drone_facing_down_a_long_corridor_turns_toward_a_wall_in_range() {
        let g = room(12.0, 4.0);
        let (view, config) = (DepthView::default(), Facing::default());
        let h = facing(&g, [1.0, 2.0], 0.0, &view, &config);
        assert!(
            h.abs() > 0.2 && h.abs() <= config.max_offset_rad + 1e-9,
            "{h}"
        );
        assert!(
            view_score(&g, [1.0, 2.0], h, &view)
                >= view_score(&g, [1.0, 2.0], 0.0, &view) + config.gain
        );
        // Facing a wall in range already: no change.
        assert_eq!(facing(&g, [10.0, 2.0], 0.0, &view, &config), 0.0);
        // Wrapped round ±π: the same, mirrored.
        let back = facing(&g, [11.0, 2.0], PI, &view, &config);
        assert!(wrap_angle(back - PI).abs() > 0.2, "{back}");
    }

    #[test]
    fn with_nothing_better_in_reach_the_path_heading_stays() {
        // An open, known-free hall: no wall in range anywhere.
        let g = Grid::new(400, 400, 0.05, [0.0, 0.0], Cell::Free);
        let (view, config) = (DepthView::default(), Facing::default());
        assert_eq!(facing(&g, [10.0, 10.0], 1.0, &view, &config), 1.0);
    }
}
