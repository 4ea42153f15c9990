//! Odometry from the depth image alone, for a camera that sees no texture.
//!
//! Visual odometry ([`crate::system::Odometry`]) registers features, and a blank wall has
//! none. A drone lost facing one (in SITL, the featureless wall of the default world's south
//! room: from 1.6 m off the floor leaves the view) measures nothing of its motion, and the air
//! carries it into the wall while it turns to look for the map. Its depth image still ranges
//! the wall: how the range changes between frames is the body's motion along the wall's
//! normal.
//!
//! Like RTAB-Map's ICP odometry (point to plane), [`register`] aligns a frame's walls on the
//! previous frame's. Walls are vertical and the height is the rangefinder's, so it works in the
//! horizontal plane: each frame is levelled by its IMU's roll and pitch and its wall points
//! (those whose surface runs steeply down the image) become a virtual laser scan
//! ([`WallScan`]): by bearing from the camera, the median range of every row that sees a wall
//! there, which is ten times less noisy than a pixel. The scans are registered point to line
//! (the previous scan's local line through each point), each pair weighed by its range's
//! noise, starting from the IMU's turn. It reports the displacement only along the directions
//! the walls constrain ([`Along`]): one wall, its normal; a corner, both.

use std::collections::HashMap;

use nalgebra::{Isometry3, Matrix2, Matrix3, Point3, UnitQuaternion, Vector2, Vector3};

use crate::dataset::Pinhole;
pub use crate::ekf::Along;

/// How a frame's walls are found and registered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthOdometryConfig {
    /// A pixel every this many, across and down.
    pub stride: usize,
    /// Points farther than this are left out (the depth's noise grows with the square of the
    /// range), metres.
    pub max_range_m: f64,
    /// A pixel is on a wall where the surface runs more steeply than this down the image
    /// (vertical over horizontal distance between the pixels a stride above and below): a
    /// floor or a ceiling runs flat.
    pub min_wall_steepness: f64,
    /// Neighbours whose ranges differ by more than this fraction are on different surfaces.
    pub max_depth_step: f64,
    /// The width of a bearing of the virtual scan, radians.
    pub bearing_step_rad: f64,
    /// A bearing needs this many wall pixels to be a point of the scan.
    pub min_bearing_pixels: usize,
    /// A scan point is paired with the previous scan's point nearest along its line within
    /// this (across the line and along it), metres…
    pub match_m: f64,
    /// …whose normal is within this of its own (cosine).
    pub min_normal_cos: f64,
    /// Residuals beyond this many of their standard deviations count less (Huber).
    pub huber_sigmas: f64,
    /// Gauss–Newton steps.
    pub iterations: usize,
    /// Pairs needed to measure anything.
    pub min_matches: usize,
    /// A direction is measured when the walls face it as squarely as this many scan points
    /// square to it would (of a lone wall, the direction along it gets only its normals'
    /// noise: weighed by the depth's noise, which averaging a bearing makes sub-millimetre,
    /// that noise passes for a measurement and reads a turn as a slide of 10 cm)…
    pub min_information: f64,
    /// …and fix the displacement along it to within this (1 σ), metres.
    pub max_sigma_m: f64,
    /// A displacement is never taken as surer than this (1 σ), metres: a scan's points are not
    /// independent (a wall's points share its normal's error, the IMU's tilt levels them all),
    /// and against the simulator's truth nine in ten of its steps are within 6 mm.
    pub min_sigma_m: f64,
    /// A step longer than this between frames is a wrong registration, metres.
    pub max_step_m: f64,
    /// A registration turning further than this from the IMU's turn is a wrong one, radians.
    pub max_turn_correction_rad: f64,
}

impl Default for DepthOdometryConfig {
    /// For a Kinect-like camera at 320 × 240 and 10 Hz on a drone flying at most 1 m/s.
    fn default() -> Self {
        Self {
            stride: 2,
            max_range_m: 3.5,
            min_wall_steepness: 3.0,
            max_depth_step: 0.05,
            bearing_step_rad: 0.4f64.to_radians(),
            min_bearing_pixels: 5,
            match_m: 0.08,
            min_normal_cos: 0.8,
            huber_sigmas: 3.0,
            iterations: 10,
            min_matches: 30,
            min_information: 5.0,
            max_sigma_m: 0.01,
            min_sigma_m: 0.005,
            max_step_m: 0.15,
            max_turn_correction_rad: 4f64.to_radians(),
        }
    }
}

