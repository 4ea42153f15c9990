//! Paths that keep their distance: through the middle of a door, not along its frame.
//!
//! A shortest path on the inflated map touches the inflation's edge at every corner it rounds,
//! and its straight shortcuts graze those corners. At a door 0.8 m wide, where only the
//! narrowest inflation (0.25 m for a drone of 0.2 m) leaves a way through, that is 5 cm between
//! the drone and the door frame, which a path follower rounding the corner, or a gust, takes
//! (seen: on true poses, every collision of a two-drone mission was at a door frame).
//! [`centred_path`] searches with a step cost that grows near anything not free, within a window
//! around the shortest path, and shortens the result only where a shortcut costs, by the same
//! measure, no more than the stretch of path it replaces.
//!
//! The unknown is kept from as well ([`Comfort::unknown_m`]): a wall the camera has not seen
//! yet may begin at its edge, and inflation grows only the walls on the map. A path at the
//! widest radius, which kept no distance from anything beyond its inflation, ran along the
//! edge of the unknown beside a wall not yet mapped, and its drone, tracked within 0.09 m,
//! touched that wall (main command, seed 1092).

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

/// A straight segment may cost this much more than the path it replaces, cell lengths: the
/// sampling's rounding.
const COST_SLACK: f64 = 0.5;

/// How far a path keeps, where it can, from what it should not graze, metres ([`centred_path`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Comfort {
    /// From anything not free on the inflated map: the inflation's edge and the unknown.
    pub blocked_m: f64,
    /// From the unknown alone: a wall not seen yet may begin at its edge.
    pub unknown_m: f64,
}

impl Comfort {
    /// Keeping `blocked_m` from anything not free, and no more from the unknown.
    pub fn blocked(blocked_m: f64) -> Self {
        Self {
            blocked_m,
            unknown_m: 0.0,
        }
    }

    fn any(self) -> bool {
        self.blocked_m > 0.0 || self.unknown_m > 0.0
    }
}

/// A rectangle of a grid's cells: the part of the map a path is searched in.
#[derive(Debug, Clone, Copy)]
struct Window {
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
}

impl Window {
    fn contains(&self, (x, y): CellXY) -> bool {
        x >= self.x0 && y >= self.y0 && x < self.x0 + self.width && y < self.y0 + self.height
    }

    fn index(&self, (x, y): CellXY) -> usize {
        (y - self.y0) * self.width + (x - self.x0)
    }

    fn cell(&self, index: usize) -> CellXY {
        (self.x0 + index % self.width, self.y0 + index / self.width)
    }
}

/// Distance of each cell of a window of a grid to the nearest cell that blocks (outside the
/// grid always blocks), in cells, edge to centre.
struct Clearance {
    window: Window,
    cells: Vec<f32>,
}

impl Clearance {
    fn new(grid: &Grid, window: Window, blocks: impl Fn(Cell) -> bool) -> Self {
        let Window {
            x0,
            y0,
            width,
            height,
        } = window;
        // One cell of border round the window: the map beyond it, or solid off the map.
        let blocked = GrayImage::from_fn(width as u32 + 2, height as u32 + 2, |i, j| {
            let (x, y) = (
                (x0 + i as usize).checked_sub(1),
                (y0 + j as usize).checked_sub(1),
            );
            let blocked = match (x, y) {
                (Some(x), Some(y)) if x < grid.width() && y < grid.height() => {
                    blocks(grid.get((x, y)))
                }
                _ => true,
            };
            Luma([u8::from(blocked)])
        });
        let d2 = euclidean_squared_distance_transform(&blocked);
        let mut cells = Vec::with_capacity(width * height);
        for j in 0..height {
            for i in 0..width {
                let Luma([d]) = *d2.get_pixel(i as u32 + 1, j as u32 + 1);
                cells.push((d.sqrt() - 0.5).max(0.0) as f32);
            }
        }
        Self { window, cells }
    }

    /// Clearance of a cell of the window, cells.
    fn at(&self, c: CellXY) -> f64 {
        f64::from(self.cells[self.window.index(c)])
    }
}

/// What a path's steps cost beyond their length: the comforts it keeps, each in cells with the
/// clearance over the search's window it is kept from.
struct Kept {
    window: Window,
    comforts: Vec<(f64, Clearance)>,
}

impl Kept {
    /// What a step into cell `c` costs beyond its length, as a fraction of it: up to
    /// [`NEAR_WEIGHT`] next to what the comfort most encroached on keeps from, nothing at the
    /// comfort distance and beyond.
    fn extra(&self, c: CellXY) -> f64 {
        let near = self
            .comforts
            .iter()
            .map(|(comfort, clearance)| ((comfort - clearance.at(c)) / comfort).clamp(0.0, 1.0))
            .fold(0.0, f64::max);
        NEAR_WEIGHT * near
    }

