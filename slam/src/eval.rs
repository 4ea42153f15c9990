//! Trajectory accuracy as the TUM RGB-D benchmark measures it: absolute trajectory error (RMSE after
//! aligning the estimate to the ground truth with SE(3) or Sim(3)) and relative pose error.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::system::LoopClosure;
use crate::trajectory::Stamped;

/// TUM's association rule: every (ground truth, estimate) pair closer in time than
/// `max_difference` seconds, best first, each timestamp used once. Returns index pairs sorted by
/// ground-truth time.
pub fn associate(gt: &[Stamped], est: &[Stamped], max_difference: f64) -> Vec<(usize, usize)> {
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (j, e) in est.iter().enumerate() {
        // gt is sorted: only a window of it can be close enough.
        let lo = gt.partition_point(|g| g.t <= e.t - max_difference);
        for (i, g) in gt.iter().enumerate().skip(lo) {
            let d = (g.t - e.t).abs();
            if g.t - e.t >= max_difference {
                break;
            }
            if d < max_difference {
                candidates.push((d, i, j));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let (mut gt_used, mut est_used) = (vec![false; gt.len()], vec![false; est.len()]);
    let mut pairs = Vec::new();
    for (_, i, j) in candidates {
        if !gt_used[i] && !est_used[j] {
            gt_used[i] = true;
            est_used[j] = true;
            pairs.push((i, j));
        }
    }
    pairs.sort();
    pairs
}

/// How the estimate is aligned to the ground truth before measuring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Alignment {
    /// Rotation and translation (Horn's method, as TUM's `evaluate_ate.py`).
    Se3,
    /// Rotation, translation and scale (Umeyama), for monocular estimates.
    Sim3,
}

/// The transform `data ≈ s·R·model + t` minimising the squared error (Umeyama 1991; with
/// `with_scale = false`, Horn's method). Returns (R, t, s).
pub fn align(
    model: &[Point3<f64>],
    data: &[Point3<f64>],
    with_scale: bool,
) -> (Rotation3<f64>, Vector3<f64>, f64) {
    let n = model.len().min(data.len()).max(1) as f64;
    let mu_m = model.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mu_d = data.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mut cov = Matrix3::zeros();
    let mut var_m = 0.0;
    for (m, d) in model.iter().zip(data) {
        let (mc, dc) = (m.coords - mu_m, d.coords - mu_d);
        cov += dc * mc.transpose();
        var_m += mc.norm_squared();
    }
    cov /= n;
    var_m /= n;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (Rotation3::identity(), mu_d - mu_m, 1.0);
    };
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let r = u * s * v_t;
    let scale = if with_scale && var_m > 0.0 {
        (svd.singular_values.component_mul(&s.diagonal())).sum() / var_m
    } else {
        1.0
    };
    let t = mu_d - scale * r * mu_m;
    (Rotation3::from_matrix_unchecked(r), t, scale)
}

/// Absolute trajectory error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ate {
    /// Root mean square of the position errors, metres.
    pub rmse_m: f64,
    /// Mean, metres.
    pub mean_m: f64,
    /// Largest, metres.
    pub max_m: f64,
    /// Pairs compared.
    pub pairs: usize,
    /// Scale found (1 for SE(3)).
    pub scale: f64,
}

/// ATE of `est` against `gt` with TUM's association (`max_difference` 0.02 s by default).
pub fn ate(
    gt: &[Stamped],
    est: &[Stamped],
    alignment: Alignment,
    max_difference: f64,
) -> Option<Ate> {
    let pairs = associate(gt, est, max_difference);
    if pairs.len() < 3 {
        return None;
    }
    let data: Vec<Point3<f64>> = pairs
        .iter()
        .map(|&(i, _)| gt[i].pose.translation.vector.into())
        .collect();
    let model: Vec<Point3<f64>> = pairs
        .iter()
        .map(|&(_, j)| est[j].pose.translation.vector.into())
        .collect();
    let (r, t, s) = align(&model, &data, alignment == Alignment::Sim3);
    let errors: Vec<f64> = model
        .iter()
        .zip(&data)
        .map(|(m, d)| (s * (r * m.coords) + t - d.coords).norm())
        .collect();
    let n = errors.len() as f64;
    Some(Ate {
        rmse_m: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        mean_m: errors.iter().sum::<f64>() / n,
        max_m: errors.iter().copied().fold(0.0, f64::max),
        pairs: errors.len(),
        scale: s,
    })
}

