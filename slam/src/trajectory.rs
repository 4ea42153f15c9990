//! Trajectories in the TUM RGB-D format: `timestamp tx ty tz qx qy qz qw` per line, `#` comments.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// A timestamped pose (world from camera/body).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stamped {
    /// Seconds.
    pub t: f64,
    /// The pose.
    pub pose: Isometry3<f64>,
}

/// A trajectory file that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line is not `timestamp tx ty tz qx qy qz qw`.
    #[error("{path}:{line}: {reason} (expected `timestamp tx ty tz qx qy qz qw`)")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// Parses TUM text; `path` is only used in error messages.
pub fn parse_tum(text: &str, path: &Path) -> Result<Vec<Stamped>, TrajectoryError> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fail = |reason: String| TrajectoryError::Line {
            path: path.to_owned(),
            line: n + 1,
            reason,
        };
        let v: Vec<f64> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| fail(format!("{s:?} is not a number")))
            })
            .collect::<Result<_, _>>()?;
        let [t, x, y, z, qx, qy, qz, qw] = v[..] else {
            return Err(fail(format!("{} values", v.len())));
        };
        if v.iter().any(|x| !x.is_finite()) {
            return Err(fail("a value is not finite".into()));
        }
        let q = Quaternion::new(qw, qx, qy, qz);
        if q.norm() < 1e-9 {
            return Err(fail("the quaternion is zero".into()));
        }
        out.push(Stamped {
            t,
            pose: Isometry3::from_parts(
                Translation3::new(x, y, z),
                UnitQuaternion::from_quaternion(q),
            ),
        });
    }
    out.sort_by(|a, b| a.t.total_cmp(&b.t));
    Ok(out)
}

/// Reads a TUM trajectory file (sorted by time).
pub fn read_tum(path: impl AsRef<Path>) -> Result<Vec<Stamped>, TrajectoryError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| TrajectoryError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_tum(&text, path)
}

/// TUM text for a trajectory.
pub fn format_tum(trajectory: &[Stamped]) -> String {
    let mut s = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for p in trajectory {
        let t = p.pose.translation.vector;
        let q = p.pose.rotation;
        let _ = writeln!(
            s,
            "{:.6} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}",
            p.t, t.x, t.y, t.z, q.i, q.j, q.k, q.w
        );
    }
    s
}

/// Writes a TUM trajectory file.
pub fn write_tum(path: impl AsRef<Path>, trajectory: &[Stamped]) -> Result<(), TrajectoryError> {
    let path = path.as_ref();
    std::fs::write(path, format_tum(trajectory)).map_err(|source| TrajectoryError::Io {
        path: path.to_owned(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let text = "# comment\n1.5 1 2 3 0 0 0 1\n\n0.5,0,0,0,0,0,0.7071068,0.7071068\n";
        let t = parse_tum(text, Path::new("x.txt")).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t[0].t, 0.5, "sorted by time");
        let back = parse_tum(&format_tum(&t), Path::new("y.txt")).unwrap();
        for (a, b) in t.iter().zip(&back) {
            assert!((a.pose.translation.vector - b.pose.translation.vector).norm() < 1e-6);
            assert!(a.pose.rotation.angle_to(&b.pose.rotation) < 1e-6);
        }
        let e = parse_tum("1 2 3\n", Path::new("bad.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("bad.txt:1: 3 values"), "{e}");
        let e = parse_tum("1 0 0 0 0 0 0 x\n", Path::new("bad.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"x\" is not a number"), "{e}");
        assert!(
            parse_tum("1 0 0 0 0 0 0 0\n", Path::new("z"))
                .unwrap_err()
                .to_string()
                .contains("zero")
        );
    }
}