    /// What the straight segment from `a` to `b` costs (in cell lengths, each stretch by the
    /// cell it ends in, as the search's steps are), sampled every half cell; `None` when it
    /// leaves the window.
    fn segment_cost(&self, a: CellXY, b: CellXY) -> Option<f64> {
        let (ax, ay, bx, by) = (a.0 as f64, a.1 as f64, b.0 as f64, b.1 as f64);
        let steps = ((bx - ax).abs().max((by - ay).abs()) * 2.0).ceil().max(1.0) as usize;
        let stretch = (bx - ax).hypot(by - ay) / steps as f64;
        (1..=steps).try_fold(0.0, |cost, k| {
            let t = k as f64 / steps as f64;
            let c = (
                (ax + (bx - ax) * t).round() as usize,
                (ay + (by - ay) * t).round() as usize,
            );
            self.window
                .contains(c)
                .then(|| cost + stretch * (1.0 + self.extra(c)))
        })
    }
}

/// A path from `start` to `goal` over the free cells of `inflated` that keeps the `comfort`
/// distances where it can: A* whose steps cost more the nearer they come (up to [`NEAR_WEIGHT`]
/// extra next to an obstacle or the unknown), searched within a window around the shortest
/// path's first [`HORIZON`] cells, then shortened to straight segments where a shortcut costs
/// no more than the part it replaces, by the same measure; beyond the horizon, the shortest path
/// simplified.
/// Both ends included; `None` when no path exists.
pub fn centred_path(
    inflated: &Grid,
    start: CellXY,
    goal: CellXY,
    comfort: Comfort,
) -> Option<Vec<CellXY>> {
    let (_, shortest) = astar(inflated, start, goal)?;
    if !comfort.any() || shortest.len() < 2 {
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
    let window = Window {
        x0,
        y0,
        width: x1 - x0 + 1,
        height: y1 - y0 + 1,
    };
    // Each comfort asked for, in cells, with the clearance it is kept from.
    let res = inflated.resolution();
    let mut kept: Vec<(f64, Clearance)> = vec![];
    if comfort.blocked_m > 0.0 {
        let clearance = Clearance::new(inflated, window, |c| c != Cell::Free);
        kept.push((comfort.blocked_m / res, clearance));
    }
    if comfort.unknown_m > 0.0 {
        let clearance = Clearance::new(inflated, window, |c| c == Cell::Unknown);
        kept.push((comfort.unknown_m / res, clearance));
    }
    let kept = Kept {
        window,
        comforts: kept,
    };
    let cells = search(inflated, &kept, start, near[cut])?;
    let mut path = shorten(inflated, &kept, &cells);
    if beyond.len() > 1 {
        path.extend(
            crate::search::simplify(inflated, beyond)
                .into_iter()
                .skip(1),
        );
    }
    Some(path)
}

/// A* within the window of `kept` with its comfort cost ([`Kept::extra`]); the octile
/// heuristic stays admissible (every step costs at least its length).
fn search(grid: &Grid, kept: &Kept, start: CellXY, goal: CellXY) -> Option<Vec<CellXY>> {
    let window = kept.window;
    let n = window.width * window.height;
    let heuristic = |(x, y): CellXY| {
        let (dx, dy) = (x.abs_diff(goal.0) as u64, y.abs_diff(goal.1) as u64);
        u64::from(STRAIGHT) * dx.max(dy) + u64::from(DIAGONAL - STRAIGHT) * dx.min(dy)
    };
    let mut dist = vec![u64::from(UNREACHABLE); n];
    let mut parent = vec![usize::MAX; n];
    let mut open = BinaryHeap::new();
    let s = window.index(start);
    dist[s] = 0;
    open.push(Reverse((heuristic(start), 0u64, s)));
    while let Some(Reverse((_, g, u))) = open.pop() {
        if g != dist[u] {
            continue;
        }
        let cell = window.cell(u);
        if cell == goal {
            let mut path = vec![goal];
            let mut i = u;
            while parent[i] != usize::MAX {
                i = parent[i];
                path.push(window.cell(i));
            }
            path.reverse();
            return Some(path);
        }
        for (v, step) in crate::search::moves(grid, cell) {
            if !window.contains(v) {
                continue;
            }
            let vi = window.index(v);
            let nd = g + (f64::from(step) * (1.0 + kept.extra(v))).round() as u64;
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
/// segment costs, by the search's own measure ([`Kept::extra`]), no more than the part of the
/// path it replaces (so it keeps the clearance that path bought), found by doubling then
/// bisecting as [`crate::search::simplify`] does. (A rule that only asked a segment to keep
/// the least clearance of the part it replaced let a path from an end beside the unknown run
/// all along it, at that end's clearance.)
fn shorten(grid: &Grid, kept: &Kept, path: &[CellXY]) -> Vec<CellXY> {
    // The cost of the path to each of its cells, as the search counted it.
    let mut to: Vec<f64> = Vec::with_capacity(path.len());
    let mut cost = 0.0;
    for (k, &c) in path.iter().enumerate() {
        if k > 0 {
            let p = path[k - 1];
            let length = (c.0.abs_diff(p.0) as f64).hypot(c.1.abs_diff(p.1) as f64);
            cost += length * (1.0 + kept.extra(c));
        }
        to.push(cost);
    }
    let keeps = |i: usize, j: usize| {
        line_of_sight(grid, path[i], path[j])
            && kept
                .segment_cost(path[i], path[j])
                .is_some_and(|segment| segment <= to[j] - to[i] + COST_SLACK)
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
        let centred =
            centred_path(&inflated, a, b, Comfort::blocked(0.3)).expect("a way through the door");
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
        let path =
            centred_path(&inflated, (10, 40), (50, 40), Comfort::blocked(0.3)).expect("a path");
        assert_eq!(path, vec![(10, 40), (50, 40)]);
        // No comfort asked: the shortest path, simplified.
        let plain =
            centred_path(&inflated, (20, 8), (100, 70), Comfort::default()).expect("a path");
        let (_, cells) = astar(&inflated, (20, 8), (100, 70)).expect("a path");
        assert_eq!(plain, crate::search::simplify(&inflated, &cells));
        assert!(centred_path(&inflated, (20, 8), (59, 8), Comfort::blocked(0.3)).is_none());
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
        let path =
            centred_path(&inflated, (10, 10), (600, 30), Comfort::blocked(0.3)).expect("a path");
        assert_eq!(
            (path[0], *path.last().expect("cells")),
            ((10, 10), (600, 30))
        );
        assert!(
            path.windows(2)
                .all(|w| line_of_sight(&inflated, w[0], w[1]))
        );
    }

    #[test]
    fn a_path_keeps_from_the_unknown_only_when_asked() {
        // A 6 × 4 m room on a map that knows nothing round it, whose top metre is unknown too
        // (a wall may begin at its edge), inflated by the widest radius: crossed from one end
        // to the other just below the unknown, and along the bottom wall.
        let mut map = Grid::new(130, 90, 0.05, [0.0, 0.0], Cell::Unknown);
        for y in 5..85 {
            for x in 5..125 {
                let wall = x == 5 || y == 5 || x == 124 || y == 84;
                if wall {
                    map.set((x, y), Cell::Occupied);
                } else if y < 65 {
                    map.set((x, y), Cell::Free);
                }
            }
        }
        let inflated = inflate(&map, 0.45);
        let path = |a, b, comfort| centred_path(&inflated, a, b, comfort).expect("a path");
        let unknown = Comfort {
            blocked_m: 0.0,
            unknown_m: 0.45,
        };
        // How far (m) the path passes from the unknown's edge (y = 3.25 m) midway, at x = 3.25 m.
        let midway = |path: &[CellXY]| {
            let points: Vec<[f64; 2]> = path.iter().map(|&c| inflated.center_of(c)).collect();
            let w = points
                .windows(2)
                .find(|w| w[0][0] <= 3.25 && w[1][0] >= 3.25)
                .expect("the path crosses the middle");
            let t = (3.25 - w[0][0]) / (w[1][0] - w[0][0]);
            3.25 - (w[0][1] + t * (w[1][1] - w[0][1]))
        };
        let (a, b) = ((15, 62), (114, 62));
        let shortest = path(a, b, Comfort::default());
        assert_eq!(shortest, vec![a, b], "the straight line beside the unknown");
        assert!(midway(&shortest) < 0.15);
        let kept = path(a, b, unknown);
        assert_eq!((kept[0], *kept.last().expect("cells")), (a, b));
        assert!(
            kept.windows(2)
                .all(|w| line_of_sight(&inflated, w[0], w[1]))
        );
        let far = midway(&kept);
        assert!(
            far > 0.35,
            "the path keeping from it passes {far:.2} m from it"
        );
        // Along a wall on the map, 0.5 m from the unknown behind it, the inflation is all it
        // keeps: the straight line, where a comfort from anything not free bends away.
        let (c, d) = ((15, 15), (114, 15));
        assert_eq!(path(c, d, unknown), vec![c, d]);
        assert_ne!(path(c, d, Comfort::blocked(0.45)), vec![c, d]);
    }
}