/// Relative pose error over a fixed interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rpe {
    /// RMSE of the translational drift over the interval, metres.
    pub trans_rmse_m: f64,
    /// RMSE of the rotational drift over the interval, degrees.
    pub rot_rmse_deg: f64,
    /// Intervals compared.
    pub pairs: usize,
}

/// The interval RPE is measured over.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Delta {
    /// Seconds (TUM's `--delta 1 --delta_unit s` gives drift per second).
    Seconds(f64),
    /// Consecutive associated frames.
    Frames(usize),
}

/// RPE of `est` against `gt`: for every associated pose and the one `delta` later, the error of the
/// estimated motion against the true motion.
pub fn rpe(gt: &[Stamped], est: &[Stamped], delta: Delta, max_difference: f64) -> Option<Rpe> {
    let pairs = associate(gt, est, max_difference);
    let mut trans = Vec::new();
    let mut rot = Vec::new();
    for (k, &(i, j)) in pairs.iter().enumerate() {
        let l = match delta {
            Delta::Frames(n) => k + n.max(1),
            Delta::Seconds(s) => {
                let target = est[j].t + s;
                k + pairs[k..].partition_point(|&(_, jj)| est[jj].t < target)
            }
        };
        let Some(&(i2, j2)) = pairs.get(l) else { break };
        let gt_motion: Isometry3<f64> = gt[i].pose.inverse() * gt[i2].pose;
        let est_motion: Isometry3<f64> = est[j].pose.inverse() * est[j2].pose;
        let e = gt_motion.inverse() * est_motion;
        trans.push(e.translation.vector.norm());
        rot.push(e.rotation.angle().to_degrees());
    }
    if trans.is_empty() {
        return None;
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    Some(Rpe {
        trans_rmse_m: rms(&trans),
        rot_rmse_deg: rms(&rot),
        pairs: trans.len(),
    })
}

/// How far each loop closure's measured relative pose lies from the true one: (metres,
/// radians), `None` where `truth` (per robot, camera poses) has no pose within
/// `max_difference` seconds of a keyframe. A correct closure is off by a registration's error
/// (centimetres); a look-alike place matched by mistake is off by decimetres or more.
pub fn loop_closure_errors(
    closures: &[LoopClosure],
    truth: &[Vec<Stamped>],
    max_difference: f64,
) -> Vec<Option<(f64, f64)>> {
    let at = |robot: usize, t: f64| {
        let track = truth.get(robot)?;
        let i = track.partition_point(|s| s.t < t);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|i| track.get(i))
            .filter(|s| (s.t - t).abs() <= max_difference)
            .min_by(|x, y| (x.t - t).abs().total_cmp(&(y.t - t).abs()))
            .map(|s| s.pose)
    };
    closures
        .iter()
        .map(|c| {
            let a = at(c.robots.0, c.stamps.0)?;
            let b = at(c.robots.1, c.stamps.1)?;
            let off = (a.inverse() * b).inverse() * c.a_from_b;
            Some((off.translation.vector.norm(), off.rotation.angle()))
        })
        .collect()
}

