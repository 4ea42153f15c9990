//! ORB-like features: FAST-9 corners spread over the image, oriented by their intensity
//! centroid, described by 256-bit steered BRIEF on a smoothed image, matched by Hamming distance
//! with a ratio test and a mutual check.
//!
//! The BRIEF pattern is fixed (generated once from a constant seed), so descriptors from
//! different runs and different cameras compare — which loop closure across drones needs.

use std::sync::OnceLock;

use image::GrayImage;
use imageproc::corners::corners_fast9;

/// A keypoint: pixel position, orientation (radians, image x toward image y) and FAST score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keypoint {
    /// Column, pixels.
    pub x: f32,
    /// Row, pixels.
    pub y: f32,
    /// Orientation of the intensity centroid, radians.
    pub angle: f32,
    /// FAST score (larger is stronger).
    pub score: f32,
}

/// A 256-bit binary descriptor.
pub type Descriptor = [u64; 4];

/// Detector settings.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureConfig {
    /// FAST intensity threshold to start from (halved, down to 5, while too few corners are found).
    pub fast_threshold: u8,
    /// At most this many keypoints per image.
    pub max_keypoints: usize,
    /// Keypoints closer than this to a stronger one are dropped, pixels.
    pub min_distance: u32,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self {
            fast_threshold: 20,
            max_keypoints: 1000,
            min_distance: 4,
        }
    }
}

/// Test points of the descriptor lie within this radius of the keypoint.
const PATCH_RADIUS: i32 = 13;
/// Keypoints must lie this far from the image border (patch, rotation, smoothing).
pub const BORDER: u32 = 20;
/// Orientation is measured over a disc of this radius.
const CENTROID_RADIUS: i32 = 15;

/// Detects up to `max_keypoints` FAST-9 corners, strongest first, no two closer than
/// `min_distance`, each with its orientation.
pub fn detect(image: &GrayImage, config: &FeatureConfig) -> Vec<Keypoint> {
    let (w, h) = image.dimensions();
    if w <= 2 * BORDER || h <= 2 * BORDER {
        return vec![];
    }
    // Blurred or dim images have few strong corners: lower the threshold until there are enough.
    let mut threshold = config.fast_threshold.max(1);
    let mut corners = loop {
        let found: Vec<_> = corners_fast9(image, threshold)
            .into_iter()
            .filter(|c| c.x >= BORDER && c.y >= BORDER && c.x < w - BORDER && c.y < h - BORDER)
            .collect();
        if found.len() >= config.max_keypoints * 2 || threshold <= 5 {
            break found;
        }
        threshold = (threshold / 2).max(5);
    };
    corners.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then((a.y, a.x).cmp(&(b.y, b.x)))
    });
    // Greedy suppression on a coarse occupancy grid of cell size min_distance.
    let cell = config.min_distance.max(1);
    let (gw, gh) = (w.div_ceil(cell) as usize, h.div_ceil(cell) as usize);
    let mut taken = vec![false; gw * gh];
    let mut out = vec![];
    for c in corners {
        if out.len() >= config.max_keypoints {
            break;
        }
        let (gx, gy) = ((c.x / cell) as usize, (c.y / cell) as usize);
        let near = (gy.saturating_sub(1)..(gy + 2).min(gh))
            .any(|y| (gx.saturating_sub(1)..(gx + 2).min(gw)).any(|x| taken[y * gw + x]));
        if near {
            continue;
        }
        taken[gy * gw + gx] = true;
        out.push(Keypoint {
            x: c.x as f32,
            y: c.y as f32,
            angle: orientation(image, c.x as i32, c.y as i32),
            score: c.score,
        });
    }
    out
}

/// Angle of the intensity centroid of the disc around `(x, y)` (Rosin's measure, as ORB).
fn orientation(image: &GrayImage, x: i32, y: i32) -> f32 {
    let (mut m10, mut m01) = (0i64, 0i64);
    let r = CENTROID_RADIUS;
    for dy in -r..=r {
        let span = f64::from(r * r - dy * dy).sqrt() as i32;
        for dx in -span..=span {
            let v = i64::from(image.get_pixel((x + dx) as u32, (y + dy) as u32)[0]);
            m10 += i64::from(dx) * v;
            m01 += i64::from(dy) * v;
        }
    }
    (m01 as f32).atan2(m10 as f32)
}