/// Standard deviation of a Kinect-like depth at `range` metres (Nguyen et al.).
fn depth_sigma(range: f64) -> f64 {
    0.0012 + 0.0019 * (range - 0.4).max(0.0).powi(2)
}

/// The walls one depth frame sees, levelled: a virtual laser scan in the body's horizontal
/// frame (x forward, y left), metres.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WallScan {
    points: Vec<Vector2<f64>>,
    /// Unit, pointing back toward the camera.
    normals: Vec<Vector2<f64>>,
    /// Each point's noise across its line (1 σ), metres.
    sigmas: Vec<f64>,
}

/// What [`register`] measured of the body's motion between two frames.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthOdometry {
    /// The earlier frame's time, seconds.
    pub since: f64,
    /// The displacement along each direction the walls constrain (none, one or two), in the
    /// body's levelled frame at the earlier frame.
    pub along: Vec<Along>,
    /// The turn between the frames (anticlockwise), radians.
    pub turn_rad: f64,
    /// Point pairs the registration rests on.
    pub matches: usize,
}

impl DepthOdometry {
    /// The displacement (forward, left; metres, in the body's levelled frame at the earlier
    /// frame) along the directions measured, nothing along the others.
    pub fn displacement(&self) -> [f64; 2] {
        self.along.iter().fold([0.0; 2], |[f, l], a| {
            [
                f + a.direction[0] * a.displacement,
                l + a.direction[1] * a.displacement,
            ]
        })
    }
}

impl WallScan {
    /// The walls of a depth image (`depth_scale` metres per unit, 0: none) seen by a
    /// `camera` placed on the body by `body_from_camera`, while the body was tilted by
    /// `tilt` (roll, pitch, radians; FLU). Empty when the image is not `width × height`.
    #[allow(clippy::too_many_arguments)]
    pub fn from_depth(
        depth: &[u16],
        width: usize,
        height: usize,
        depth_scale: f64,
        camera: &Pinhole,
        body_from_camera: &Isometry3<f64>,
        tilt: [f64; 2],
        config: &DepthOdometryConfig,
    ) -> Self {
        let mut scan = Self::default();
        let s = config.stride.max(1);
        let step = config.bearing_step_rad;
        if depth.len() != width * height
            || !(camera.fx > 0.0 && camera.fy > 0.0 && step > 0.0 && step.is_finite())
        {
            return scan;
        }
        let level_from_camera =
            UnitQuaternion::from_euler_angles(tilt[0], tilt[1], 0.0) * body_from_camera;
        let point = |u: usize, v: usize| -> Option<(f64, Vector3<f64>)> {
            let z = f64::from(*depth.get(v * width + u)?) * depth_scale;
            (z > 0.0 && z <= config.max_range_m).then(|| {
                let x = (u as f64 - camera.cx) / camera.fx * z;
                let y = (v as f64 - camera.cy) / camera.fy * z;
                (z, (level_from_camera * Point3::new(x, y, z)).coords)
            })
        };
        let camera_at = level_from_camera.translation.vector.xy();
        let near = |a: f64, b: f64| (a - b).abs() <= config.max_depth_step * a.min(b);
        // Every wall pixel's range from the camera and place, by bearing.
        let bins = (std::f64::consts::TAU / step).ceil() as usize;
        let mut by_bearing: Vec<Vec<(f64, Vector2<f64>)>> = vec![vec![]; bins];
        for v in (s..height.saturating_sub(s)).step_by(s) {
            for u in (0..width).step_by(s) {
                let Some((z, p)) = point(u, v) else { continue };
                let (Some((za, above)), Some((zb, below))) = (point(u, v - s), point(u, v + s))
                else {
                    continue;
                };
                let down = above - below;
                if !(near(z, za) && near(z, zb))
                    || down.z.abs() < config.min_wall_steepness * down.xy().norm()
                {
                    continue;
                }
                let ray = p.xy() - camera_at;
                let bearing = ray.y.atan2(ray.x) + std::f64::consts::PI;
                let bin = ((bearing / step) as usize).min(bins - 1);
                by_bearing[bin].push((ray.norm(), p.xy()));
            }
        }
        // Each bearing's pixels near their median range, averaged: a point of the scan.
        let mut ranged: Vec<(usize, f64, Vector2<f64>, f64)> = vec![];
        for (bin, seen) in by_bearing.iter_mut().enumerate() {
            if seen.len() < config.min_bearing_pixels.max(1) {
                continue;
            }
            seen.sort_by(|a, b| a.0.total_cmp(&b.0));
            let median = seen[seen.len() / 2].0;
            let band = 3.0 * depth_sigma(median) + 0.002;
            let kept: Vec<Vector2<f64>> = seen
                .iter()
                .filter(|(r, _)| (r - median).abs() <= band)
                .map(|(_, p)| *p)
                .collect();
            let count = kept.len() as f64;
            let mean = kept.iter().sum::<Vector2<f64>>() / count;
            let range = (mean - camera_at).norm();
            ranged.push((bin, range, mean, depth_sigma(range) / count.sqrt()));
        }
        // Each point's line: the neighbours two bearings either side on the same surface.
        for (i, &(bin, range, here, sigma)) in ranged.iter().enumerate() {
            let line: Vec<Vector2<f64>> = ranged[i.saturating_sub(2)..(i + 3).min(ranged.len())]
                .iter()
                .filter(|(b, r, _, _)| b.abs_diff(bin) <= 2 && near(range, *r))
                .map(|(_, _, p, _)| *p)
                .collect();
            if line.len() < 3 {
                continue;
            }
            let mean = line.iter().sum::<Vector2<f64>>() / line.len() as f64;
            let spread = line
                .iter()
                .map(|p| (p - mean) * (p - mean).transpose())
                .sum::<Matrix2<f64>>();
            let eigen = spread.symmetric_eigen();
            let k = if eigen.eigenvalues[0] < eigen.eigenvalues[1] {
                0
            } else {
                1
            };
            let mut normal = eigen.eigenvectors.column(k).into_owned();
            if normal.dot(&(camera_at - here)) < 0.0 {
                normal = -normal;
            }
            // The range's noise, across the line.
            let ray = (here - camera_at).normalize();
            scan.points.push(here);
            scan.normals.push(normal);
            scan.sigmas.push(sigma * normal.dot(&ray).abs().max(0.2));
        }
        scan
    }

