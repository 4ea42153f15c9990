//! The simulated building: a floor plan of cells extruded from the floor (z = 0) to the ceiling.
//!
//! A world is loaded from one of three formats:
//!
//! * a **world text file** (`.txt`): one character per cell, north up — `#` textured wall,
//!   `+` featureless wall, `~` glass, `.` floor, `1`–`9` a drone's start, space outside — after a
//!   header of `resolution M` and `ceiling M` lines and a `---` line (see `worlds/apartment.txt`);
//! * a ROS **`map_server`** map (`.yaml` naming a PGM or PNG): free cells are floor, occupied and
//!   unknown cells are walls (an unobserved region is not a place to fly);
//! * a **HouseExpo** floor plan (`.json`): the `verts` polygon, in metres, bounds the floor.
//!
//! Everything outside the plan is solid, so maps with gaps and open edges stay closed.

use std::path::{Path, PathBuf};

use nav::grid::{Cell, Grid};

/// What a cell is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Material {
    /// Open floor from the floor to the ceiling.
    Free,
    /// A wall with a textured surface (features for the camera).
    Wall,
    /// A wall with a plain, featureless surface.
    Plain,
    /// Glass: solid to the drone, invisible to the depth camera.
    Glass,
}

impl Material {
    /// True for anything a drone cannot fly through.
    pub fn is_solid(self) -> bool {
        self != Material::Free
    }
}

/// A world that could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A `map_server` map could not be loaded.
    #[error(transparent)]
    Map(#[from] nav::grid::MapError),
    /// The file's content is not a world.
    #[error("{path}: {reason}")]
    Format {
        /// The file (or built-in world name).
        path: PathBuf,
        /// What is wrong, and what a valid file looks like.
        reason: String,
    },
    /// No built-in world has this name and no such file exists.
    #[error(
        "no world '{0}': give a built-in name ({names}) or a .txt, .yaml or .json file",
        names = BUILT_IN.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
    )]
    Unknown(String),
}

/// The built-in worlds, by name.
pub const BUILT_IN: [(&str, &str); 1] = [("apartment", include_str!("../worlds/apartment.txt"))];

/// The world used when none is named.
pub const DEFAULT_WORLD: &str = "apartment";

/// A floor plan: cells row-major from the bottom row, and where they lie.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Cells across.
    pub width: usize,
    /// Cells up.
    pub height: usize,
    /// Cell size, metres.
    pub resolution: f64,
    /// Map-frame position of the lower-left corner of cell (0, 0).
    pub origin: [f64; 2],
    /// The cells, `width × height`, row 0 at the bottom.
    pub cells: Vec<Material>,
}

/// A floor plan extruded to a ceiling.
#[derive(Debug, Clone)]
pub struct World {
    name: String,
    width: usize,
    height: usize,
    resolution: f64,
    origin: [f64; 2],
    ceiling: f64,
    cells: Vec<Material>,
    /// Distance from each cell's centre to the nearest solid cell's centre, in cells (chamfer).
    clearance: Vec<f32>,
    starts: Vec<[f64; 2]>,
}

/// Ceiling height used for maps that do not give one, metres.
pub const DEFAULT_CEILING: f64 = 2.6;

impl World {
    /// A world from its floor plan, for tests and generated worlds; without `starts`, start
    /// positions are chosen in the most open space.
    ///
    /// # Panics
    /// If the plan's cells do not fill `width × height`.
    pub fn new(name: &str, plan: Plan, ceiling: f64, starts: Vec<[f64; 2]>) -> Self {
        let Plan {
            width,
            height,
            resolution,
            origin,
            cells,
        } = plan;
        assert_eq!(cells.len(), width * height, "cells must fill the grid");
        let clearance = chamfer(width, height, &cells);
        let mut world = Self {
            name: name.into(),
            width,
            height,
            resolution,
            origin,
            ceiling,
            cells,
            clearance,
            starts,
        };
        if world.starts.is_empty() {
            world.starts = world.automatic_starts(9);
        }
        world
    }