/// The 256 test pairs: Gaussian around the keypoint (σ = radius / 2.5), clipped to the patch.
fn pattern() -> &'static [[i8; 4]; 256] {
    static PATTERN: OnceLock<[[i8; 4]; 256]> = OnceLock::new();
    PATTERN.get_or_init(|| {
        // SplitMix64 with a constant seed: the pattern never changes.
        let mut state = 0x005E_ED0F_0B0B_u64;
        let mut next = || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let sigma = f64::from(PATCH_RADIUS) / 2.5;
        let mut gauss = || loop {
            let (u1, u2) = (1.0 - next(), next());
            let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos() * sigma;
            if g.abs() <= f64::from(PATCH_RADIUS) / std::f64::consts::SQRT_2 {
                return g.round() as i8;
            }
        };
        let mut p = [[0i8; 4]; 256];
        for pair in &mut p {
            *pair = [gauss(), gauss(), gauss(), gauss()];
        }
        p
    })
}

/// A 5×5 box-smoothed copy of the image (from an integral image), for stable binary tests.
fn smooth(image: &GrayImage) -> Vec<u8> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let mut integral = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0u32;
        for x in 0..w {
            row += u32::from(image.as_raw()[y * w + x]);
            integral[(y + 1) * (w + 1) + x + 1] = integral[y * (w + 1) + x + 1] + row;
        }
    }
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(2), (y + 3).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(2), (x + 3).min(w));
            let sum = integral[y1 * (w + 1) + x1] + integral[y0 * (w + 1) + x0]
                - integral[y0 * (w + 1) + x1]
                - integral[y1 * (w + 1) + x0];
            out[y * w + x] = (sum / ((y1 - y0) * (x1 - x0)) as u32) as u8;
        }
    }
    out
}

