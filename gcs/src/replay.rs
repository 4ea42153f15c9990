//! `gcs replay FILE.mcap`: reruns the SLAM on a recorded mission's sensor data (camera frames,
//! IMU heading, sonar height, the filter's poses as relocalisation hints) and reports how the
//! result differs from what the mission produced: its final map and the poses it flew on.
//!
//! A log cut short by a crash replays up to its last readable message. Colour was recorded as
//! JPEG, so the replay sees slightly different pixels than the live SLAM did, and its optimiser
//! runs in step with the frames (deterministic) rather than in the background: small
//! differences are expected, large ones point at a problem worth a look.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, bail};
use clap::Args;
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, CompressedImage, Grid as FoxGrid, PoseInFrame};
use link::camera::{Intrinsics, RgbdFrame};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use nav::grid::{Cell, Grid};
use slam::system::{RobotSetup, Slam, SlamConfig};
use slam::trajectory::Stamped;

use gcs::outputs;
use gcs::record::{DroneState, Setup};
use gcs::runtime::perception::{CameraFrame, SensorSample, slam_frame};

/// Arguments of `gcs replay`.
#[derive(Args, Debug, Clone)]
pub struct ReplayArgs {
    /// The mission log (`mission.mcap` of `gcs explore`).
    pub log: PathBuf,
    /// Where to write the replayed map, trajectories and report.
    #[arg(long, default_value = "replay-out")]
    pub out: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Map on the simulator's true camera poses recorded in the log (as `gcs explore --poses
    /// truth` did) instead of tracking the cameras.
    #[arg(long)]
    pub truth_poses: bool,
}

/// How the replay compares with the mission, as written to `replay.json`.
#[derive(Debug, serde::Serialize)]
pub struct ReplayReport {
    /// Messages read from the log.
    pub messages: usize,
    /// Whether the log ended early (a crashed writer): replayed up to its last whole message.
    pub truncated: bool,
    /// Camera frames replayed.
    pub frames: usize,
    /// Keyframes and loop closures of the replayed graph.
    pub keyframes: usize,
    /// Loop closures in the replayed graph.
    pub loop_closures: usize,
    /// The replayed map against the mission's last recorded map.
    pub map: Option<MapComparison>,
    /// Per drone: the replayed body trajectory against the poses the mission flew on.
    pub drones: Vec<DroneComparison>,
}

/// Two 2D maps cell by cell.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MapComparison {
    /// Cells known (free or occupied) in either map.
    pub cells: usize,
    /// Fraction of those with the same state in both.
    pub agreement: f64,
    /// Free cells of both over free cells of either.
    pub free_iou: f64,
}

/// One drone's replayed trajectory against the recorded one.
#[derive(Debug, serde::Serialize)]
pub struct DroneComparison {
    /// 1-based id.
    pub id: usize,
    /// Recorded poses compared (the filter's, at control ticks with a replayed pose near).
    pub compared: usize,
    /// RMS horizontal distance between them, metres.
    pub rms_m: Option<f64>,
    /// Frames the replayed SLAM could not track.
    pub lost_frames: usize,
}

/// A recorded mission, as replay needs it.
struct MissionLog {
    setup: Setup,
    /// Camera frames in log order.
    frames: Vec<CameraFrame>,
    /// Per drone: (time, state) in time order.
    states: Vec<Vec<DroneState>>,
    /// The last recorded 2D map.
    grid: Option<Grid>,
    messages: usize,
    truncated: bool,
}

