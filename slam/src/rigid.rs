//! Rigid motion between two sets of matched 3D points: closed form (Horn/Umeyama, without scale)
//! and RANSAC over three-point samples with a final fit on every inlier.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// `T` minimising Σ‖dst − T·src‖² (Umeyama 1991 without scale); `None` for fewer than three
/// points or a degenerate set.
pub fn fit(src: &[Point3<f64>], dst: &[Point3<f64>]) -> Option<Isometry3<f64>> {
    let n = src.len().min(dst.len());
    if n < 3 {
        return None;
    }
    let centroid =
        |p: &[Point3<f64>]| p[..n].iter().fold(Vector3::zeros(), |a, q| a + q.coords) / n as f64;
    let (cs, cd) = (centroid(src), centroid(dst));
    let mut h = Matrix3::zeros();
    for (s, d) in src[..n].iter().zip(&dst[..n]) {
        h += (d.coords - cd) * (s.coords - cs).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    // The points must span at least a plane.
    if svd.singular_values[1] < 1e-9 * svd.singular_values[0].max(1e-12) {
        return None;
    }
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * v_t;
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = cd - rotation * cs;
    let iso = Isometry3::from_parts(Translation3::from(t), rotation);
    iso.translation
        .vector
        .iter()
        .all(|v| v.is_finite())
        .then_some(iso)
}

/// RANSAC settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RansacConfig {
    /// Samples to draw.
    pub iterations: usize,
    /// A pair is an inlier when `‖dst − T·src‖` is below this, metres.
    pub inlier_distance: f64,
    /// Fewer inliers than this: no motion.
    pub min_inliers: usize,
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self {
            iterations: 200,
            inlier_distance: 0.04,
            min_inliers: 12,
        }
    }
}

/// The motion found by RANSAC and the pairs that agree with it.
#[derive(Debug, Clone)]
pub struct Motion {
    /// `dst ≈ T·src`.
    pub transform: Isometry3<f64>,
    /// Indices of the inlier pairs.
    pub inliers: Vec<usize>,
    /// RMS distance of the inliers after the final fit, metres.
    pub rms: f64,
}

/// RANSAC over three-point samples (deterministic for a `seed`), then a least-squares fit on the
/// inliers, repeated once with the inliers of the refined motion.
pub fn ransac(
    src: &[Point3<f64>],
    dst: &[Point3<f64>],
    config: &RansacConfig,
    seed: u64,
) -> Option<Motion> {
    let n = src.len().min(dst.len());
    if n < config.min_inliers.max(3) {
        return None;
    }
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let mut next = |m: usize| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) as usize) % m
    };
    let inliers_of = |t: &Isometry3<f64>| -> Vec<usize> {
        (0..n)
            .filter(|&i| (dst[i] - t * src[i]).norm() < config.inlier_distance)
            .collect()
    };
    let mut best: Vec<usize> = vec![];
    for _ in 0..config.iterations {
        let (a, b, c) = (next(n), next(n), next(n));
        if a == b || b == c || a == c {
            continue;
        }
        // Reject samples whose points are almost collinear or too close together.
        let (pa, pb, pc) = (src[a], src[b], src[c]);
        if (pb - pa).cross(&(pc - pa)).norm() < 1e-4 {
            continue;
        }
        let Some(t) = fit(&[pa, pb, pc], &[dst[a], dst[b], dst[c]]) else {
            continue;
        };
        let inliers = inliers_of(&t);
        if inliers.len() > best.len() {
            best = inliers;
        }
    }
    if best.len() < config.min_inliers {
        return None;
    }
    let mut transform = fit_subset(src, dst, &best)?;
    for _ in 0..2 {
        let refined = inliers_of(&transform);
        if refined.len() < config.min_inliers {
            break;
        }
        transform = fit_subset(src, dst, &refined)?;
        best = refined;
    }
    let rms = (best
        .iter()
        .map(|&i| (dst[i] - transform * src[i]).norm_squared())
        .sum::<f64>()
        / best.len() as f64)
        .sqrt();
    Some(Motion {
        transform,
        inliers: best,
        rms,
    })
}

fn fit_subset(src: &[Point3<f64>], dst: &[Point3<f64>], idx: &[usize]) -> Option<Isometry3<f64>> {
    let s: Vec<Point3<f64>> = idx.iter().map(|&i| src[i]).collect();
    let d: Vec<Point3<f64>> = idx.iter().map(|&i| dst[i]).collect();
    fit(&s, &d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|i| {
                let f = i as f64;
                Point3::new(
                    (f * 0.37).sin() * 2.0,
                    (f * 0.91).cos() * 1.5,
                    1.0 + (f * 0.13).sin().abs() * 3.0,
                )
            })
            .collect()
    }

    fn motion() -> Isometry3<f64> {
        Isometry3::new(Vector3::new(0.3, -0.1, 0.05), Vector3::new(0.05, -0.2, 0.1))
    }

    #[test]
    fn fit_recovers_an_exact_motion() {
        let src = cloud(20);
        let t = motion();
        let dst: Vec<_> = src.iter().map(|p| t * p).collect();
        let est = fit(&src, &dst).unwrap();
        assert!((est.to_homogeneous() - t.to_homogeneous()).norm() < 1e-9);
        // Degenerate: collinear points, or too few.
        let line: Vec<_> = (0..5)
            .map(|i| Point3::new(f64::from(i), 0.0, 0.0))
            .collect();
        assert!(fit(&line, &line).is_none());
        assert!(fit(&src[..2], &dst[..2]).is_none());
    }

    #[test]
    fn ransac_ignores_outliers_and_reports_inliers() {
        let src = cloud(100);
        let t = motion();
        let mut dst: Vec<_> = src.iter().map(|p| t * p).collect();
        // 30 % wrong matches, and 3 mm noise on the rest.
        for (i, d) in dst.iter_mut().enumerate() {
            if i % 10 < 3 {
                *d = Point3::new(f64::from(i as u32 % 7), -1.0, 2.0);
            } else {
                d.x += 0.003 * ((i as f64) * 1.7).sin();
            }
        }
        let m = ransac(&src, &dst, &RansacConfig::default(), 1).unwrap();
        assert_eq!(m.inliers.len(), 70);
        assert!(m.inliers.iter().all(|i| i % 10 >= 3));
        let err = (m.transform.translation.vector - t.translation.vector).norm();
        let rot = m.transform.rotation.angle_to(&t.rotation);
        assert!(err < 0.005 && rot < 0.005, "{err} {rot}");
        assert!(m.rms < 0.004);
        // Deterministic for a seed.
        let again = ransac(&src, &dst, &RansacConfig::default(), 1).unwrap();
        assert_eq!(again.inliers, m.inliers);
    }

    #[test]
    fn too_few_agreeing_pairs_is_no_motion() {
        let src = cloud(30);
        let dst: Vec<_> = src.iter().rev().copied().collect();
        assert!(ransac(&src, &dst, &RansacConfig::default(), 1).is_none());
    }
}
