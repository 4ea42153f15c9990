//! Depth odometry's cost per frame on real Kinect frames: `cargo bench -p slam --bench
//! depth_odometry` (TUM fr1/rpy, the first 150 frames in `../shared/data/rgbd`).
//!
//! A station runs it on the frames of drones the SLAM does not place: the wall scan of the frame
//! and of the one before (`WallScan::from_depth`), then their registration (`register`). The
//! camera is taken as level on a body looking along its x axis; fr1/rpy is hand-held and rolls,
//! so fewer of its pixels pass as walls than a drone's would.

use std::path::Path;
use std::time::Instant;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use slam::dataset::Dataset;
use slam::depth_odometry::{DepthOdometryConfig, WallScan, register};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let dir =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/rgbd/tum_fr1_rpy_first150");
    let dataset = match Dataset::open(&dir) {
        Ok(d) => d,
        Err(e) => {
            println!("depth odometry: {e}; skipped");
            return;
        }
    };
    let frames = if quick { 20 } else { dataset.frames.len() };
    let mut depths = Vec::new();
    for i in 0..frames {
        match dataset.load(i) {
            Ok((grey, depth)) => {
                depths.push((grey.width() as usize, grey.height() as usize, depth))
            }
            Err(e) => {
                println!("depth odometry: {e}; skipped");
                return;
            }
        }
    }
    // Optical frame (x right, y down, z forward) on a body looking along its x axis.
    let body_from_camera = Isometry3::from_parts(
        Translation3::new(0.1, 0.0, 0.0),
        UnitQuaternion::from_basis_unchecked(&[
            Vector3::new(0.0, -1.0, 0.0),
            Vector3::new(0.0, 0.0, -1.0),
            Vector3::new(1.0, 0.0, 0.0),
        ]),
    );
    let config = DepthOdometryConfig::default();
    let runs = if quick { 1 } else { 3 };
    let (mut scan_s, mut register_s) = (f64::INFINITY, f64::INFINITY);
    let (mut points, mut measured) = (0, 0);
    for _ in 0..runs {
        let started = Instant::now();
        let scans: Vec<WallScan> = depths
            .iter()
            .map(|(w, h, depth)| {
                let scale = dataset.depth_scale;
                WallScan::from_depth(
                    depth,
                    *w,
                    *h,
                    scale,
                    &dataset.camera,
                    &body_from_camera,
                    [0.0; 2],
                    &config,
                )
            })
            .collect();
        scan_s = scan_s.min(started.elapsed().as_secs_f64());
        let started = Instant::now();
        measured = scans
            .windows(2)
            .filter(|pair| register(0.0, &pair[0], &pair[1], 0.0, &config).is_some())
            .count();
        register_s = register_s.min(started.elapsed().as_secs_f64());
        points = scans.iter().map(WallScan::len).sum();
    }
    let n = depths.len();
    println!("depth odometry on TUM fr1/rpy, {n} frames of 640 × 480 (best of {runs})\n");
    println!(
        "  wall scan     {:>7.3} ms a frame ({:.0} wall points a scan)",
        scan_s / n as f64 * 1e3,
        points as f64 / n as f64
    );
    println!(
        "  registration  {:>7.3} ms a pair ({measured} of {} pairs measured a motion)",
        register_s / (n - 1).max(1) as f64 * 1e3,
        n - 1
    );
}
