//! What a mission leaves on disk: the 2D map (ROS `map_server` PGM + YAML, and a PNG with
//! trajectories), the 3D map (PLY), trajectories (TUM) and JSON summaries. Every file is
//! written to a temporary name and renamed into place, so a crash never leaves a half-written
//! file where a good one was.

use std::path::{Path, PathBuf};

use anyhow::Context;
use image::Rgb;
use nav::grid::Grid;
use nav::render::ROBOT_COLOURS;
use slam::occupancy::VoxelMap;
use slam::trajectory::Stamped;

/// `dir/.name.partial`: where `path` is written before it is renamed into place.
fn partial(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.partial"))
}

/// Writes `path` through `write` on a temporary file, then renames it into place.
pub fn atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let tmp = partial(path);
    write(&tmp).with_context(|| format!("cannot write {}", path.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
}

/// `map.yaml` + `map.pgm` in `dir`.
pub fn write_map(dir: &Path, grid: &Grid) -> anyhow::Result<()> {
    // The YAML names the PGM: write the image first, then the YAML that points at it.
    let yaml = dir.join("map.yaml");
    let tmp_dir = dir.join(".map.partial");
    std::fs::create_dir_all(&tmp_dir)
        .with_context(|| format!("cannot write {}", yaml.display()))?;
    grid.save(tmp_dir.join("map.yaml"))
        .with_context(|| format!("cannot write {}", yaml.display()))?;
    std::fs::rename(tmp_dir.join("map.pgm"), dir.join("map.pgm"))
        .with_context(|| format!("cannot write {}", dir.join("map.pgm").display()))?;
    std::fs::rename(tmp_dir.join("map.yaml"), &yaml)
        .with_context(|| format!("cannot write {}", yaml.display()))?;
    let _ = std::fs::remove_dir(&tmp_dir);
    Ok(())
}

/// A picture of the map with each drone's trajectory (x, y) in its colour.
pub fn write_picture(path: &Path, grid: &Grid, tracks: &[Vec<[f64; 2]>]) -> anyhow::Result<()> {
    let scale = 4;
    let mut img = grid.render(scale);
    let o = grid.origin();
    let to_px = |p: [f64; 2]| {
        (
            ((p[0] - o[0]) / grid.resolution() * f64::from(scale)) as f32,
            ((grid.height() as f64 - (p[1] - o[1]) / grid.resolution()) * f64::from(scale)) as f32,
        )
    };
    for (k, track) in tracks.iter().enumerate() {
        let c = ROBOT_COLOURS[k % ROBOT_COLOURS.len()];
        for pair in track.windows(2) {
            imageproc::drawing::draw_line_segment_mut(
                &mut img,
                to_px(pair[0]),
                to_px(pair[1]),
                Rgb(c),
            );
        }
    }
    atomically(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png)?;
        Ok(())
    })
}

/// The occupied voxels as a PLY point cloud.
pub fn write_ply(path: &Path, voxels: &VoxelMap) -> anyhow::Result<()> {
    atomically(path, |tmp| Ok(voxels.write_ply(tmp)?))
}

/// A TUM trajectory.
pub fn write_trajectory(path: &Path, trajectory: &[Stamped]) -> anyhow::Result<()> {
    atomically(path, |tmp| {
        Ok(slam::trajectory::write_tum(tmp, trajectory)?)
    })
}

/// Pretty JSON.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value)? + "\n";
    atomically(path, |tmp| Ok(std::fs::write(tmp, text)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nav::grid::Cell;

    #[test]
    fn files_appear_whole_under_their_names_and_nothing_partial_is_left() {
        let dir = std::env::temp_dir().join(format!("gcs-outputs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut g = Grid::new(20, 10, 0.05, [-0.5, 0.0], Cell::Free);
        g.set((3, 4), Cell::Occupied);
        write_map(&dir, &g).unwrap();
        let back = Grid::load(dir.join("map.yaml")).unwrap();
        assert_eq!(back.counts(), g.counts());
        write_picture(&dir.join("map.png"), &g, &[vec![[0.0, 0.1], [0.3, 0.4]]]).unwrap();
        assert!(image::open(dir.join("map.png")).is_ok());
        write_json(&dir.join("s.json"), &serde_json::json!({"a": 1})).unwrap();
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
            .collect();
        assert!(left.is_empty(), "{left:?}");
        // A failed write leaves the good file in place.
        let r = atomically(&dir.join("s.json"), |_| anyhow::bail!("disk full"));
        assert!(r.is_err());
        assert!(
            std::fs::read_to_string(dir.join("s.json"))
                .unwrap()
                .contains("\"a\"")
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