/// Steered BRIEF descriptors of `keypoints` (which must come from [`detect`] on this image).
pub fn describe(image: &GrayImage, keypoints: &[Keypoint]) -> Vec<Descriptor> {
    let smoothed = smooth(image);
    let (w, h) = (image.width() as i32, image.height() as i32);
    let at = |x: i32, y: i32| smoothed[(y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize];
    // Round to nearest without a libm call (test points never lie 64 pixels left of the image).
    let round = |v: f32| (v + 64.5) as i32 - 64;
    keypoints
        .iter()
        .map(|k| {
            let (s, c) = k.angle.sin_cos();
            let rotate = |dx: i8, dy: i8| {
                let (dx, dy) = (f32::from(dx), f32::from(dy));
                (round(k.x + c * dx - s * dy), round(k.y + s * dx + c * dy))
            };
            let mut d = [0u64; 4];
            for (i, p) in pattern().iter().enumerate() {
                let (ax, ay) = rotate(p[0], p[1]);
                let (bx, by) = rotate(p[2], p[3]);
                if at(ax, ay) < at(bx, by) {
                    d[i / 64] |= 1 << (i % 64);
                }
            }
            d
        })
        .collect()
}

/// Number of differing bits.
pub fn hamming(a: &Descriptor, b: &Descriptor) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// Matches `a` to `b`: each pair is the other's nearest, closer than `max_distance` bits, and
/// clearly nearer than the second nearest (distance < `ratio` × second). Returns index pairs.
pub fn match_descriptors(
    a: &[Descriptor],
    b: &[Descriptor],
    max_distance: u32,
    ratio: f32,
) -> Vec<(usize, usize)> {
    let best = |from: &[Descriptor], to: &[Descriptor]| -> Vec<Option<(usize, u32, u32)>> {
        from.iter()
            .map(|d| {
                let (mut first, mut second) = ((usize::MAX, u32::MAX), u32::MAX);
                for (j, e) in to.iter().enumerate() {
                    let h = hamming(d, e);
                    if h < first.1 {
                        second = first.1;
                        first = (j, h);
                    } else if h < second {
                        second = h;
                    }
                }
                (first.0 != usize::MAX).then_some((first.0, first.1, second))
            })
            .collect()
    };
    let forward = best(a, b);
    let backward = best(b, a);
    forward
        .iter()
        .enumerate()
        .filter_map(|(i, m)| {
            let (j, d, second) = (*m)?;
            let mutual = backward[j].is_some_and(|(k, _, _)| k == i);
            let distinct = second == u32::MAX || (d as f32) < ratio * second as f32;
            (mutual && distinct && d <= max_distance).then_some((i, j))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    /// A textured test image: random blocks (deterministic).
    fn blocks(w: u32, h: u32, seed: u64) -> GrayImage {
        let mut s = seed;
        let mut cells = vec![0u8; ((w / 8 + 1) * (h / 8 + 1)) as usize];
        for c in &mut cells {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *c = (s >> 56) as u8;
        }
        GrayImage::from_fn(w, h, |x, y| {
            Luma([cells[((y / 8) * (w / 8 + 1) + x / 8) as usize]])
        })
    }

    #[test]
    fn keypoints_are_spread_and_away_from_the_border() {
        let img = blocks(320, 240, 1);
        let config = FeatureConfig {
            max_keypoints: 300,
            min_distance: 8,
            ..FeatureConfig::default()
        };
        let k = detect(&img, &config);
        assert!(k.len() > 100, "{}", k.len());
        assert!(k.len() <= config.max_keypoints);
        let d = config.min_distance as f32;
        for (i, a) in k.iter().enumerate() {
            assert!(a.x >= 20.0 && a.y >= 20.0 && a.x < 300.0 && a.y < 220.0);
            for b in &k[..i] {
                // No two keypoints closer than the minimum distance (in either axis).
                assert!(
                    (a.x - b.x).abs() > d || (a.y - b.y).abs() > d,
                    "{a:?} {b:?}"
                );
            }
        }
    }

    #[test]
    fn a_shifted_image_matches_itself_and_rotation_is_tolerated() {
        let img = blocks(320, 240, 2);
        // The same scene shifted by (7, 3) pixels.
        let shifted = GrayImage::from_fn(320, 240, |x, y| {
            *img.get_pixel(x.saturating_sub(7), y.saturating_sub(3))
        });
        let config = FeatureConfig::default();
        let (ka, kb) = (detect(&img, &config), detect(&shifted, &config));
        let (da, db) = (describe(&img, &ka), describe(&shifted, &kb));
        let m = match_descriptors(&da, &db, 64, 0.8);
        let good = m
            .iter()
            .filter(|(i, j)| {
                (kb[*j].x - ka[*i].x - 7.0).abs() < 1.5 && (kb[*j].y - ka[*i].y - 3.0).abs() < 1.5
            })
            .count();
        assert!(m.len() > 50, "{} matches", m.len());
        // Blocky test images repeat themselves; RANSAC removes the few wrong matches.
        assert!(
            good as f64 / m.len() as f64 > 0.9,
            "{good} of {} correct",
            m.len()
        );
        // Rotated by 90°: steered descriptors still match many keypoints.
        let rotated = GrayImage::from_fn(240, 320, |x, y| *img.get_pixel(y, 239 - x));
        let kr = detect(&rotated, &config);
        let dr = describe(&rotated, &kr);
        let m = match_descriptors(&da, &dr, 64, 0.8);
        let good = m
            .iter()
            .filter(|(i, j)| {
                // (x, y) in the original is (239 − y, x) in the rotated image.
                (kr[*j].x - (239.0 - ka[*i].y)).abs() < 2.0 && (kr[*j].y - ka[*i].x).abs() < 2.0
            })
            .count();
        assert!(good > 30, "{good} correct of {} after a 90° turn", m.len());
    }

    #[test]
    fn hamming_counts_bits_and_tiny_images_have_no_keypoints() {
        assert_eq!(hamming(&[0, 0, 0, 0], &[1, 3, 0, u64::MAX]), 67);
        assert!(detect(&GrayImage::new(30, 30), &FeatureConfig::default()).is_empty());
        assert!(match_descriptors(&[], &[[0; 4]], 64, 0.8).is_empty());
    }
}
