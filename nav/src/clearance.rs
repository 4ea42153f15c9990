//! Paths that keep their distance: through the middle of a door, not along its frame.
//!
//! A shortest path on the inflated map touches the inflation's edge at every corner it rounds,
//! and its straight shortcuts graze those corners. At a door 0.8 m wide, where only the
//! narrowest inflation (0.25 m for a drone of 0.2 m) leaves a way through, that is 5 cm between
//! the drone and the door frame, which a path follower rounding the corner, or a gust, takes
//! (seen: on true poses, every collision of a two-drone mission was at a door frame).
//! [`centred_path`] searches with a step cost that grows near anything not free, within a window
//! around the shortest path, and shortens the result only where a shortcut keeps the clearance
//! the path had.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use image::{GrayImage, Luma};
use imageproc::distance_transform::euclidean_squared_distance_transform;

use crate::grid::{Cell, CellXY, Grid};
use crate::search::{DIAGONAL, STRAIGHT, UNREACHABLE, astar, line_of_sight};

/// The path searched within this many cells of the shortest path's bounding box.
const WINDOW_MARGIN: usize = 40;

/// Only this many cells of the shortest path are centred (10 m at 5 cm), the rest kept as it is:
/// a robot replans long before it gets there, and the search's window stays small on a large
/// building.
const HORIZON: usize = 200;

/// A step next to an obstacle costs this many times a step in the open, tapering to nothing at
/// the comfort distance.
const NEAR_WEIGHT: f64 = 2.0;

/// Distance of each cell of a window of a grid to the nearest cell that is not free (outside
/// the grid counts as not free), in cells, edge to centre.
struct Clearance {
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    cells: Vec<f32>,
}

impl Clearance {
    fn new(grid: &Grid, x0: usize, y0: usize, width: usize, height: usize) -> Self {
        // One cell of border round the window: the map beyond it, or solid off the map.
        let blocked = GrayImage::from_fn(width as u32 + 2, height as u32 + 2, |i, j| {
            let (x, y) = (
                (x0 + i as usize).checked_sub(1),
                (y0 + j as usize).checked_sub(1),
            );
            let free = match (x, y) {
                (Some(x), Some(y)) if x < grid.width() && y < grid.height() => {
                    grid.get((x, y)) == Cell::Free
                }
                _ => false,
            };
            Luma([u8::from(!free)])
        });
        let d2 = euclidean_squared_distance_transform(&blocked);
        let mut cells = Vec::with_capacity(width * height);
        for j in 0..height {
            for i in 0..width {
                let Luma([d]) = *d2.get_pixel(i as u32 + 1, j as u32 + 1);
                cells.push((d.sqrt() - 0.5).max(0.0) as f32);
            }
        }
        Self {
            x0,
            y0,
            width,
            height,
            cells,
        }
    }

    fn contains(&self, (x, y): CellXY) -> bool {
        x >= self.x0 && y >= self.y0 && x < self.x0 + self.width && y < self.y0 + self.height
    }

    fn index(&self, (x, y): CellXY) -> usize {
        (y - self.y0) * self.width + (x - self.x0)
    }

    /// Clearance of a cell of the window, cells.
    fn at(&self, c: CellXY) -> f64 {
        f64::from(self.cells[self.index(c)])
    }