/// Runs `gcs replay`.
pub fn run(args: &ReplayArgs) -> anyhow::Result<()> {
    let log = read_log(&args.log)?;
    if args.truth_poses && log.frames.iter().all(|f| f.truth.is_none()) {
        bail!(
            "{} has no true camera poses (/droneK/camera/truth): it was not recorded in the simulator; replay without --truth-poses",
            args.log.display()
        );
    }
    if log.truncated {
        tracing::warn!(
            "{} ends early (a crashed writer?): replaying its first {} messages",
            args.log.display(),
            log.messages
        );
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let setups: Vec<RobotSetup> = log
        .setup
        .drones
        .iter()
        .map(|d| {
            let [x, y, z, qx, qy, qz, qw] = d.body_from_camera;
            RobotSetup {
                body_from_camera: Isometry3::from_parts(
                    Translation3::new(x, y, z),
                    UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
                ),
                start: d.start.map(|s| {
                    Isometry3::new(
                        nalgebra::Vector3::new(s[0], s[1], 0.0),
                        nalgebra::Vector3::z() * s[2],
                    )
                }),
            }
        })
        .collect();
    let n = setups.len();
    let mut slam = Slam::new(
        SlamConfig {
            background: false,
            known_poses: args.truth_poses,
            ..SlamConfig::default()
        },
        setups,
    );
    let total = log.frames.len();
    eprintln!(
        "replay: {} frames of {} drone(s) from {}",
        total,
        n,
        args.log.display()
    );
    let mut body_tracks: Vec<Vec<(f64, [f64; 2])>> = vec![vec![]; n];
    for (i, f) in log.frames.iter().enumerate() {
        if f.drone >= n {
            continue;
        }
        let sample = sample_at(&log.states[f.drone], f.stamp);
        let Some(frame) = slam_frame(f, sample, args.truth_poses) else {
            continue;
        };
        if let Err(e) = slam.process(frame) {
            tracing::warn!(
                drone = f.drone + 1,
                "frame at {:.2} s refused: {e}",
                f.stamp
            );
            continue;
        }
        if let Some(b) = slam.estimate(f.drone).and_then(|e| e.map_from_body()) {
            let v = b.translation.vector;
            body_tracks[f.drone].push((f.stamp, [v.x, v.y]));
        }
        if (i + 1) % 200 == 0 || i + 1 == total {
            eprintln!(
                "[{:5.1} %] {} keyframes, {} loops",
                (i + 1) as f64 / total.max(1) as f64 * 100.0,
                slam.stats().keyframes,
                slam.stats().loop_closures
            );
        }
    }
    slam.finish();
    let voxels = slam.map().snapshot();
    let grid = voxels.project();
    let stats = slam.stats();
    let report = ReplayReport {
        messages: log.messages,
        truncated: log.truncated,
        frames: total,
        keyframes: stats.keyframes,
        loop_closures: stats.loop_closures,
        map: match (&grid, &log.grid) {
            (Some(a), Some(b)) => compare_maps(a, b),
            _ => None,
        },
        drones: (0..n)
            .map(|k| {
                let (compared, rms_m) = compare_tracks(&body_tracks[k], &log.states[k]);
                DroneComparison {
                    id: k + 1,
                    compared,
                    rms_m,
                    lost_frames: slam.estimate(k).map_or(0, |e| e.lost_frames),
                }
            })
            .collect(),
    };
    if let Some(g) = &grid {
        outputs::write_map(&args.out, g)?;
    }
    for k in 0..n {
        let t: Vec<Stamped> = slam.trajectory(k);
        outputs::write_trajectory(&args.out.join(format!("drone{}.tum", k + 1)), &t)?;
    }
    outputs::write_json(&args.out.join("replay.json"), &report)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "replayed {} frames: {} keyframes, {} loops; map agreement with the mission's: {}; outputs in {}",
            report.frames,
            report.keyframes,
            report.loop_closures,
            report
                .map
                .map_or("-".into(), |m| format!("{:.1} %", m.agreement * 100.0)),
            args.out.display()
        );
    }
    Ok(())
}

