//! Recorded RGB-D sequences: TUM RGB-D folders (`associations.txt`, `rgb/`, `depth/`,
//! `groundtruth.txt`) and Redwood / ICL-NUIM folders (`rgbd.match` or `color/` + `depth/`,
//! `camera_primesense.json`, `trajectory.log`).

use std::path::{Path, PathBuf};

use image::GrayImage;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};

use crate::trajectory::{Stamped, read_tum};

/// Pinhole intrinsics, pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Focal length along x.
    pub fx: f64,
    /// Focal length along y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

impl Pinhole {
    /// TUM's Freiburg 1 Kinect (ORB-SLAM2's `TUM1.yaml`), the default for TUM folders.
    pub const TUM_FR1: Pinhole = Pinhole {
        fx: 517.306,
        fy: 516.469,
        cx: 318.643,
        cy: 255.314,
    };
}

/// One colour/depth pair of a sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetFrame {
    /// Timestamp, seconds (the frame index for sequences without time).
    pub stamp: f64,
    /// Colour image.
    pub rgb: PathBuf,
    /// Depth image (16-bit).
    pub depth: PathBuf,
}

/// A sequence on disk.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The folder.
    pub dir: PathBuf,
    /// The frames, in order.
    pub frames: Vec<DatasetFrame>,
    /// The camera.
    pub camera: Pinhole,
    /// Metres per depth unit (TUM 1/5000, Redwood 1/1000).
    pub depth_scale: f64,
    /// Ground truth (camera to world), when the folder has it.
    pub ground_truth: Option<Vec<Stamped>>,
}

/// A sequence that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The folder is not a sequence this reader knows, or a file in it is malformed.
    #[error("{path}: {reason}")]
    Format {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

fn read(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.into(),
        source,
    })
}

fn format_err(path: &Path, reason: impl Into<String>) -> DatasetError {
    DatasetError::Format {
        path: path.into(),
        reason: reason.into(),
    }
}

impl Dataset {
    /// Opens a TUM or Redwood/ICL-NUIM folder.
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        if dir.join("associations.txt").exists() {
            Self::open_tum(dir)
        } else if dir.join("camera_primesense.json").exists() || dir.join("rgbd.match").exists() {
            Self::open_redwood(dir)
        } else {
            Err(format_err(
                dir,
                "not an RGB-D sequence: expected associations.txt (TUM) or rgbd.match / camera_primesense.json (Redwood, ICL-NUIM)",
            ))
        }
    }

    fn open_tum(dir: &Path) -> Result<Self, DatasetError> {
        let path = dir.join("associations.txt");
        let mut frames = vec![];
        for (n, line) in read(&path)?.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let f: Vec<&str> = line.split_whitespace().collect();
            let (Some(t), Some(rgb), Some(depth)) = (f.first(), f.get(1), f.get(3)) else {
                return Err(format_err(
                    &path,
                    format!("line {}: expected 'rgb_time rgb depth_time depth'", n + 1),
                ));
            };
            let stamp: f64 = t
                .parse()
                .map_err(|_| format_err(&path, format!("line {}: '{t}' is not a time", n + 1)))?;
            frames.push(DatasetFrame {
                stamp,
                rgb: dir.join(rgb),
                depth: dir.join(depth),
            });
        }
        let gt = dir.join("groundtruth.txt");
        let ground_truth = if gt.exists() {
            Some(read_tum(&gt).map_err(|e| format_err(&gt, e.to_string()))?)
        } else {
            None
        };
        Ok(Self {
            dir: dir.into(),
            frames,
            camera: Pinhole::TUM_FR1,
            depth_scale: 1.0 / 5000.0,
            ground_truth,
        })
    }

    fn open_redwood(dir: &Path) -> Result<Self, DatasetError> {
        let cam_path = dir.join("camera_primesense.json");
        let camera = if cam_path.exists() {
            #[derive(serde::Deserialize)]
            struct Camera {
                intrinsic_matrix: [f64; 9],
            }
            let c: Camera = serde_json::from_str(&read(&cam_path)?)
                .map_err(|e| format_err(&cam_path, format!("not an Open3D camera file: {e}")))?;
            // Column-major 3×3.
            let m = c.intrinsic_matrix;
            Pinhole {
                fx: m[0],
                fy: m[4],
                cx: m[6],
                cy: m[7],
            }
        } else {
            Pinhole {
                fx: 525.0,
                fy: 525.0,
                cx: 319.5,
                cy: 239.5,
            }
        };
        let match_path = dir.join("rgbd.match");
        let mut frames = vec![];
        if match_path.exists() {
            for (n, line) in read(&match_path)?.lines().enumerate() {
                let f: Vec<&str> = line.split_whitespace().collect();
                if f.is_empty() {
                    continue;
                }
                let [depth, rgb] = f[..] else {
                    return Err(format_err(
                        &match_path,
                        format!("line {}: expected 'depth colour'", n + 1),
                    ));
                };
                frames.push(DatasetFrame {
                    stamp: frames.len() as f64,
                    rgb: dir.join(rgb),
                    depth: dir.join(depth),
                });
            }
        }
        let log = dir.join("trajectory.log");
        let ground_truth = if log.exists() {
            Some(read_redwood_log(&log)?)
        } else {
            None
        };
        Ok(Self {
            dir: dir.into(),
            frames,
            camera,
            depth_scale: 1.0 / 1000.0,
            ground_truth,
        })
    }

    /// Loads frame `i`: grey image, depth image (raw units), width and height.
    pub fn load(&self, i: usize) -> Result<(GrayImage, Vec<u16>), DatasetError> {
        let f = self
            .frames
            .get(i)
            .ok_or_else(|| format_err(&self.dir, format!("no frame {i}")))?;
        let rgb = image::open(&f.rgb)
            .map_err(|e| format_err(&f.rgb, e.to_string()))?
            .into_luma8();
        let depth = image::open(&f.depth).map_err(|e| format_err(&f.depth, e.to_string()))?;
        if !matches!(depth.color(), image::ColorType::L16) {
            return Err(format_err(
                &f.depth,
                "depth must be a 16-bit greyscale image",
            ));
        }
        let depth = depth.into_luma16();
        if depth.dimensions() != rgb.dimensions() {
            return Err(format_err(
                &f.depth,
                format!(
                    "depth is {:?} but colour is {:?}",
                    depth.dimensions(),
                    rgb.dimensions()
                ),
            ));
        }
        Ok((rgb, depth.into_raw()))
    }
}