    /// Points in the scan.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// No wall seen.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// A 2-D rotation by `angle`, and its derivative.
fn rotation(angle: f64) -> (Matrix2<f64>, Matrix2<f64>) {
    let (s, c) = angle.sin_cos();
    (Matrix2::new(c, -s, s, c), Matrix2::new(-s, -c, c, -s))
}

/// The previous scan's points by grid cell, to pair with.
struct Cells {
    size: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
}

impl Cells {
    fn new(points: &[Vector2<f64>], size: f64) -> Self {
        let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells.entry(Self::key(p, size)).or_default().push(i);
        }
        Self { size, cells }
    }

    fn key(p: &Vector2<f64>, size: f64) -> (i64, i64) {
        ((p.x / size).floor() as i64, (p.y / size).floor() as i64)
    }

    /// The indices of points in the cells round `p`.
    fn round(&self, p: &Vector2<f64>) -> impl Iterator<Item = usize> + '_ {
        let (i, j) = Self::key(p, self.size);
        (-1..=1)
            .flat_map(move |di| (-1..=1).map(move |dj| (i + di, j + dj)))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
    }
}

/// The body's motion between the frame at `since` (`previous`) and the one after it
/// (`current`), as far as their walls show it, starting from the IMU's turn between them
/// (`turn_guess`, anticlockwise, radians). `None` when the frames share too little wall, or
/// the registration lands where no drone moves in a frame.
pub fn register(
    since: f64,
    previous: &WallScan,
    current: &WallScan,
    turn_guess: f64,
    config: &DepthOdometryConfig,
) -> Option<DepthOdometry> {
    if previous.is_empty() || current.is_empty() || !turn_guess.is_finite() {
        return None;
    }
    let cells = Cells::new(&previous.points, config.match_m);
    let mut x = Vector3::new(0.0, 0.0, turn_guess);
    let mut solved = None;
    for _ in 0..config.iterations.max(1) {
        let (r, dr) = rotation(x.z);
        let t = x.xy();
        let mut h = Matrix3::zeros();
        let mut g = Vector3::zeros();
        // The same, every pair weighing one: the walls' geometry alone.
        let mut geometry = Matrix3::zeros();
        let (mut matches, mut squares) = (0usize, 0.0);
        for (i, p) in current.points.iter().enumerate() {
            let q = r * p + t;
            let n_here = r * current.normals[i];
            // Paired with the point nearest along its line, not nearest outright: the
            // nearest outright is the one whose noise brings it nearest, which reads part of
            // the motion toward a wall as none.
            let paired = cells
                .round(&q)
                .filter(|&j| previous.normals[j].dot(&n_here) >= config.min_normal_cos)
                .filter_map(|j| {
                    let (d, n) = (q - previous.points[j], previous.normals[j]);
                    let (across, along) = (n.dot(&d), n.perp(&d));
                    (across.abs() <= config.match_m && along.abs() <= config.match_m)
                        .then_some((j, along.abs()))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let Some((j, _)) = paired else { continue };
            let n = previous.normals[j];
            let sigma = previous.sigmas[j].hypot(current.sigmas[i]);
            let residual = n.dot(&(q - previous.points[j])) / sigma;
            let huber = if residual.abs() <= config.huber_sigmas {
                1.0
            } else {
                config.huber_sigmas / residual.abs()
            };
            let unit = Vector3::new(n.x, n.y, n.dot(&(dr * p)));
            let jac = unit / sigma;
            h += huber * jac * jac.transpose();
            g += huber * jac * residual;
            geometry += huber * unit * unit.transpose();
            matches += 1;
            squares += huber * residual * residual;
        }
        if matches < config.min_matches.max(4) {
            return None;
        }
        // A little damping holds what the walls do not constrain (along a lone wall) where
        // it started.
        let damping = 1e-9 * h.trace().max(1e-12);
        let step = (h + Matrix3::identity() * damping).cholesky()?.solve(&(-g));
        x += step;
        // Residuals larger than the depth's noise says widen the result.
        let spread = (squares / (matches - 3) as f64).sqrt().max(1.0);
        solved = Some((h, geometry, matches, spread));
        if step.xy().norm() < 1e-5 && step.z.abs() < 1e-6 {
            break;
        }
    }
    let (h, geometry, matches, spread) = solved?;
    let moved = x.xy();
    let turn = x.z;
    if moved.norm() > config.max_step_m
        || (turn - turn_guess).abs() > config.max_turn_correction_rad
    {
        return None;
    }
    // The directions the walls constrain, from their geometry once the turn is free (the
    // Schur complement); how well, from the same weighed by the depth's noise.
    let translation = |m: &Matrix3<f64>| {
        let (mt, mtr) = (
            m.fixed_view::<2, 2>(0, 0).into_owned(),
            m.fixed_view::<2, 1>(0, 2).into_owned(),
        );
        if m[(2, 2)] > 1e-12 {
            mt - mtr * mtr.transpose() / m[(2, 2)]
        } else {
            mt
        }
    };
    let (faced, information) = (translation(&geometry).symmetric_eigen(), translation(&h));
    let along = (0..2)
        .filter_map(|k| {
            let e = faced.eigenvectors.column(k).into_owned();
            let sigma = spread / e.dot(&(information * e)).max(1e-12).sqrt();
            (faced.eigenvalues[k] >= config.min_information && sigma <= config.max_sigma_m).then(
                || Along {
                    direction: [e.x, e.y],
                    displacement: e.dot(&moved),
                    sigma: sigma.max(config.min_sigma_m),
                },
            )
        })
        .collect();
    Some(DepthOdometry {
        since,
        along,
        turn_rad: turn,
        matches,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 320 × 240 Kinect-like camera looking along the body's x axis from 0.1 m ahead of its
    /// centre (optical frame: x right, y down, z forward).
    fn body_from_camera() -> Isometry3<f64> {
        Isometry3::from_parts(
            nalgebra::Translation3::new(0.1, 0.0, 0.0),
            UnitQuaternion::from_basis_unchecked(&[
                Vector3::new(0.0, -1.0, 0.0),
                Vector3::new(0.0, 0.0, -1.0),
                Vector3::new(1.0, 0.0, 0.0),
            ]),
        )
    }

    fn camera() -> Pinhole {
        Pinhole {
            fx: 262.5,
            fy: 262.5,
            cx: 159.5,
            cy: 119.5,
        }
    }

    /// The depth image (mm) of vertical walls, each a line `n · p = d` in the horizontal plane
    /// (normal `n` pointing at the body), with floor 0.9 m below the body and ceiling 1.6 m
    /// above it, seen by a level body at `position` (x, y) turned by `yaw`.
    fn render(walls: &[([f64; 2], f64)], position: [f64; 2], yaw: f64) -> Vec<u16> {
        render_tilted(walls, position, yaw, [0.0; 2])
    }

    fn scan(depth: &[u16], tilt: [f64; 2]) -> WallScan {
        WallScan::from_depth(
            depth,
            320,
            240,
            1e-3,
            &camera(),
            &body_from_camera(),
            tilt,
            &DepthOdometryConfig::default(),
        )
    }

    /// The displacement [`register`] measures along `direction` (body frame), if it measures
    /// that direction.
    fn measured(o: &DepthOdometry, direction: [f64; 2]) -> Option<f64> {
        o.along.iter().find_map(|a| {
            let cos = a.direction[0] * direction[0] + a.direction[1] * direction[1];
            (cos.abs() > 0.99).then(|| cos.signum() * a.displacement)
        })
    }

    #[test]
    fn a_blank_wall_ahead_measures_the_motion_toward_it_and_nothing_along_it() {
        // A wall 1.3 m ahead (the line x = 1.3, facing −x), the body moving 1.2 cm toward it
        // and 2 cm along it between frames, turning 1°.
        let wall = [([-1.0, 0.0], -1.3)];
        let before = scan(&render(&wall, [0.0, 0.0], 0.0), [0.0; 2]);
        let after = scan(&render(&wall, [0.012, 0.02], 1f64.to_radians()), [0.0; 2]);
        assert!(before.len() > 100, "{} scan points", before.len());
        let config = DepthOdometryConfig::default();
        let o =
            register(0.0, &before, &after, 1f64.to_radians(), &config).expect("the wall registers");
        assert_eq!(o.along.len(), 1, "{:?}", o.along);
        let toward = measured(&o, [1.0, 0.0]).expect("measured toward the wall");
        assert!((toward - 0.012).abs() < 0.001, "{toward}");
        assert!(o.along[0].sigma <= 0.005, "{:?}", o.along);
        assert!((o.turn_rad - 1f64.to_radians()).abs() < 0.2f64.to_radians());
        // The IMU's turn 2° off: the wall's own direction puts it right.
        let o = register(0.0, &before, &after, 3f64.to_radians(), &config).expect("registers");
        let toward = measured(&o, [1.0, 0.0]).expect("measured toward the wall");
        assert!((toward - 0.012).abs() < 0.001, "{toward}");
    }

    #[test]
    fn a_corner_measures_the_whole_motion_and_a_tilt_is_levelled() {
        // A wall ahead and one to the left; the body moves 1 cm forward and 1.5 cm right,
        // and is tilted 4° nose down and 3° right at the second frame.
        let walls = [([-1.0, 0.0], -1.5), ([0.0, -1.0], -0.8)];
        let before = scan(&render(&walls, [0.0, 0.0], 0.3), [0.0; 2]);
        let tilt = [3f64.to_radians(), 4f64.to_radians()];
        let depth = render_tilted(&walls, [0.01, -0.015], 0.3, tilt);
        let after = scan(&depth, tilt);
        let o = register(0.0, &before, &after, 0.0, &DepthOdometryConfig::default())
            .expect("registers");
        assert_eq!(o.along.len(), 2, "{:?}", o.along);
        // Directions in the body at the first frame, turned 0.3 in the map.
        let (s, c) = 0.3f64.sin_cos();
        let moved = [c * 0.01 + s * -0.015, -s * 0.01 + c * -0.015];
        let off = |o: &DepthOdometry| {
            let got = o.displacement();
            (got[0] - moved[0]).hypot(got[1] - moved[1])
        };
        assert!(off(&o) < 0.002, "{o:?} against {moved:?}");
        // Not levelled, the tilt bends the walls and the registration goes wrong or gives up.
        let unlevelled = scan(&depth, [0.0; 2]);
        let wrong = register(
            0.0,
            &before,
            &unlevelled,
            0.0,
            &DepthOdometryConfig::default(),
        );
        assert!(!wrong.is_some_and(|o| o.along.len() == 2 && off(&o) < 0.002));
    }

    /// [`render`] from a body tilted by `tilt` (roll, pitch).
    fn render_tilted(
        walls: &[([f64; 2], f64)],
        position: [f64; 2],
        yaw: f64,
        tilt: [f64; 2],
    ) -> Vec<u16> {
        let c = camera();
        let map_from_body = Isometry3::from_parts(
            nalgebra::Translation3::new(position[0], position[1], 0.0),
            UnitQuaternion::from_euler_angles(tilt[0], tilt[1], yaw),
        );
        let map_from_camera = map_from_body * body_from_camera();
        let origin = map_from_camera.translation.vector;
        let mut depth = vec![0u16; 320 * 240];
        for v in 0..240 {
            for u in 0..320 {
                let ray_in_camera =
                    Vector3::new((u as f64 - c.cx) / c.fx, (v as f64 - c.cy) / c.fy, 1.0);
                let ray = map_from_camera.rotation * ray_in_camera;
                let mut s = f64::INFINITY;
                for (n, d) in walls {
                    let along = -(n[0] * ray.x + n[1] * ray.y);
                    if along > 1e-9 {
                        s = s.min((n[0] * origin.x + n[1] * origin.y - d) / along);
                    }
                }
                for (plane, sign) in [(-0.9, -1.0), (1.6, 1.0)] {
                    if ray.z * sign > 1e-9 {
                        s = s.min((plane - origin.z) / ray.z);
                    }
                }
                if s.is_finite() && s > 0.0 && s <= 4.0 {
                    // The ray's optical-axis component is 1: s is the depth.
                    depth[v * 320 + u] = (s * 1000.0).round() as u16;
                }
            }
        }
        depth
    }

    #[test]
    fn a_turn_the_imu_misjudges_is_put_right_by_the_walls() {
        // In a room, moving 1 cm forward and 1.5 cm right while turning up to 3.6° a frame,
        // with the IMU's turn up to 3.6° off (its heading is sampled at the control rate, and
        // a frame can read the sample before): the turn and the motion are measured alike.
        let walls = [
            ([-1.0, 0.0], -1.5),
            ([0.0, -1.0], -0.8),
            ([1.0, 0.0], -2.0),
            ([0.0, 1.0], -2.5),
        ];
        let before = scan(&render(&walls, [0.0, 0.0], 0.3), [0.0; 2]);
        let (s, c) = 0.3f64.sin_cos();
        let moved = [c * 0.01 + s * -0.015, -s * 0.01 + c * -0.015];
        let config = DepthOdometryConfig::default();
        for (turn, guess) in [
            (2.0f64, 0.0f64),
            (0.0, 2.0),
            (3.6, 0.0),
            (3.6, 7.2),
            (-3.6, 0.0),
        ] {
            let turned = 0.3 + turn.to_radians();
            let after = scan(&render(&walls, [0.01, -0.015], turned), [0.0; 2]);
            let o = register(0.0, &before, &after, guess.to_radians(), &config).expect("registers");
            assert!(
                (o.turn_rad.to_degrees() - turn).abs() < 0.05,
                "{turn}°: {o:?}"
            );
            assert_eq!(o.along.len(), 2, "{turn}°: {o:?}");
            for a in &o.along {
                let truth = a.direction[0] * moved[0] + a.direction[1] * moved[1];
                assert!((a.displacement - truth).abs() < 0.001, "{turn}°: {a:?}");
            }
        }
    }

    #[test]
    fn floor_and_ceiling_are_not_walls_and_bad_input_measures_nothing() {
        // Nothing but floor and ceiling in view (no wall within 4 m).
        let open = scan(&render(&[], [0.0, 0.0], 0.0), [0.0; 2]);
        assert!(open.is_empty(), "{} points", open.len());
        let config = DepthOdometryConfig::default();
        let wall = [([-1.0, 0.0], -1.3)];
        let seen = scan(&render(&wall, [0.0, 0.0], 0.0), [0.0; 2]);
        assert!(register(0.0, &open, &seen, 0.0, &config).is_none());
        assert!(register(0.0, &seen, &seen, f64::NAN, &config).is_none());
        // An image of the wrong size, or no focal length: no points.
        let depth = render(&wall, [0.0, 0.0], 0.0);
        let c = camera();
        let b = body_from_camera();
        assert!(WallScan::from_depth(&depth, 320, 200, 1e-3, &c, &b, [0.0; 2], &config).is_empty());
        let flat = Pinhole { fx: 0.0, ..c };
        assert!(
            WallScan::from_depth(&depth, 320, 240, 1e-3, &flat, &b, [0.0; 2], &config).is_empty()
        );
        // A step no drone makes in a frame (0.3 m) is refused.
        let far = scan(&render(&wall, [0.3, 0.0], 0.0), [0.0; 2]);
        assert!(register(0.0, &seen, &far, 0.0, &config).is_none());
    }
}