/// Reads what replay needs from a mission log; stops at the first unreadable message (a log cut
/// short by a crash) and says so.
fn read_log(path: &Path) -> anyhow::Result<MissionLog> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let not_mcap = || {
        format!(
            "{} is not an MCAP file (expected a mission.mcap written by gcs explore)",
            path.display()
        )
    };
    if !bytes.starts_with(mcap::MAGIC) {
        bail!(not_mcap());
    }
    let stream = mcap::MessageStream::new(&bytes).with_context(not_mcap)?;
    let mut setup = None;
    let mut states: BTreeMap<usize, Vec<DroneState>> = BTreeMap::new();
    let mut grid = None;
    // Per drone: the latest calibration, and colour and depth waiting for their partner.
    let mut calibration: BTreeMap<usize, CameraCalibration> = BTreeMap::new();
    let mut colour: BTreeMap<usize, (u64, Vec<u8>)> = BTreeMap::new();
    let mut depth: BTreeMap<usize, (u64, Vec<u16>, u32, u32)> = BTreeMap::new();
    let mut frames = vec![];
    let mut truths: BTreeMap<(usize, u64), Isometry3<f64>> = BTreeMap::new();
    let (mut messages, mut truncated) = (0, false);
    for m in stream {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                tracing::debug!("log read stops: {e}");
                truncated = true;
                break;
            }
        };
        messages += 1;
        let topic = m.channel.topic.as_str();
        let drone = drone_of(topic);
        match (topic, drone) {
            ("/setup", _) => {
                setup = Some(
                    serde_json::from_slice::<Setup>(&m.data)
                        .context("the log's /setup is not a gcs setup")?,
                );
            }
            ("/map", _) => {
                if let Ok(g) = FoxGrid::decode(&m.data[..]) {
                    grid = grid_of(&g);
                }
            }
            (t, Some(k)) if t.ends_with("/state") => {
                if let Ok(s) = serde_json::from_slice::<DroneState>(&m.data) {
                    states.entry(k).or_default().push(s);
                }
            }
            (t, Some(k)) if t.ends_with("/camera/truth") => {
                if let Ok(p) = PoseInFrame::decode(&m.data[..])
                    && let Some(pose) = isometry_of(&p)
                {
                    truths.insert((k, m.log_time), pose);
                }
            }
            (t, Some(k)) if t.ends_with("/camera/calibration") => {
                if let Ok(c) = CameraCalibration::decode(&m.data[..]) {
                    calibration.insert(k, c);
                }
            }
            (t, Some(k)) if t.ends_with("/camera/color") => {
                let Ok(c) = CompressedImage::decode(&m.data[..]) else {
                    continue;
                };
                match image::load_from_memory(&c.data) {
                    Ok(img) => {
                        colour.insert(k, (m.log_time, img.into_rgb8().into_raw()));
                    }
                    Err(e) => tracing::warn!("drone {} colour frame unreadable: {e}", k + 1),
                }
            }
            (t, Some(k)) if t.ends_with("/camera/depth") => {
                let Ok(c) = CompressedImage::decode(&m.data[..]) else {
                    continue;
                };
                match image::load_from_memory(&c.data) {
                    Ok(img) => {
                        let d = img.into_luma16();
                        let (w, h) = d.dimensions();
                        depth.insert(k, (m.log_time, d.into_raw(), w, h));
                    }
                    Err(e) => tracing::warn!("drone {} depth frame unreadable: {e}", k + 1),
                }
            }
            _ => {}
        }
        // A frame is whole once its colour, depth and calibration are in, at one time.
        if let Some(k) = drone
            && let (Some((tc, _)), Some((td, ..)), Some(cal)) =
                (colour.get(&k), depth.get(&k), calibration.get(&k))
            && tc == td
            && cal.k.len() == 9
        {
            let (Some((t, rgb)), Some((_, d, w, h))) = (colour.remove(&k), depth.remove(&k)) else {
                continue;
            };
            if rgb.len() != (w * h * 3) as usize {
                continue;
            }
            frames.push(CameraFrame {
                drone: k,
                stamp: t as f64 * 1e-9,
                frame: Arc::new(RgbdFrame {
                    vehicle: u8::try_from(k).unwrap_or(u8::MAX),
                    stamp: std::time::Duration::from_nanos(t),
                    width: w,
                    height: h,
                    intrinsics: Intrinsics {
                        fx: cal.k[0] as f32,
                        fy: cal.k[4] as f32,
                        cx: cal.k[2] as f32,
                        cy: cal.k[5] as f32,
                    },
                    rgb,
                    depth_mm: d,
                }),
                truth: None,
            });
        }
    }
    let Some(setup) = setup else {
        bail!(
            "{} has no /setup message: not a log of gcs explore, or cut before its first second",
            path.display()
        );
    };
    for f in &mut frames {
        f.truth = truths
            .get(&(f.drone, f.frame.stamp.as_nanos() as u64))
            .copied();
    }
    let n = setup.drones.len();
    Ok(MissionLog {
        states: (0..n)
            .map(|k| states.remove(&k).unwrap_or_default())
            .collect(),
        setup,
        frames,
        grid,
        messages,
        truncated,
    })
}

/// A recorded pose as an isometry (`None` when incomplete or not a rotation).
fn isometry_of(p: &PoseInFrame) -> Option<Isometry3<f64>> {
    let pose = p.pose.as_ref()?;
    let (v, q) = (pose.position.as_ref()?, pose.orientation.as_ref()?);
    let q = Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = q.norm();
    (norm.is_finite() && (norm - 1.0).abs() < 1e-3 && v.x.is_finite() && v.y.is_finite()).then(
        || {
            Isometry3::from_parts(
                Translation3::new(v.x, v.y, v.z),
                UnitQuaternion::from_quaternion(q),
            )
        },
    )
}

/// The drone index of a `/droneK/...` topic.
fn drone_of(topic: &str) -> Option<usize> {
    let rest = topic.strip_prefix("/drone")?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse::<usize>().ok()?.checked_sub(1)
}

