//! Localisation without features: the depth image's points at wall height, placed by a
//! predicted pose, matched in 2D against the walls of the occupancy map around it (correlative
//! scan matching, Olson 2009). It is for the moments the visual tracking loses the map — a bare
//! wall, a door into a room deeper than the camera sees — when what the depth still sees of
//! mapped walls says where the vehicle is, at least across them.
//!
//! Every translation (and a few headings) within a window around the prediction is scored by how
//! close its points fall to mapped walls; the scores become weights, and the weighted mean and
//! covariance of the candidates are the fix. In front of one wall the weights are flat along it:
//! the covariance says the position is known across the wall only, and the filter takes exactly
//! that.

use nalgebra::{Isometry3, Point3, Vector2};

use crate::occupancy::{DepthImage, VoxelMap, depth_cloud};

/// How the scan is matched.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanMatchConfig {
    /// Step of the translation search, metres.
    pub step_m: f64,
    /// Headings searched either side of the prediction, radians (the IMU's heading is good to
    /// about a degree; a degree is 7 cm at 4 m).
    pub yaw_search: f64,
    /// Step of the heading search, radians.
    pub yaw_step: f64,
    /// How far a point may lie from a wall and still count, metres (the likelihood's σ).
    pub sigma_m: f64,
    /// Use every n-th depth pixel each way.
    pub pixel_step: usize,
    /// At most this many points are scored (evenly chosen).
    pub max_points: usize,
    /// Fewest points at wall height for a match.
    pub min_points: usize,
    /// The best pose's mean likelihood must reach this: that share of the points (about) lies
    /// on mapped walls.
    pub min_matched: f64,
    /// Sharpness of the weights: a candidate whose mean likelihood is `1/sharpness` below the
    /// best weighs e⁻¹ as much.
    pub sharpness: f64,
    /// Added to the fix's variance each way (the map's own error and resolution), m².
    pub floor_variance: f64,
    /// A direction whose spread (before `floor_variance`) exceeds this is left unknown, metres.
    pub max_sigma_m: f64,
}

impl Default for ScanMatchConfig {
    fn default() -> Self {
        Self {
            step_m: 0.025,
            yaw_search: 2f64.to_radians(),
            yaw_step: 1f64.to_radians(),
            sigma_m: 0.07,
            pixel_step: 6,
            max_points: 400,
            min_points: 40,
            min_matched: 0.5,
            sharpness: 30.0,
            floor_variance: 0.06 * 0.06,
            max_sigma_m: 0.06,
        }
    }
}

/// The position known along one direction: `axis · position` has the variance `variance`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Along {
    /// A unit vector in the map's horizontal plane.
    pub axis: [f64; 2],
    /// Variance of the position along it, m².
    pub variance: f64,
}

/// A body position from a scan match.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanFix {
    /// The body's horizontal position in the map, metres.
    pub position: [f64; 2],
    /// The body's heading in the map, radians.
    pub yaw: f64,
    /// The directions along which the walls in view fix the position (one in front of a single
    /// wall, two at a corner); along any other, `position` is the prediction's.
    pub known: Vec<Along>,
    /// Mean likelihood of the points at the best pose (0–1).
    pub matched: f64,
    /// Points scored.
    pub points: usize,
}

/// Why a scan gave no fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoFix {
    /// The depth image saw too little at wall height.
    #[error("{points} depth points at wall height, {needed} needed")]
    TooFewPoints {
        /// Points found.
        points: usize,
        /// Points needed.
        needed: usize,
    },
    /// No pose in the window puts enough of the points on mapped walls.
    #[error("best match puts {matched:.2} of the points on mapped walls, {needed:.2} needed")]
    Weak {
        /// The best mean likelihood.
        matched: f64,
        /// The least accepted.
        needed: f64,
    },
    /// The walls in view fix no direction (or the best pose is at the window's edge).
    #[error("the walls in view do not fix the position")]
    Flat,
}