    /// Loads a built-in world by name, or a world file (`.txt`, `.yaml`, `.json`).
    pub fn load(name_or_path: &str) -> Result<Self, WorldError> {
        if let Some((name, text)) = BUILT_IN.iter().find(|(n, _)| *n == name_or_path) {
            return Self::parse_text(name, text);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(WorldError::Unknown(name_or_path.into()));
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        match ext.as_str() {
            "yaml" | "yml" => Self::from_map_server(path),
            "json" => Self::from_house_expo(path),
            "txt" | "world" => {
                let text = read(path)?;
                let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("world");
                Self::parse_text(name, &text).map_err(|e| match e {
                    WorldError::Format { reason, .. } => WorldError::Format {
                        path: path.into(),
                        reason,
                    },
                    e => e,
                })
            }
            _ => Err(WorldError::Format {
                path: path.into(),
                reason: "unknown world format: use .txt (world text), .yaml (map_server) or .json (HouseExpo)".into(),
            }),
        }
    }

    /// Parses a world text (see the module documentation).
    pub fn parse_text(name: &str, text: &str) -> Result<Self, WorldError> {
        let err = |reason: String| WorldError::Format {
            path: name.into(),
            reason,
        };
        let mut resolution = None;
        let mut ceiling = DEFAULT_CEILING;
        let mut lines = text.lines();
        for line in lines.by_ref() {
            let line = line.trim();
            if line == "---" {
                break;
            }
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (key, value) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
            let value: f64 = value
                .trim()
                .parse()
                .map_err(|_| err(format!("'{line}': expected '{key} <metres>'")))?;
            if !(value.is_finite() && value > 0.0) {
                return Err(err(format!(
                    "'{line}': must be a positive number of metres"
                )));
            }
            match key {
                "resolution" => resolution = Some(value),
                "ceiling" => ceiling = value,
                _ => {
                    return Err(err(format!(
                        "unknown header line '{line}' (expected resolution, ceiling or ---)"
                    )));
                }
            }
        }
        let resolution = resolution
            .ok_or_else(|| err("the header has no 'resolution M' line before '---'".into()))?;
        let rows: Vec<&str> = lines.collect();
        let rows: Vec<&str> = rows
            .iter()
            .rev()
            .skip_while(|r| r.trim().is_empty())
            .copied()
            .collect(); // bottom row first
        let height = rows.len();
        let width = rows.iter().map(|r| r.chars().count()).max().unwrap_or(0);
        if width == 0 || height == 0 {
            return Err(err("no map rows after '---'".into()));
        }
        let mut cells = vec![Material::Wall; width * height];
        let mut starts: Vec<(u32, [f64; 2])> = vec![];
        for (y, row) in rows.iter().enumerate() {
            for (x, c) in row.chars().enumerate() {
                let m = match c {
                    '#' | ' ' => Material::Wall,
                    '+' => Material::Plain,
                    '~' => Material::Glass,
                    '.' => Material::Free,
                    '1'..='9' => {
                        let centre = [(x as f64 + 0.5) * resolution, (y as f64 + 0.5) * resolution];
                        starts.push((c.to_digit(10).unwrap_or(0), centre));
                        Material::Free
                    }
                    _ => {
                        return Err(err(format!(
                            "row {} column {}: unknown character '{c}' (use # + ~ . 1-9 or space)",
                            height - y,
                            x + 1
                        )));
                    }
                };
                cells[y * width + x] = m;
            }
        }
        starts.sort_by_key(|(k, _)| *k);
        if let Some(w) = starts.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(err(format!("start {} appears twice", w[0].0)));
        }
        let starts = starts.into_iter().map(|(_, p)| p).collect();
        let plan = Plan {
            width,
            height,
            resolution,
            origin: [0.0, 0.0],
            cells,
        };
        Ok(Self::new(name, plan, ceiling, starts))
    }

