//! Ternary occupancy grids, and ROS `map_server` map files (PGM/PNG + YAML).
//!
//! Cells are row-major; row 0 is the bottom of the map (smallest y), so cell `(x, y)` covers
//! `origin + [x, x+1) × [y, y+1)` cell sizes. `map_server` images are stored top row first and are
//! flipped on load and save.

use std::path::{Path, PathBuf};

use image::codecs::pnm::{PnmEncoder, PnmSubtype, SampleEncoding};
use image::{GrayImage, Luma, Rgb, RgbImage};
use serde::Deserialize;

/// One cell of a ternary map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Cell {
    /// Known free.
    Free,
    /// Known occupied.
    Occupied,
    /// Not observed.
    Unknown,
}

/// A cell position: column `x`, row `y` (row 0 at the bottom).
pub type CellXY = (usize, usize);

/// A ternary occupancy grid with its size in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    width: usize,
    height: usize,
    resolution: f64,
    origin: [f64; 2],
    cells: Vec<Cell>,
}

/// A map file that could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The file could not be read or written.
    #[error("{path}: {why}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why (in the message, not as a source: the message would say it twice).
        why: std::io::Error,
    },
    /// The YAML is not a map_server map description.
    #[error("{path}: not a map_server map description: {reason}")]
    Yaml {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The image could not be decoded or encoded.
    #[error("{path}: {reason}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// A length of `length_m` metres in cells of `resolution` metres, a whole number where the
/// division misses one by rounding only: settings are written in decimals binary floating point
/// does not hold (`0.35 / 0.05` is 6.999…, `0.3 / 0.05` 5.999…), and a radius or a height
/// floored, ceiled or squared from that falls a cell short.
pub fn in_cells(length_m: f64, resolution: f64) -> f64 {
    let cells = length_m / resolution;
    let whole = cells.round();
    if (cells - whole).abs() <= 1e-9 * whole.abs().max(1.0) {
        whole
    } else {
        cells
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MapYaml {
    image: String,
    resolution: f64,
    origin: [f64; 3],
    #[serde(default)]
    negate: u8,
    occupied_thresh: f64,
    free_thresh: f64,
    #[serde(default)]
    mode: Option<String>,
}

impl Grid {
    /// A grid of `width × height` cells of `resolution` metres, all `fill`.
    pub fn new(width: usize, height: usize, resolution: f64, origin: [f64; 2], fill: Cell) -> Self {
        Self {
            width,
            height,
            resolution,
            origin,
            cells: vec![fill; width * height],
        }
    }

    /// Cells across.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Cells up.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Cell size, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// World position of the lower-left corner of cell (0, 0), metres.
    pub fn origin(&self) -> [f64; 2] {
        self.origin
    }

    /// All cells, row-major from the bottom row.
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// The flat index of a cell.
    pub fn index(&self, (x, y): CellXY) -> usize {
        y * self.width + x
    }

    /// The cell at a flat index.
    pub fn xy(&self, i: usize) -> CellXY {
        (i % self.width, i / self.width)
    }

    /// The cell at `(x, y)`; outside the grid counts as occupied (the outside of a building is solid).
    pub fn get(&self, (x, y): CellXY) -> Cell {
        if x < self.width && y < self.height {
            self.cells[y * self.width + x]
        } else {
            Cell::Occupied
        }
    }

    /// Sets a cell; outside the grid is ignored.
    pub fn set(&mut self, (x, y): CellXY, c: Cell) {
        if x < self.width && y < self.height {
            self.cells[y * self.width + x] = c;
        }
    }

    /// The cell containing a point of the map frame, `None` outside the grid.
    pub fn cell_of(&self, point_in_map: [f64; 2]) -> Option<CellXY> {
        let fx = (point_in_map[0] - self.origin[0]) / self.resolution;
        let fy = (point_in_map[1] - self.origin[1]) / self.resolution;
        if !(fx.is_finite() && fy.is_finite()) || fx < 0.0 || fy < 0.0 {
            return None;
        }
        let (x, y) = (fx as usize, fy as usize);
        (x < self.width && y < self.height).then_some((x, y))
    }

    /// The map-frame position of a cell's centre.
    pub fn center_of(&self, (x, y): CellXY) -> [f64; 2] {
        [
            self.origin[0] + (x as f64 + 0.5) * self.resolution,
            self.origin[1] + (y as f64 + 0.5) * self.resolution,
        ]
    }

    /// Loads a `map_server` map: the YAML and the image it names (PGM or PNG), thresholded as in
    /// trinary mode (`p = (255 − v)/255`, or `v/255` with `negate`; occupied above
    /// `occupied_thresh`, free below `free_thresh`, unknown between).
    pub fn load(yaml_path: impl AsRef<Path>) -> Result<Self, MapError> {
        let yaml_path = yaml_path.as_ref();
        let text = std::fs::read_to_string(yaml_path).map_err(|why| MapError::Io {
            path: yaml_path.into(),
            why,
        })?;
        Self::from_map_server(yaml_path, &text, |image_path| {
            std::fs::read(image_path).map_err(|why| MapError::Io {
                path: image_path.into(),
                why,
            })
        })
    }

    /// A `map_server` map from its YAML's text (`yaml_path` names it in errors and places the
    /// image) and a reader of the image file it names, as [`Grid::load`] does.
    pub fn from_map_server(
        yaml_path: &Path,
        text: &str,
        read_image: impl FnOnce(&Path) -> Result<Vec<u8>, MapError>,
    ) -> Result<Self, MapError> {
        let yaml_err = |reason: String| MapError::Yaml {
            path: yaml_path.into(),
            reason,
        };
        let meta: MapYaml = serde_yaml_ng::from_str(text).map_err(|e| yaml_err(e.to_string()))?;
        if !(meta.resolution.is_finite() && meta.resolution > 0.0) {
            return Err(yaml_err(format!(
                "resolution {} must be a positive number of metres",
                meta.resolution
            )));
        }
        if meta.origin.iter().any(|v| !v.is_finite()) {
            return Err(yaml_err(
                "origin must be three finite numbers [x, y, yaw]".into(),
            ));
        }
        if meta.origin[2] != 0.0 {
            return Err(yaml_err(format!(
                "origin yaw {} is not supported: rotate the image instead",
                meta.origin[2]
            )));
        }
        if !(0.0..=1.0).contains(&meta.free_thresh)
            || !(0.0..=1.0).contains(&meta.occupied_thresh)
            || meta.free_thresh > meta.occupied_thresh
        {
            return Err(yaml_err(
                "thresholds must satisfy 0 ≤ free_thresh ≤ occupied_thresh ≤ 1".into(),
            ));
        }
        match meta.mode.as_deref() {
            None | Some("trinary") | Some("scale") => {}
            Some(m) => {
                return Err(yaml_err(format!(
                    "mode {m:?} is not supported (trinary or scale)"
                )));
            }
        }
        let image_path = yaml_path
            .parent()
            .unwrap_or(Path::new("."))
            .join(&meta.image);
        let bytes = read_image(&image_path)?;
        let img = image::load_from_memory(&bytes)
            .map_err(|e| MapError::Image {
                path: image_path.clone(),
                reason: e.to_string(),
            })?
            .to_luma8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        if w == 0 || h == 0 {
            return Err(MapError::Image {
                path: image_path,
                reason: "the image is empty".into(),
            });
        }
        let mut grid = Grid::new(
            w,
            h,
            meta.resolution,
            [meta.origin[0], meta.origin[1]],
            Cell::Unknown,
        );
        for (px, py, Luma([v])) in img.enumerate_pixels() {
            let v = f64::from(*v);
            let p = if meta.negate != 0 {
                v / 255.0
            } else {
                (255.0 - v) / 255.0
            };
            let c = if p > meta.occupied_thresh {
                Cell::Occupied
            } else if p < meta.free_thresh {
                Cell::Free
            } else {
                Cell::Unknown
            };
            grid.set((px as usize, h - 1 - py as usize), c);
        }
        Ok(grid)
    }

    /// Saves as a `map_server` map: `yaml_path` and a PGM beside it with the same stem
    /// (free 254, occupied 0, unknown 205, as `map_saver` writes).
    pub fn save(&self, yaml_path: impl AsRef<Path>) -> Result<(), MapError> {
        let yaml_path = yaml_path.as_ref();
        let pgm_path = yaml_path.with_extension("pgm");
        let mut img = GrayImage::new(self.width as u32, self.height as u32);
        for (i, c) in self.cells.iter().enumerate() {
            let (x, y) = self.xy(i);
            let v = match c {
                Cell::Free => 254,
                Cell::Occupied => 0,
                Cell::Unknown => 205,
            };
            img.put_pixel(x as u32, (self.height - 1 - y) as u32, Luma([v]));
        }
        // Binary PGM (P5), as map_server reads it; the image crate's default PNM is PAM (P7).
        let file = std::fs::File::create(&pgm_path).map_err(|why| MapError::Io {
            path: pgm_path.clone(),
            why,
        })?;
        let encoder = PnmEncoder::new(std::io::BufWriter::new(file))
            .with_subtype(PnmSubtype::Graymap(SampleEncoding::Binary));
        img.write_with_encoder(encoder)
            .map_err(|e| MapError::Image {
                path: pgm_path.clone(),
                reason: e.to_string(),
            })?;
        let name = pgm_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let yaml = format!(
            "image: {name}\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
            self.resolution, self.origin[0], self.origin[1]
        );
        std::fs::write(yaml_path, yaml).map_err(|why| MapError::Io {
            path: yaml_path.into(),
            why,
        })
    }

    /// The map as a picture: free white, occupied black, unknown grey, north up, `scale` pixels
    /// per cell.
    pub fn render(&self, scale: u32) -> RgbImage {
        let s = scale.max(1);
        RgbImage::from_fn(self.width as u32 * s, self.height as u32 * s, |px, py| {
            let (x, y) = ((px / s) as usize, self.height - 1 - (py / s) as usize);
            match self.get((x, y)) {
                Cell::Free => Rgb([255, 255, 255]),
                Cell::Occupied => Rgb([0, 0, 0]),
                Cell::Unknown => Rgb([160, 160, 160]),
            }
        })
    }

    /// Counts of free, occupied and unknown cells.
    pub fn counts(&self) -> [usize; 3] {
        let mut n = [0; 3];
        for c in &self.cells {
            n[*c as usize] += 1;
        }
        n
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Builds a grid of 0.1 m cells from rows of text, top row first: `.` free, `#` occupied,
    /// `?` unknown.
    pub(crate) fn grid(rows: &[&str]) -> Grid {
        grid_with(rows, 0.1)
    }

    /// [`grid`] with another cell size.
    pub(crate) fn grid_with(rows: &[&str], resolution: f64) -> Grid {
        let h = rows.len();
        let w = rows[0].len();
        let mut g = Grid::new(w, h, resolution, [0.0, 0.0], Cell::Unknown);
        for (r, line) in rows.iter().enumerate() {
            for (x, ch) in line.chars().enumerate() {
                let c = match ch {
                    '.' => Cell::Free,
                    '#' => Cell::Occupied,
                    _ => Cell::Unknown,
                };
                g.set((x, h - 1 - r), c);
            }
        }
        g
    }

    pub(crate) fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/maps")
            .join(name)
    }

    #[test]
    fn a_length_of_whole_cells_is_whole() {
        assert_eq!(in_cells(0.35, 0.05), 7.0);
        assert_eq!(in_cells(0.3, 0.05), 6.0);
        assert_eq!(in_cells(0.15, 0.05), 3.0);
        assert_eq!(in_cells(0.45, 0.05), 9.0);
        assert_eq!(in_cells(0.0, 0.05), 0.0);
        // Not near a whole number: as divided.
        assert!((in_cells(0.27, 0.05) - 5.4).abs() < 1e-12);
        assert!((in_cells(0.21, 0.1) - 2.1).abs() < 1e-12);
    }

    #[test]
    fn world_and_cells_agree() {
        let g = Grid::new(10, 5, 0.5, [-1.0, 2.0], Cell::Free);
        assert_eq!(g.cell_of([-1.0, 2.0]), Some((0, 0)));
        assert_eq!(g.cell_of([3.99, 4.49]), Some((9, 4)));
        assert_eq!(g.cell_of([4.0, 3.0]), None);
        assert_eq!(g.cell_of([-1.01, 3.0]), None);
        assert_eq!(g.cell_of([f64::NAN, 3.0]), None);
        assert_eq!(g.center_of((1, 2)), [-0.25, 3.25]);
        assert_eq!(g.get((10, 0)), Cell::Occupied, "outside is solid");
    }

    #[test]
    fn real_maps_load_with_plausible_counts() {
        let willow = Grid::load(data("willow-full.yaml")).unwrap();
        assert_eq!(
            (willow.width(), willow.height(), willow.resolution()),
            (540, 587, 0.1)
        );
        // Exactly what map_server's trinary rule gives for this file's pixels (counted in Python).
        // Its grey 206 is p = 49/255 = 0.192 < free_thresh 0.196, so map_server reads it as free.
        assert_eq!(willow.counts(), [300_466, 8_419, 8_095]);
        let b31 = Grid::load(data("building_31.yaml")).unwrap();
        assert_eq!((b31.width(), b31.height()), (693, 648));
        assert_eq!(b31.origin(), [-26.0, -11.0]);
        assert_eq!(b31.counts(), [431_063, 17_553, 448]);
    }

    #[test]
    fn save_and_load_round_trip() {
        let g = grid(&["#..?", "#.#?", "...."]);
        let dir = std::env::temp_dir().join(format!("nav-grid-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let yaml = dir.join("m.yaml");
        g.save(&yaml).unwrap();
        assert_eq!(Grid::load(&yaml).unwrap(), g);
        // map_server reads binary PGM: "P5", width, height, maxval, then one byte per cell.
        let pgm = std::fs::read(dir.join("m.pgm")).unwrap();
        assert!(pgm.starts_with(b"P5\n4 3 255\n"), "{:?}", &pgm[..12]);
        assert_eq!(pgm.len(), b"P5\n4 3 255\n".len() + 12);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_map_files_say_what_is_wrong() {
        let dir = std::env::temp_dir().join(format!("nav-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let case = |yaml: &str| {
            let p = dir.join("bad.yaml");
            std::fs::write(&p, yaml).unwrap();
            Grid::load(&p).unwrap_err().to_string()
        };
        assert!(case("image: x.pgm\nresolution: -1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n").contains("resolution"));
        assert!(case("image: x.pgm\nresolution: 0.1\norigin: [0,0,1.5]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n").contains("yaw"));
        assert!(case("image: x.pgm\nresolution: 0.1\norigin: [0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n").contains("not a map_server"));
        assert!(case("image: missing.pgm\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n").contains("missing.pgm"));
        assert!(case("not: [valid").contains("not a map_server"));
        assert!(
            Grid::load(dir.join("nope.yaml"))
                .unwrap_err()
                .to_string()
                .contains("nope.yaml")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