/// Matches the depth image `image`, taken from a camera at `body_from_camera` on a body
/// predicted at `map_from_body`, against the walls of `map`, searching translations within
/// `search_m` of the prediction.
pub fn match_depth(
    map: &VoxelMap,
    image: &DepthImage<'_>,
    map_from_body: &Isometry3<f64>,
    body_from_camera: &Isometry3<f64>,
    search_m: f64,
    config: &ScanMatchConfig,
) -> Result<ScanFix, NoFix> {
    let occupancy = map.config();
    let map_from_camera = map_from_body * body_from_camera;
    let body = map_from_body.translation.vector.xy();
    let at_wall_height: Vec<Vector2<f64>> =
        depth_cloud(image, config.pixel_step, occupancy.max_range)
            .iter()
            .map(|p| map_from_camera * Point3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z)))
            .filter(|p| (occupancy.occupancy_min_z..=occupancy.occupancy_max_z).contains(&p.z))
            .map(|p| p.coords.xy() - body)
            .collect();
    if at_wall_height.len() < config.min_points {
        return Err(NoFix::TooFewPoints {
            points: at_wall_height.len(),
            needed: config.min_points,
        });
    }
    let every = at_wall_height.len().div_ceil(config.max_points.max(1));
    let offsets: Vec<Vector2<f64>> = at_wall_height.into_iter().step_by(every).collect();
    let search = search_m.max(config.step_m);
    let field = Field::around(
        map,
        body,
        &offsets,
        search + 3.0 * config.sigma_m,
        config.sigma_m,
    );

    let steps = (search / config.step_m).round() as i32;
    let yaw_steps = (config.yaw_search / config.yaw_step.max(1e-6)).round() as i32;
    // (translation, heading offset, mean likelihood) of every candidate.
    let mut candidates =
        Vec::with_capacity(((2 * steps + 1).pow(2) * (2 * yaw_steps + 1)) as usize);
    for k in -yaw_steps..=yaw_steps {
        let dyaw = f64::from(k) * config.yaw_step;
        let rotation = nalgebra::Rotation2::new(dyaw);
        let turned: Vec<Vector2<f64>> = offsets.iter().map(|o| body + rotation * o).collect();
        for i in -steps..=steps {
            for j in -steps..=steps {
                let d = Vector2::new(f64::from(i), f64::from(j)) * config.step_m;
                let sum: f64 = turned.iter().map(|p| field.at(p + d)).sum();
                candidates.push((d, dyaw, sum / turned.len() as f64));
            }
        }
    }
    let (best, _, matched) = candidates
        .iter()
        .copied()
        .max_by(|a, b| a.2.total_cmp(&b.2))
        .ok_or(NoFix::Flat)?;
    if matched < config.min_matched {
        return Err(NoFix::Weak {
            matched,
            needed: config.min_matched,
        });
    }
    // Weighted mean and covariance over all candidates.
    let (mut total, mut mean, mut mean_yaw) = (0.0, Vector2::zeros(), 0.0);
    for &(d, dyaw, m) in &candidates {
        let w = (config.sharpness * (m - matched)).exp();
        total += w;
        mean += d * w;
        mean_yaw += dyaw * w;
    }
    mean /= total;
    mean_yaw /= total;
    let mut cov = nalgebra::Matrix2::zeros();
    for &(d, _, m) in &candidates {
        let w = (config.sharpness * (m - matched)).exp();
        let e = d - mean;
        cov += e * e.transpose() * (w / total);
    }
    // Along a direction whose spread is that of the window itself, nothing is known.
    let eigen = nalgebra::SymmetricEigen::new(cov);
    let window_variance = search * search / 3.0;
    let mut known = vec![];
    let mut correction = Vector2::zeros();
    for i in 0..2 {
        let variance = eigen.eigenvalues[i];
        if variance > 0.5 * window_variance || variance > config.max_sigma_m.powi(2) {
            continue;
        }
        let axis: Vector2<f64> = eigen.eigenvectors.column(i).into_owned();
        // The best pose at the window's edge in this direction: the truth may lie beyond.
        if best.dot(&axis).abs() > search - 0.5 * config.step_m {
            return Err(NoFix::Flat);
        }
        correction += axis * axis.dot(&mean);
        known.push(Along {
            axis: [axis.x, axis.y],
            variance: variance + config.floor_variance,
        });
    }
    if known.is_empty() {
        return Err(NoFix::Flat);
    }
    let position = body + correction;
    let (_, _, yaw) = map_from_body.rotation.euler_angles();
    Ok(ScanFix {
        position: [position.x, position.y],
        yaw: yaw + mean_yaw,
        known,
        matched,
        points: offsets.len(),
    })
}

/// How likely a point is on a mapped wall, over a window of the 2D grid.
struct Field {
    /// The grid cell of the window's first value.
    lo: [i32; 2],
    width: i32,
    height: i32,
    resolution: f64,
    values: Vec<f32>,
}