/// A recorded `foxglove.Grid` (int8 occupancy, as the recorder writes it) as a map.
fn grid_of(g: &FoxGrid) -> Option<Grid> {
    let w = g.column_count as usize;
    let res = g.cell_size.as_ref()?.x;
    if w == 0 || g.cell_stride != 1 || g.row_stride as usize != w || !res.is_finite() || res <= 0.0
    {
        return None;
    }
    let h = g.data.len() / w;
    let o = g.pose.as_ref()?.position.as_ref()?;
    let mut grid = Grid::new(w, h, res, [o.x, o.y], Cell::Unknown);
    for y in 0..h {
        for x in 0..w {
            let cell = match g.data[y * w + x] as i8 {
                0 => Cell::Free,
                100 => Cell::Occupied,
                _ => Cell::Unknown,
            };
            grid.set((x, y), cell);
        }
    }
    Some(grid)
}

/// The latest sample of a drone's state at or before `t`.
fn sample_at(states: &[DroneState], t: f64) -> Option<SensorSample> {
    let i = states.partition_point(|s| s.t <= t).checked_sub(1)?;
    let s = &states[i];
    Some(SensorSample {
        t: s.t,
        heading: s.yaw_rad.map(f64::from),
        height: s.height_m.map(f64::from),
        body: s.pose,
    })
}

/// Cell-by-cell agreement of two maps, over the cells either knows (`b`'s cells looked up by
/// their centres in `a`).
fn compare_maps(a: &Grid, b: &Grid) -> Option<MapComparison> {
    let (mut cells, mut same, mut free_both, mut free_either) = (0usize, 0usize, 0usize, 0usize);
    let lookup = |g: &Grid, p: [f64; 2]| g.cell_of(p).map_or(Cell::Unknown, |c| g.get(c));
    // Every cell of either map, visited once: b's cells, then a's cells b does not cover.
    let mut visit = |ca: Cell, cb: Cell| {
        if ca == Cell::Unknown && cb == Cell::Unknown {
            return;
        }
        cells += 1;
        same += usize::from(ca == cb);
        free_both += usize::from(ca == Cell::Free && cb == Cell::Free);
        free_either += usize::from(ca == Cell::Free || cb == Cell::Free);
    };
    for y in 0..b.height() {
        for x in 0..b.width() {
            let p = b.center_of((x, y));
            visit(lookup(a, p), b.get((x, y)));
        }
    }
    for y in 0..a.height() {
        for x in 0..a.width() {
            let p = a.center_of((x, y));
            if b.cell_of(p).is_none() {
                visit(a.get((x, y)), Cell::Unknown);
            }
        }
    }
    (cells > 0).then(|| MapComparison {
        cells,
        agreement: same as f64 / cells as f64,
        free_iou: free_both as f64 / free_either.max(1) as f64,
    })
}

/// RMS horizontal distance between the recorded filter poses and the replayed body poses
/// nearest in time (within 0.1 s).
fn compare_tracks(replayed: &[(f64, [f64; 2])], recorded: &[DroneState]) -> (usize, Option<f64>) {
    let (mut sum, mut count) = (0.0, 0usize);
    for s in recorded {
        let Some(p) = s.pose else { continue };
        let i = replayed.partition_point(|(t, _)| *t < s.t);
        let nearest = [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| replayed.get(j))
            .min_by(|a, b| (a.0 - s.t).abs().total_cmp(&(b.0 - s.t).abs()));
        if let Some((t, q)) = nearest
            && (t - s.t).abs() <= 0.1
        {
            sum += (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
            count += 1;
        }
    }
    (count, (count > 0).then(|| (sum / count as f64).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drone_topics_name_their_drone() {
        assert_eq!(drone_of("/drone1/camera/color"), Some(0));
        assert_eq!(drone_of("/drone12/state"), Some(11));
        assert_eq!(drone_of("/drone0/state"), None);
        assert_eq!(drone_of("/map"), None);
    }

    #[test]
    fn a_map_agrees_with_itself_and_less_with_a_shifted_copy() {
        let mut a = Grid::new(40, 20, 0.05, [0.0, 0.0], Cell::Unknown);
        for y in 0..20 {
            for x in 0..30 {
                a.set((x, y), if x == 29 { Cell::Occupied } else { Cell::Free });
            }
        }
        let same = compare_maps(&a, &a).expect("cells");
        assert_eq!((same.agreement, same.free_iou), (1.0, 1.0));
        let mut b = a.clone();
        for y in 0..20 {
            for x in 20..30 {
                b.set((x, y), Cell::Unknown);
            }
        }
        let part = compare_maps(&a, &b).expect("cells");
        assert!((part.agreement - 20.0 / 30.0).abs() < 1e-9, "{part:?}");
    }
}