    /// Loads a ROS `map_server` map; free cells are floor, everything else is wall.
    pub fn from_map_server(yaml: &Path) -> Result<Self, WorldError> {
        let grid = Grid::load(yaml)?;
        let cells = grid
            .cells()
            .iter()
            .map(|c| match c {
                Cell::Free => Material::Free,
                _ => Material::Wall,
            })
            .collect();
        let name = yaml.file_stem().and_then(|s| s.to_str()).unwrap_or("map");
        let plan = Plan {
            width: grid.width(),
            height: grid.height(),
            resolution: grid.resolution(),
            origin: grid.origin(),
            cells,
        };
        let world = Self::new(name, plan, DEFAULT_CEILING, vec![]);
        world.require_starts(yaml)
    }

    /// Loads a HouseExpo floor plan, rasterised at 0.05 m.
    pub fn from_house_expo(json: &Path) -> Result<Self, WorldError> {
        #[derive(serde::Deserialize)]
        struct HouseExpo {
            verts: Vec<[f64; 2]>,
        }
        let text = read(json)?;
        let err = |reason: String| WorldError::Format {
            path: json.into(),
            reason,
        };
        let plan: HouseExpo = serde_json::from_str(&text).map_err(|e| {
            err(format!(
                "not a HouseExpo plan (expected {{\"verts\": [[x, y], ...]}}): {e}"
            ))
        })?;
        if plan.verts.len() < 3 || plan.verts.iter().flatten().any(|v| !v.is_finite()) {
            return Err(err(
                "'verts' must be at least three finite [x, y] points".into()
            ));
        }
        let resolution = 0.05;
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for v in &plan.verts {
            for k in 0..2 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        if span > 200.0 {
            return Err(err(format!(
                "the plan spans {span:.0} m; HouseExpo plans are in metres and a few tens of metres across"
            )));
        }
        // One wall cell of margin around the polygon.
        let origin = [lo[0] - 2.0 * resolution, lo[1] - 2.0 * resolution];
        let width = ((hi[0] - origin[0]) / resolution).ceil() as usize + 2;
        let height = ((hi[1] - origin[1]) / resolution).ceil() as usize + 2;
        let mut cells = vec![Material::Wall; width * height];
        for y in 0..height {
            let py = origin[1] + (y as f64 + 0.5) * resolution;
            for x in 0..width {
                let px = origin[0] + (x as f64 + 0.5) * resolution;
                if inside(&plan.verts, [px, py]) {
                    cells[y * width + x] = Material::Free;
                }
            }
        }
        // The polygon's edges are the walls' faces: a cell is floor when its centre is inside, so
        // rooms and doors keep the plan's sizes to within a cell (an outline of wall cells drawn
        // inside the polygon made every door 0.1 m narrower than the plan's).
        let name = json.file_stem().and_then(|s| s.to_str()).unwrap_or("house");
        let plan = Plan {
            width,
            height,
            resolution,
            origin,
            cells,
        };
        let world = Self::new(name, plan, DEFAULT_CEILING, vec![]);
        world.require_starts(json)
    }

    fn require_starts(self, path: &Path) -> Result<Self, WorldError> {
        if self.starts.is_empty() {
            return Err(WorldError::Format {
                path: path.into(),
                reason: "no free space wide enough for a drone (0.5 m clearance) in this map"
                    .into(),
            });
        }
        Ok(self)
    }

    /// Start positions for up to `n` drones: the free cell with the most clearance in the largest
    /// open area, then cells about 1 m apart around it with at least 0.5 m clearance.
    fn automatic_starts(&self, n: usize) -> Vec<[f64; 2]> {
        let need = (0.5 / self.resolution) as f32 + 0.5;
        let Some(first) = (0..self.cells.len())
            .filter(|&i| self.clearance[i] >= need)
            .max_by(|&a, &b| {
                self.clearance[a]
                    .total_cmp(&self.clearance[b])
                    .then(b.cmp(&a))
            })
        else {
            return vec![];
        };
        // Breadth-first over cells with clearance, taking cells at least 1 m from every start so far.
        let mut seen = vec![false; self.cells.len()];
        let mut queue = std::collections::VecDeque::from([first]);
        seen[first] = true;
        let mut starts = vec![self.center(first)];
        while let Some(i) = queue.pop_front() {
            if starts.len() >= n {
                break;
            }
            let p = self.center(i);
            if starts.iter().all(|s| dist(*s, p) >= 1.0) {
                starts.push(p);
            }
            let (x, y) = (i % self.width, i / self.width);
            for (dx, dy) in [(0, 1), (2, 1), (1, 0), (1, 2)] {
                let (nx, ny) = ((x + dx).wrapping_sub(1), (y + dy).wrapping_sub(1));
                if nx < self.width && ny < self.height {
                    let j = ny * self.width + nx;
                    if !seen[j] && self.clearance[j] >= need {
                        seen[j] = true;
                        queue.push_back(j);
                    }
                }
            }
        }
        starts
    }

    fn center(&self, i: usize) -> [f64; 2] {
        let (x, y) = (i % self.width, i / self.width);
        [
            self.origin[0] + (x as f64 + 0.5) * self.resolution,
            self.origin[1] + (y as f64 + 0.5) * self.resolution,
        ]
    }

    /// The world's name (built-in name or file stem).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Cells across and up.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Cell size, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Map-frame position of the lower-left corner of cell (0, 0).
    pub fn origin(&self) -> [f64; 2] {
        self.origin
    }

    /// Ceiling height, metres above the floor.
    pub fn ceiling(&self) -> f64 {
        self.ceiling
    }

    /// The drones' start positions (map frame, metres), in order.
    pub fn starts(&self) -> &[[f64; 2]] {
        &self.starts
    }

    /// The material of cell `(x, y)`; outside the plan is wall.
    pub fn material(&self, x: i64, y: i64) -> Material {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            Material::Wall
        } else {
            self.cells[y as usize * self.width + x as usize]
        }
    }