impl Field {
    /// The field over the walls of `map` around `centre` and its points' `offsets`, `margin`
    /// metres beyond them.
    fn around(
        map: &VoxelMap,
        centre: Vector2<f64>,
        offsets: &[Vector2<f64>],
        margin: f64,
        sigma: f64,
    ) -> Self {
        let r = map.config().resolution;
        let (mut min, mut max) = (centre, centre);
        for o in offsets {
            min = min.inf(&(centre + o));
            max = max.sup(&(centre + o));
        }
        let cell = |v: f64| (v / r).floor() as i32;
        let lo = [cell(min.x - margin), cell(min.y - margin)];
        let hi = [cell(max.x + margin) + 1, cell(max.y + margin) + 1];
        let (width, height) = (hi[0] - lo[0], hi[1] - lo[1]);
        let counts = map.band_counts(lo, hi);
        let min_voxels = map.config().occupied_min_voxels.max(1);
        let mut values = vec![0f32; counts.len()];
        let reach = (3.0 * sigma / r).ceil() as i32;
        for (i, &n) in counts.iter().enumerate() {
            if usize::from(n) < min_voxels {
                continue;
            }
            let (x, y) = (i as i32 % width, i as i32 / width);
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let (u, v) = (x + dx, y + dy);
                    if u < 0 || v < 0 || u >= width || v >= height {
                        continue;
                    }
                    let d2 = f64::from(dx * dx + dy * dy) * r * r;
                    let l = (-d2 / (2.0 * sigma * sigma)).exp() as f32;
                    let value = &mut values[(v * width + u) as usize];
                    *value = value.max(l);
                }
            }
        }
        Self {
            lo,
            width,
            height,
            resolution: r,
            values,
        }
    }

    /// The likelihood at a point, interpolated between cell centres (0 outside the window).
    fn at(&self, p: Vector2<f64>) -> f64 {
        let u = p.x / self.resolution - 0.5 - f64::from(self.lo[0]);
        let v = p.y / self.resolution - 0.5 - f64::from(self.lo[1]);
        let (u0, v0) = (u.floor(), v.floor());
        let (fu, fv) = (u - u0, v - v0);
        let (u0, v0) = (u0 as i32, v0 as i32);
        let value = |x: i32, y: i32| {
            if x < 0 || y < 0 || x >= self.width || y >= self.height {
                0.0
            } else {
                f64::from(self.values[(y * self.width + x) as usize])
            }
        };
        value(u0, v0) * (1.0 - fu) * (1.0 - fv)
            + value(u0 + 1, v0) * fu * (1.0 - fv)
            + value(u0, v0 + 1) * (1.0 - fu) * fv
            + value(u0 + 1, v0 + 1) * fu * fv
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

    use super::*;
    use crate::occupancy::OccupancyConfig;

    const W: usize = 160;
    const H: usize = 120;
    const INTRINSICS: [f64; 4] = [120.0, 120.0, 80.0, 60.0];

    /// The camera looking along the body's x axis (optical: x right, y down, z forward).
    fn body_from_camera() -> Isometry3<f64> {
        let r = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
        Isometry3::from_parts(
            Translation3::new(0.1, 0.0, 0.0),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        )
    }

    fn body(x: f64, y: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::new(Vector3::new(x, y, 1.0), Vector3::z() * yaw)
    }

    /// The depth image (millimetres) seen from inside the box `lo..hi` (floor to ceiling at
    /// 2.5 m) by a body at `map_from_body`.
    fn render(lo: [f64; 2], hi: [f64; 2], map_from_body: &Isometry3<f64>) -> Vec<u16> {
        let map_from_camera = map_from_body * body_from_camera();
        let o = map_from_camera.translation.vector;
        let (lo, hi) = ([lo[0], lo[1], 0.0], [hi[0], hi[1], 2.5]);
        let [fx, fy, cx, cy] = INTRINSICS;
        let mut depth = vec![0u16; W * H];
        for v in 0..H {
            for u in 0..W {
                let ray = Vector3::new((u as f64 - cx) / fx, (v as f64 - cy) / fy, 1.0);
                let d = map_from_camera.rotation * ray;
                let t = (0..3)
                    .filter(|&k| d[k].abs() > 1e-12)
                    .map(|k| ((if d[k] > 0.0 { hi[k] } else { lo[k] }) - o[k]) / d[k])
                    .fold(f64::INFINITY, f64::min);
                depth[v * W + u] = (t * 1000.0).round().min(65535.0) as u16;
            }
        }
        depth
    }

    fn image(depth: &[u16]) -> DepthImage<'_> {
        DepthImage {
            width: W,
            height: H,
            depth,
            depth_scale: 0.001,
            intrinsics: INTRINSICS,
        }
    }

    /// A map of the box built from views at `poses`.
    fn mapped(lo: [f64; 2], hi: [f64; 2], poses: &[Isometry3<f64>]) -> VoxelMap {
        let mut map = VoxelMap::new(OccupancyConfig::default());
        for pose in poses {
            let depth = render(lo, hi, pose);
            map.insert_depth(&image(&depth), &(pose * body_from_camera()));
        }
        map
    }

    fn four_ways(x: f64, y: f64) -> Vec<Isometry3<f64>> {
        (0..8)
            .map(|k| body(x, y, f64::from(k) * std::f64::consts::FRAC_PI_4))
            .collect()
    }

    #[test]
    fn a_corner_in_view_fixes_the_position_both_ways() {
        let (lo, hi) = ([0.0, 0.0], [6.0, 4.0]);
        let map = mapped(lo, hi, &[four_ways(2.0, 2.0), four_ways(4.0, 2.0)].concat());
        let truth = body(3.0, 2.2, 0.54);
        let depth = render(lo, hi, &truth);
        let predicted = body(3.15, 2.08, 0.54 + 1f64.to_radians());
        let config = ScanMatchConfig::default();
        let fix = match_depth(
            &map,
            &image(&depth),
            &predicted,
            &body_from_camera(),
            0.4,
            &config,
        )
        .expect("a fix");
        let err = (fix.position[0] - 3.0).hypot(fix.position[1] - 2.2);
        assert!(err < 0.03, "{fix:?}");
        assert!((fix.yaw - 0.54).abs() < 1.5f64.to_radians(), "{fix:?}");
        assert_eq!(fix.known.len(), 2, "{fix:?}");
        for along in &fix.known {
            let sigma = along.variance.sqrt();
            assert!((0.02..0.1).contains(&sigma), "σ {sigma}: {fix:?}");
        }
        assert!(fix.matched > 0.5, "{fix:?}");
    }

    #[test]
    fn one_wall_in_view_fixes_the_position_across_it_only() {
        // A corridor along x; the camera faces its side wall from 1 m.
        let (lo, hi) = ([0.0, 0.0], [20.0, 2.0]);
        let poses: Vec<_> = (1..10)
            .flat_map(|k| four_ways(f64::from(k) * 2.0, 1.0))
            .collect();
        let map = mapped(lo, hi, &poses);
        let truth = body(8.0, 1.0, std::f64::consts::FRAC_PI_2);
        let depth = render(lo, hi, &truth);
        let predicted = body(8.2, 0.85, std::f64::consts::FRAC_PI_2);
        let fix = match_depth(
            &map,
            &image(&depth),
            &predicted,
            &body_from_camera(),
            0.4,
            &ScanMatchConfig::default(),
        )
        .expect("a fix across the wall");
        assert!((fix.position[1] - 1.0).abs() < 0.03, "{fix:?}");
        assert_eq!(fix.known.len(), 1, "{fix:?}");
        let along = fix.known[0];
        assert!(along.axis[1].abs() > 0.99, "across the corridor: {fix:?}");
        assert!(along.variance.sqrt() < 0.1, "{fix:?}");
        assert!(
            (fix.position[0] - 8.2).abs() < 0.01,
            "along, the prediction: {fix:?}"
        );
    }

    #[test]
    fn unmapped_walls_and_empty_images_give_no_fix() {
        let (lo, hi) = ([0.0, 0.0], [6.0, 4.0]);
        let truth = body(3.0, 2.0, 0.0);
        let depth = render(lo, hi, &truth);
        let config = ScanMatchConfig::default();
        let empty = VoxelMap::new(OccupancyConfig::default());
        let got = match_depth(
            &empty,
            &image(&depth),
            &truth,
            &body_from_camera(),
            0.3,
            &config,
        );
        assert!(matches!(got, Err(NoFix::Weak { .. })), "{got:?}");
        let map = mapped(lo, hi, &four_ways(3.0, 2.0));
        let blank = vec![0u16; W * H];
        let got = match_depth(
            &map,
            &image(&blank),
            &truth,
            &body_from_camera(),
            0.3,
            &config,
        );
        assert_eq!(
            got,
            Err(NoFix::TooFewPoints {
                points: 0,
                needed: config.min_points
            })
        );
        // A prediction half a metre off with a window of 0.3 m: the best pose is at the
        // window's edge, no fix.
        let off = body(3.5, 2.0, 0.0);
        let got = match_depth(
            &map,
            &image(&depth),
            &off,
            &body_from_camera(),
            0.3,
            &config,
        );
        assert!(got.is_err(), "{got:?}");
    }
}
