//! Reading a mission log (`mission.mcap` written by `gcs explore` or `gcs fly`) back: its
//! setup, every drone's camera frames and recorded states, and the last map. A log cut short by
//! a crash reads up to its last whole message.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, bail};
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, CompressedImage, Grid as FoxGrid, PoseInFrame};
use link::camera::{Intrinsics, RgbdFrame};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use nav::grid::{Cell, Grid};

use crate::record::{DroneState, Setup};
use crate::runtime::perception::CameraFrame;

/// A recorded mission, as replay needs it.
#[derive(Debug)]
pub struct MissionLog {
    /// The mission's setup (world, drones, cameras).
    pub setup: Setup,
    /// Camera frames in log order.
    pub frames: Vec<CameraFrame>,
    /// Per drone: (time, state) in time order.
    pub states: Vec<Vec<DroneState>>,
    /// The last recorded 2D map.
    pub grid: Option<Grid>,
    /// Messages read.
    pub messages: usize,
    /// The log ended in an unreadable message (a crash cut it short).
    pub truncated: bool,
}

/// Reads what replay needs from a mission log; stops at the first unreadable message (a log cut
/// short by a crash) and says so.
pub fn load(path: &Path) -> anyhow::Result<MissionLog> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    read(&bytes, &path.display().to_string())
}

/// Reads a mission log from its bytes; `origin` names it in errors.
pub fn read(bytes: &[u8], origin: &str) -> anyhow::Result<MissionLog> {
    let not_mcap =
        || format!("{origin} is not an MCAP file (expected a mission.mcap written by gcs explore)");
    if !bytes.starts_with(mcap::MAGIC) {
        bail!(not_mcap());
    }
    let stream = mcap::MessageStream::new(bytes).with_context(not_mcap)?;
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
            "{origin} has no /setup message: not a log of gcs explore, or cut before its first second"
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
    fn what_is_not_a_mission_log_says_so() {
        let e = format!("{:#}", read(b"hello", "x.mcap").expect_err("not MCAP"));
        assert!(e.contains("x.mcap is not an MCAP file"), "{e}");
        let e = format!("{:#}", read(mcap::MAGIC, "y.mcap").expect_err("no setup"));
        assert!(e.contains("y.mcap"), "{e}");
    }
}