/// A Redwood `.log`: per pose a line `i j k` then four rows of a 4×4 matrix (camera to world).
pub fn read_redwood_log(path: &Path) -> Result<Vec<Stamped>, DatasetError> {
    let text = read(path)?;
    let numbers: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .map(|v| v.parse::<f64>())
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<_, _>>()
        .map_err(|e| format_err(path, format!("not numbers: {e}")))?;
    if !numbers.len().is_multiple_of(5) {
        return Err(format_err(
            path,
            "expected blocks of five lines: 'i j k' and a 4×4 matrix",
        ));
    }
    numbers
        .chunks(5)
        .enumerate()
        .map(|(k, block)| {
            let rows = &block[1..];
            if rows.iter().any(|r| r.len() != 4) {
                return Err(format_err(
                    path,
                    format!("pose {k}: matrix rows need four numbers"),
                ));
            }
            let r = Matrix3::from_fn(|i, j| rows[i][j]);
            let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
            let t = Translation3::new(rows[0][3], rows[1][3], rows[2][3]);
            Ok(Stamped {
                t: k as f64,
                pose: Isometry3::from_parts(t, rotation),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/rgbd")
            .join(name)
    }

    #[test]
    fn opens_the_shared_tum_and_icl_sequences() {
        let tum = Dataset::open(&data("tum_fr1_rpy_first150")).unwrap();
        assert_eq!(tum.frames.len(), 150);
        assert_eq!(tum.camera, Pinhole::TUM_FR1);
        assert!(tum.ground_truth.as_ref().is_some_and(|g| g.len() > 400));
        let (grey, depth) = tum.load(0).unwrap();
        assert_eq!(grey.dimensions(), (640, 480));
        assert_eq!(depth.len(), 640 * 480);
        let icl = Dataset::open(&data("iclnuim_livingroom_5")).unwrap();
        assert_eq!(icl.frames.len(), 5);
        assert_eq!(icl.camera.fx, 525.0);
        assert_eq!(icl.camera.cx, 319.5);
        let gt = icl.ground_truth.clone().unwrap();
        assert_eq!(gt.len(), 5);
        assert!((gt[0].pose.translation.vector.z - 2.1264800183565487).abs() < 1e-12);
        assert!(icl.load(4).is_ok());
    }

    #[test]
    fn a_folder_that_is_not_a_sequence_says_so() {
        let e = Dataset::open(&data("tum_fr1_xyz_trajectories")).unwrap_err();
        assert!(e.to_string().contains("not an RGB-D sequence"), "{e}");
    }
}