/// A pose from translation and rotation, for tests and tools.
pub fn pose(t: [f64; 3], r: UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::read_tum;
    use std::path::PathBuf;

    fn data(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/rgbd/tum_fr1_xyz_trajectories")
            .join(name)
    }

    #[test]
    fn reproduces_tums_figure_for_rgbdslam_on_fr1_xyz() {
        let gt = read_tum(data("freiburg1_xyz-groundtruth.txt")).unwrap();
        let est = read_tum(data("freiburg1_xyz-rgbdslam.txt")).unwrap();
        let a = ate(&gt, &est, Alignment::Se3, 0.02).unwrap();
        // TUM's evaluate_ate.py: 0.0135 m over 786 pairs.
        assert_eq!(a.pairs, 786);
        assert!((a.rmse_m - 0.0135).abs() < 0.00005, "{}", a.rmse_m);
        let r = rpe(&gt, &est, Delta::Seconds(1.0), 0.02).unwrap();
        assert!(
            r.trans_rmse_m > 0.0 && r.trans_rmse_m < 0.1 && r.rot_rmse_deg < 10.0,
            "{r:?}"
        );
    }

    #[test]
    fn a_transformed_copy_has_no_error_and_sim3_finds_the_scale() {
        let gt: Vec<Stamped> = (0..50)
            .map(|k| {
                let a = k as f64 * 0.1;
                Stamped {
                    t: k as f64 * 0.1,
                    pose: pose(
                        [a.cos(), a.sin(), 0.1 * a],
                        UnitQuaternion::from_euler_angles(0.0, 0.0, a),
                    ),
                }
            })
            .collect();
        let moved = pose(
            [3.0, -1.0, 2.0],
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
        );
        let est: Vec<Stamped> = gt
            .iter()
            .map(|s| Stamped {
                t: s.t + 0.001,
                pose: moved * s.pose,
            })
            .collect();
        assert!(ate(&gt, &est, Alignment::Se3, 0.02).unwrap().rmse_m < 1e-9);
        let r = rpe(&gt, &est, Delta::Frames(1), 0.02).unwrap();
        assert!(r.trans_rmse_m < 1e-9 && r.rot_rmse_deg < 1e-6 && r.pairs == 49);
        let scaled: Vec<Stamped> = gt
            .iter()
            .map(|s| Stamped {
                t: s.t,
                pose: pose((s.pose.translation.vector * 0.5).into(), s.pose.rotation),
            })
            .collect();
        let a = ate(&gt, &scaled, Alignment::Sim3, 0.02).unwrap();
        assert!(a.rmse_m < 1e-9 && (a.scale - 2.0).abs() < 1e-9, "{a:?}");
        assert!(ate(&gt, &scaled, Alignment::Se3, 0.02).unwrap().rmse_m > 0.1);
    }

    #[test]
    fn a_loop_closure_is_scored_against_the_true_relative_pose() {
        // Both robots fly along x, 1 m/s; robot 1 flies 2 m to the side of robot 0.
        let track = |y: f64| -> Vec<Stamped> {
            (0..10)
                .map(|k| Stamped {
                    t: k as f64,
                    pose: pose([k as f64, y, 0.0], UnitQuaternion::identity()),
                })
                .collect()
        };
        let truth = [track(0.0), track(2.0)];
        let closure = |b_in_a: [f64; 3], stamps: (f64, f64)| LoopClosure {
            robots: (0, 1),
            stamps,
            a_from_b: pose(b_in_a, UnitQuaternion::identity()),
            alive: true,
        };
        // Keyframe at t = 2 (x = 2) and t = 5 (x = 5, y = 2): b lies at (3, 2, 0) in a.
        let scored = loop_closure_errors(
            &[
                closure([3.0, 2.0, 0.0], (2.0, 5.0)),
                closure([3.0, 1.5, 0.0], (2.0, 5.0)),
                closure([3.0, 2.0, 0.0], (2.0, 50.0)),
            ],
            &truth,
            0.01,
        );
        let (t, r) = scored[0].unwrap();
        assert!(t < 1e-12 && r < 1e-12);
        let (t, _) = scored[1].unwrap();
        assert!((t - 0.5).abs() < 1e-12, "{t}");
        assert_eq!(scored[2], None, "no truth at t = 50");
    }

    #[test]
    fn association_takes_best_pairs_once() {
        let at = |t: f64| Stamped {
            t,
            pose: Isometry3::identity(),
        };
        let gt = [at(0.0), at(1.0), at(1.015)];
        let est = [at(1.01), at(5.0)];
        assert_eq!(associate(&gt, &est, 0.02), vec![(2, 0)]);
    }
}