    /// Clearance of cell `(x, y)` in cells: at least this far (centre to centre, within 8 %) from
    /// any solid cell; 0 for solid cells and outside.
    pub fn clearance(&self, x: i64, y: i64) -> f32 {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            0.0
        } else {
            self.clearance[y as usize * self.width + x as usize]
        }
    }

    /// The cell containing a map-frame point (may lie outside the plan).
    pub fn cell_of(&self, point_in_map: [f64; 2]) -> (i64, i64) {
        (
            ((point_in_map[0] - self.origin[0]) / self.resolution).floor() as i64,
            ((point_in_map[1] - self.origin[1]) / self.resolution).floor() as i64,
        )
    }

    /// True when a disc of `radius` at `point_in_map` overlaps a solid cell (or leaves the plan).
    pub fn disc_hits_wall(&self, point_in_map: [f64; 2], radius: f64) -> bool {
        if !(point_in_map[0].is_finite() && point_in_map[1].is_finite()) {
            return true;
        }
        let (x0, y0) = self.cell_of([point_in_map[0] - radius, point_in_map[1] - radius]);
        let (x1, y1) = self.cell_of([point_in_map[0] + radius, point_in_map[1] + radius]);
        for y in y0..=y1 {
            for x in x0..=x1 {
                if !self.material(x, y).is_solid() {
                    continue;
                }
                // Nearest point of the cell to the disc's centre.
                let cx0 = self.origin[0] + x as f64 * self.resolution;
                let cy0 = self.origin[1] + y as f64 * self.resolution;
                let nx = point_in_map[0].clamp(cx0, cx0 + self.resolution);
                let ny = point_in_map[1].clamp(cy0, cy0 + self.resolution);
                if dist([nx, ny], point_in_map) < radius {
                    return true;
                }
            }
        }
        false
    }

    /// The floor plan as a ternary grid: floor free, everything else occupied (glass included).
    pub fn to_grid(&self) -> Grid {
        let mut grid = Grid::new(
            self.width,
            self.height,
            self.resolution,
            self.origin,
            Cell::Free,
        );
        for (i, m) in self.cells.iter().enumerate() {
            if m.is_solid() {
                grid.set((i % self.width, i / self.width), Cell::Occupied);
            }
        }
        grid
    }
}