    /// The least clearance along the straight segment between two cell centres, cells.
    fn along(&self, a: CellXY, b: CellXY) -> f64 {
        let (ax, ay, bx, by) = (a.0 as f64, a.1 as f64, b.0 as f64, b.1 as f64);
        let steps = ((bx - ax).abs().max((by - ay).abs()) * 2.0).ceil().max(1.0) as usize;
        (0..=steps)
            .map(|k| {
                let t = k as f64 / steps as f64;
                let c = (
                    (ax + (bx - ax) * t).round() as usize,
                    (ay + (by - ay) * t).round() as usize,
                );
                if self.contains(c) { self.at(c) } else { 0.0 }
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// A path from `start` to `goal` over the free cells of `inflated` that keeps `comfort_m` from
/// anything not free where it can: A* whose steps cost more the nearer they come (up to
/// [`NEAR_WEIGHT`] extra next to an obstacle), searched within a window around the shortest
/// path's first [`HORIZON`] cells, then shortened to straight segments where a shortcut keeps
/// the clearance of the part it replaces; beyond the horizon, the shortest path simplified.
/// Both ends included; `None` when no path exists.
pub fn centred_path(
    inflated: &Grid,
    start: CellXY,
    goal: CellXY,
    comfort_m: f64,
) -> Option<Vec<CellXY>> {
    let (_, shortest) = astar(inflated, start, goal)?;
    let comfort = comfort_m / inflated.resolution();
    if comfort <= 0.0 || shortest.len() < 2 {
        return Some(crate::search::simplify(inflated, &shortest));
    }
    let cut = shortest.len().min(HORIZON + 1) - 1;
    let (near, beyond) = (&shortest[..=cut], &shortest[cut..]);
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for &(x, y) in near {
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    let (x0, y0) = (
        x0.saturating_sub(WINDOW_MARGIN),
        y0.saturating_sub(WINDOW_MARGIN),
    );
    let (x1, y1) = (
        (x1 + WINDOW_MARGIN).min(inflated.width() - 1),
        (y1 + WINDOW_MARGIN).min(inflated.height() - 1),
    );
    let clearance = Clearance::new(inflated, x0, y0, x1 - x0 + 1, y1 - y0 + 1);
    let cells = search(inflated, &clearance, start, near[cut], comfort)?;
    let mut path = shorten(inflated, &clearance, &cells);
    if beyond.len() > 1 {
        path.extend(
            crate::search::simplify(inflated, beyond)
                .into_iter()
                .skip(1),
        );
    }
    Some(path)
}

/// A* within the clearance window with the comfort cost; the octile heuristic stays admissible
/// (every step costs at least its length).
fn search(
    grid: &Grid,
    clearance: &Clearance,
    start: CellXY,
    goal: CellXY,
    comfort: f64,
) -> Option<Vec<CellXY>> {
    let n = clearance.width * clearance.height;
    let heuristic = |(x, y): CellXY| {
        let (dx, dy) = (x.abs_diff(goal.0) as u64, y.abs_diff(goal.1) as u64);
        u64::from(STRAIGHT) * dx.max(dy) + u64::from(DIAGONAL - STRAIGHT) * dx.min(dy)
    };
    let extra = |c: CellXY| {
        let near = ((comfort - clearance.at(c)) / comfort).clamp(0.0, 1.0);
        NEAR_WEIGHT * near
    };
    let mut dist = vec![u64::from(UNREACHABLE); n];
    let mut parent = vec![usize::MAX; n];
    let mut open = BinaryHeap::new();
    let s = clearance.index(start);
    dist[s] = 0;
    open.push(Reverse((heuristic(start), 0u64, s)));
    while let Some(Reverse((_, g, u))) = open.pop() {
        if g != dist[u] {
            continue;
        }
        let cell = (
            clearance.x0 + u % clearance.width,
            clearance.y0 + u / clearance.width,
        );
        if cell == goal {
            let mut path = vec![goal];
            let mut i = u;
            while parent[i] != usize::MAX {
                i = parent[i];
                path.push((
                    clearance.x0 + i % clearance.width,
                    clearance.y0 + i / clearance.width,
                ));
            }
            path.reverse();
            return Some(path);
        }
        for (v, step) in crate::search::moves(grid, cell) {
            if !clearance.contains(v) {
                continue;
            }
            let vi = clearance.index(v);
            let nd = g + (f64::from(step) * (1.0 + extra(v))).round() as u64;
            if nd < dist[vi] {
                dist[vi] = nd;
                parent[vi] = u;
                open.push(Reverse((nd + heuristic(v), nd, vi)));
            }
        }
    }
    None
}

/// Straight segments along `path`: from each waypoint, a far later one in line of sight whose
/// segment keeps at least the least clearance of the path between them (less half a cell of
/// rounding), found by doubling then bisecting as [`crate::search::simplify`] does.
fn shorten(grid: &Grid, clearance: &Clearance, path: &[CellXY]) -> Vec<CellXY> {
    let keeps = |i: usize, j: usize| {
        let least = path[i..=j]
            .iter()
            .map(|&c| clearance.at(c))
            .fold(f64::INFINITY, f64::min);
        line_of_sight(grid, path[i], path[j]) && clearance.along(path[i], path[j]) >= least - 0.5
    };
    crate::search::simplify_by(path, keeps)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inflate::inflate;

    /// A 6 × 4 m room of 5 cm cells split by a wall at x = 3 m with a door 0.8 m wide whose
    /// frame is at y = 1.0 and 1.8 m.
    fn room_with_a_door() -> Grid {
        let mut g = Grid::new(120, 80, 0.05, [0.0, 0.0], Cell::Free);
        for y in 0..80 {
            for x in 0..120 {
                let border = x == 0 || y == 0 || x == 119 || y == 79;
                let wall = (59..=60).contains(&x) && !(20..36).contains(&y);
                if border || wall {
                    g.set((x, y), Cell::Occupied);
                }
            }
        }
        g
    }

    /// The least distance (m) from the straight segments of `path` to the door's frame.
    fn from_the_frame(g: &Grid, path: &[CellXY]) -> f64 {
        let frame = [[2.95, 1.0], [3.05, 1.0], [2.95, 1.8], [3.05, 1.8]];
        let mut least = f64::INFINITY;
        for w in path.windows(2) {
            let (a, b) = (g.center_of(w[0]), g.center_of(w[1]));
            for k in 0..=200 {
                let t = f64::from(k) / 200.0;
                let p = [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
                for f in frame {
                    least = least.min((p[0] - f[0]).hypot(p[1] - f[1]));
                }
            }
        }
        least
    }

    #[test]
    fn a_path_through_a_door_keeps_to_its_middle() {
        let map = room_with_a_door();
        let inflated = inflate(&map, 0.25);
        // From low on the left to high on the right: the shortest path grazes both sides of
        // the frame.
        let (a, b) = ((20, 8), (100, 70));
        let (_, cells) = astar(&inflated, a, b).expect("a way through the door");
        let shortest = crate::search::simplify(&inflated, &cells);
        let centred = centred_path(&inflated, a, b, 0.3).expect("a way through the door");
        let (near, far) = (
            from_the_frame(&map, &shortest),
            from_the_frame(&map, &centred),
        );
        assert!(
            near < 0.3,
            "the shortest path passes {near:.2} m from the frame"
        );
        assert!(
            far > 0.35,
            "the centred path passes {far:.2} m from the frame"
        );
        // Both ends kept, every segment on free cells, and not much longer.
        assert_eq!((centred[0], *centred.last().expect("cells")), (a, b));
        assert!(
            centred
                .windows(2)
                .all(|w| line_of_sight(&inflated, w[0], w[1]))
        );
        let length = |p: &[CellXY]| -> f64 {
            p.windows(2)
                .map(|w| {
                    let (a, b) = (map.center_of(w[0]), map.center_of(w[1]));
                    (a[0] - b[0]).hypot(a[1] - b[1])
                })
                .sum()
        };
        assert!(length(&centred) < 1.15 * length(&shortest));
    }

    #[test]
    fn in_the_open_the_path_is_the_straight_line() {
        let map = room_with_a_door();
        let inflated = inflate(&map, 0.25);
        let path = centred_path(&inflated, (10, 40), (50, 40), 0.3).expect("a path");
        assert_eq!(path, vec![(10, 40), (50, 40)]);
        // No comfort asked: the shortest path, simplified.
        let plain = centred_path(&inflated, (20, 8), (100, 70), 0.0).expect("a path");
        let (_, cells) = astar(&inflated, (20, 8), (100, 70)).expect("a path");
        assert_eq!(plain, crate::search::simplify(&inflated, &cells));
        assert!(centred_path(&inflated, (20, 8), (59, 8), 0.3).is_none());
    }

    #[test]
    fn a_long_path_is_centred_near_the_robot_and_kept_beyond() {
        // A corridor 30 m long: beyond the horizon the path is the shortest one, and it ends
        // where it should.
        let mut map = Grid::new(620, 40, 0.05, [0.0, 0.0], Cell::Free);
        for x in 0..620 {
            for y in [0, 39] {
                map.set((x, y), Cell::Occupied);
            }
        }
        let inflated = inflate(&map, 0.25);
        let path = centred_path(&inflated, (10, 10), (600, 30), 0.3).expect("a path");
        assert_eq!(
            (path[0], *path.last().expect("cells")),
            ((10, 10), (600, 30))
        );
        assert!(
            path.windows(2)
                .all(|w| line_of_sight(&inflated, w[0], w[1]))
        );
    }
}