fn read(path: &Path) -> Result<String, WorldError> {
    std::fs::read_to_string(path).map_err(|source| WorldError::Io {
        path: path.into(),
        source,
    })
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Even–odd point-in-polygon test.
fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut inside = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[j]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// Two-pass chamfer distance (1, √2) from every cell to the nearest solid cell, in cells. It
/// overestimates the Euclidean distance by at most 8.3 %.
fn chamfer(width: usize, height: usize, cells: &[Material]) -> Vec<f32> {
    const D: f32 = std::f32::consts::SQRT_2;
    let big = (width + height) as f32 * 2.0;
    let mut d: Vec<f32> = cells
        .iter()
        .map(|m| if m.is_solid() { 0.0 } else { big })
        .collect();
    // Cells beyond the border are solid: seed the border with distance 1.
    for y in 0..height {
        for x in 0..width {
            if x == 0 || y == 0 || x + 1 == width || y + 1 == height {
                let i = y * width + x;
                d[i] = d[i].min(1.0);
            }
        }
    }
    let at = |d: &[f32], x: isize, y: isize| -> f32 {
        if x < 0 || y < 0 || x as usize >= width || y as usize >= height {
            0.0
        } else {
            d[y as usize * width + x as usize]
        }
    };
    for y in 0..height as isize {
        for x in 0..width as isize {
            let i = y as usize * width + x as usize;
            let v = d[i]
                .min(at(&d, x - 1, y) + 1.0)
                .min(at(&d, x, y - 1) + 1.0)
                .min(at(&d, x - 1, y - 1) + D)
                .min(at(&d, x + 1, y - 1) + D);
            d[i] = v;
        }
    }
    for y in (0..height as isize).rev() {
        for x in (0..width as isize).rev() {
            let i = y as usize * width + x as usize;
            let v = d[i]
                .min(at(&d, x + 1, y) + 1.0)
                .min(at(&d, x, y + 1) + 1.0)
                .min(at(&d, x + 1, y + 1) + D)
                .min(at(&d, x - 1, y + 1) + D);
            d[i] = v;
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/maps")
            .join(name)
    }

    #[test]
    fn the_default_apartment_loads_with_eight_starts_on_the_floor() {
        let w = World::load(DEFAULT_WORLD).unwrap();
        assert_eq!(w.size(), (75, 48));
        assert_eq!(w.resolution(), 0.2);
        assert_eq!(w.ceiling(), 2.6);
        assert_eq!(w.starts().len(), 8);
        assert!((w.starts()[0][0] - 13.1).abs() < 1e-9 && (w.starts()[0][1] - 2.1).abs() < 1e-9);
        for s in w.starts() {
            assert!(!w.disc_hits_wall(*s, 0.3), "{s:?}");
        }
        // The outer wall, the featureless bathroom wall, the corridor.
        assert_eq!(w.material(0, 10), Material::Wall);
        assert_eq!(w.material(30, 1), Material::Plain);
        assert_eq!(w.material(30, 22), Material::Free);
        assert_eq!(w.material(-1, 10), Material::Wall);
        assert_eq!(w.material(75, 10), Material::Wall);
    }

    #[test]
    fn world_text_errors_say_where_and_what() {
        let e = World::parse_text("t", "resolution 0.1\n---\n#.x#\n").unwrap_err();
        assert!(
            e.to_string()
                .contains("row 1 column 3: unknown character 'x'"),
            "{e}"
        );
        let e = World::parse_text("t", "---\n#..#\n").unwrap_err();
        assert!(e.to_string().contains("no 'resolution M' line"), "{e}");
        let e = World::parse_text("t", "resolution -1\n---\n#\n").unwrap_err();
        assert!(e.to_string().contains("positive"), "{e}");
        let e = World::parse_text("t", "resolution 0.1\n---\n#1.1#\n").unwrap_err();
        assert!(e.to_string().contains("start 1 appears twice"), "{e}");
        let e = World::load("no-such-world").unwrap_err();
        assert!(e.to_string().contains("apartment"), "{e}");
    }

    #[test]
    fn glass_and_plain_walls_are_solid_and_outside_is_wall() {
        let w = World::parse_text("t", "resolution 0.5\n---\n~+.\n").unwrap();
        assert!(w.disc_hits_wall([0.25, 0.25], 0.1));
        assert!(w.disc_hits_wall([0.75, 0.25], 0.1));
        assert!(w.disc_hits_wall([1.25, 0.25], 0.3)); // reaches outside the plan
        assert!(!w.disc_hits_wall([1.25, 0.25], 0.2));
    }

    #[test]
    fn chamfer_clearance_is_within_eight_percent_of_euclidean() {
        let w = World::load(DEFAULT_WORLD).unwrap();
        let (width, height) = w.size();
        let solid: Vec<(i64, i64)> = (0..width as i64)
            .flat_map(|x| (0..height as i64).map(move |y| (x, y)))
            .filter(|&(x, y)| w.material(x, y).is_solid())
            .collect();
        for y in (1..height as i64 - 1).step_by(3) {
            for x in (1..width as i64 - 1).step_by(3) {
                let exact = solid
                    .iter()
                    .map(|&(sx, sy)| ((sx - x) as f64).hypot((sy - y) as f64))
                    .fold(f64::MAX, f64::min);
                let c = w.clearance(x, y) as f64;
                assert!(
                    c >= exact - 1e-6 && c <= exact * 1.083 + 1e-6,
                    "({x},{y}) {c} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn real_maps_load_closed_with_starts_in_free_space() {
        let willow = World::load(data("willow-full.yaml").to_str().unwrap()).unwrap();
        assert_eq!(willow.size(), (540, 587));
        assert!(willow.starts().len() >= 8);
        let building = World::load(data("building_31.yaml").to_str().unwrap()).unwrap();
        assert_eq!(building.origin(), [-26.0, -11.0]);
        let house = World::load(data("house_expo_room_0000.json").to_str().unwrap()).unwrap();
        // ~10 × 8 m at 0.05 m: the polygon's bounding box plus margins.
        let (hw, hh) = house.size();
        assert!(
            (205..=210).contains(&hw) && (165..=170).contains(&hh),
            "{hw}×{hh}"
        );
        for w in [&willow, &building, &house] {
            for s in w.starts() {
                assert!(!w.disc_hits_wall(*s, 0.45), "{}: {s:?}", w.name());
            }
            // The border is solid even where the map is free up to its edge.
            let (width, height) = w.size();
            assert!(w.material(width as i64, height as i64 / 2).is_solid());
        }
        // Inside the house polygon is free, outside solid.
        let (x, y) = house.cell_of([3.0, 2.0]);
        assert_eq!(house.material(x, y), Material::Free);
        let (x, y) = house.cell_of([0.0, 0.0]);
        assert!(house.material(x, y).is_solid());
        // Doors keep the plan's width: the one in the wall at x ≈ 5.1 m spans y 3.68–4.42 m.
        let door = (0..30)
            .map(|k| house.cell_of([5.12, 3.5 + 0.05 * k as f64]))
            .filter(|&(x, y)| !house.material(x, y).is_solid())
            .count();
        assert!(
            (14..=15).contains(&door),
            "{door} free cells across the door"
        );
    }

    #[test]
    fn bad_house_expo_is_a_clear_error() {
        let dir = std::env::temp_dir().join(format!("sitl-world-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("bad.json");
        std::fs::write(&f, r#"{"verts": [[0, 0], [1, 0]]}"#).unwrap();
        let e = World::load(f.to_str().unwrap()).unwrap_err();
        assert!(e.to_string().contains("at least three"), "{e}");
        std::fs::write(&f, "not json").unwrap();
        let e = World::load(f.to_str().unwrap()).unwrap_err();
        assert!(e.to_string().contains("not a HouseExpo plan"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
