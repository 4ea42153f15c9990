//! Shortest paths over free cells: 8-connected, √2 diagonals, no corner cutting past an obstacle.
//!
//! Costs are integers: 1000 per straight step and 1414 per diagonal step (√2 to 0.015 %), so that
//! Dijkstra runs as a bucket queue in time linear in the map (Dial's algorithm) and A* finds
//! exactly the same costs.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::grid::{Cell, CellXY, Grid};

/// Cost of a straight step.
pub const STRAIGHT: u32 = 1000;
/// Cost of a diagonal step.
pub const DIAGONAL: u32 = 1414;
/// Distance of a cell that cannot be reached.
pub const UNREACHABLE: u32 = u32::MAX;

/// Metres per cost unit for a grid.
pub fn metres(grid: &Grid, cost: u32) -> f64 {
    f64::from(cost) / f64::from(STRAIGHT) * grid.resolution()
}

/// The free cells of a grid with a one-cell border of obstacles, so that neighbours are found by
/// flat-index arithmetic with no bounds checks. Build it once and search from many starts.
#[derive(Debug, Clone)]
pub struct Graph {
    width: usize,
    height: usize,
    /// Padded width: `width + 2`.
    stride: usize,
    free: Vec<bool>,
}

impl Graph {
    /// The graph of a grid's free cells.
    pub fn new(grid: &Grid) -> Self {
        let (w, h) = (grid.width(), grid.height());
        let stride = w + 2;
        let mut free = vec![false; stride * (h + 2)];
        for (i, c) in grid.cells().iter().enumerate() {
            if *c == Cell::Free {
                free[(i / w + 1) * stride + i % w + 1] = true;
            }
        }
        Self {
            width: w,
            height: h,
            stride,
            free,
        }
    }

    /// Dijkstra from `start` over free cells (the start cell itself may be anything), as a bucket
    /// queue: every step costs 1000 or 1414, so 1415 buckets in a ring hold every pending distance.
    pub fn dijkstra(&self, start: CellXY) -> DistanceField {
        let n = self.free.len();
        let mut field = DistanceField {
            start,
            stride: self.stride,
            width: self.width,
            height: self.height,
            dist: vec![UNREACHABLE; n],
            parent: vec![u32::MAX; n],
        };
        let Some(s) = field.padded(start) else {
            return field;
        };
        let (dist, parent) = (&mut field.dist, &mut field.parent);
        let st = self.stride as isize;
        // (offset, cost, the two orthogonal cells a diagonal step passes)
        let steps: [(isize, u32, isize, isize); 8] = [
            (1, STRAIGHT, 0, 0),
            (-1, STRAIGHT, 0, 0),
            (st, STRAIGHT, 0, 0),
            (-st, STRAIGHT, 0, 0),
            (st + 1, DIAGONAL, 1, st),
            (st - 1, DIAGONAL, -1, st),
            (-st + 1, DIAGONAL, 1, -st),
            (-st - 1, DIAGONAL, -1, -st),
        ];
        let ring = DIAGONAL as usize + 1;
        let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); ring];
        dist[s] = 0;
        buckets[0].push(s as u32);
        let mut pending = 1usize;
        let mut cur = 0u32;
        while pending > 0 {
            let b = cur as usize % ring;
            while let Some(u) = buckets[b].pop() {
                pending -= 1;
                let u = u as usize;
                if dist[u] != cur {
                    continue; // stale: reached cheaper since
                }
                for &(off, w, a, c) in &steps {
                    // A free cell is never on the border, so u ± 1 and u ± stride stay inside.
                    let v = u.wrapping_add_signed(off);
                    let corner_ok = w == STRAIGHT
                        || (self.free[u.wrapping_add_signed(a)]
                            && self.free[u.wrapping_add_signed(c)]);
                    if !self.free[v] || !corner_ok {
                        continue;
                    }
                    let nd = cur + w;
                    if nd < dist[v] {
                        dist[v] = nd;
                        parent[v] = u as u32;
                        buckets[nd as usize % ring].push(v as u32);
                        pending += 1;
                    }
                }
            }
            cur += 1;
        }
        field
    }

    /// Which cells a search from any of `starts` reaches (each start included, whatever it is),
    /// indexed like the grid's cells (`y * width + x`). One flood fill for all starts: a
    /// diagonal step needs both cells beside it free, so 4-neighbour steps reach the same cells.
    pub fn reachable(&self, starts: &[CellXY]) -> Vec<bool> {
        let mut seen = vec![false; self.free.len()];
        let mut stack: Vec<usize> = starts
            .iter()
            .filter(|(x, y)| *x < self.width && *y < self.height)
            .map(|(x, y)| (y + 1) * self.stride + x + 1)
            .collect();
        for &s in &stack {
            seen[s] = true;
        }
        while let Some(u) = stack.pop() {
            for v in [u + 1, u - 1, u + self.stride, u - self.stride] {
                if self.free[v] && !seen[v] {
                    seen[v] = true;
                    stack.push(v);
                }
            }
        }
        (0..self.width * self.height)
            .map(|i| seen[(i / self.width + 1) * self.stride + i % self.width + 1])
            .collect()
    }
}

/// The moves from a cell that stay on free cells and do not cut a corner: `(neighbour, cost)`.
pub(crate) fn moves(grid: &Grid, (x, y): CellXY) -> impl Iterator<Item = (CellXY, u32)> + '_ {
    const STEPS: [(isize, isize); 8] = [
        (1, 0),
        (-1, 0),
        (0, 1),
        (0, -1),
        (1, 1),
        (1, -1),
        (-1, 1),
        (-1, -1),
    ];
    let free = move |dx: isize, dy: isize| {
        let (nx, ny) = (x as isize + dx, y as isize + dy);
        nx >= 0 && ny >= 0 && grid.get((nx as usize, ny as usize)) == Cell::Free
    };
    STEPS.into_iter().filter_map(move |(dx, dy)| {
        if !free(dx, dy) {
            return None;
        }
        let n = ((x as isize + dx) as usize, (y as isize + dy) as usize);
        if dx != 0 && dy != 0 {
            (free(dx, 0) && free(0, dy)).then_some((n, DIAGONAL))
        } else {
            Some((n, STRAIGHT))
        }
    })
}

/// Distances from one start cell to every cell, and the tree to walk paths back.
#[derive(Debug, Clone)]
pub struct DistanceField {
    start: CellXY,
    stride: usize,
    width: usize,
    height: usize,
    dist: Vec<u32>,
    parent: Vec<u32>,
}

impl DistanceField {
    /// The start cell.
    pub fn start(&self) -> CellXY {
        self.start
    }

    fn padded(&self, (x, y): CellXY) -> Option<usize> {
        (x < self.width && y < self.height).then(|| (y + 1) * self.stride + x + 1)
    }

    /// Cost to a cell ([`UNREACHABLE`] if it cannot be reached).
    pub fn cost(&self, cell: CellXY) -> u32 {
        self.padded(cell).map_or(UNREACHABLE, |i| self.dist[i])
    }

    /// The cells from the start to `goal`, both included; `None` if unreachable.
    pub fn path_to(&self, goal: CellXY) -> Option<Vec<CellXY>> {
        let mut i = self.padded(goal)?;
        if self.dist[i] == UNREACHABLE {
            return None;
        }
        let mut path = vec![goal];
        while self.parent[i] != u32::MAX {
            i = self.parent[i] as usize;
            path.push((i % self.stride - 1, i / self.stride - 1));
        }
        path.reverse();
        Some(path)
    }
}

/// Dijkstra from `start` over free cells (the start cell itself may be anything). To search from
/// several starts on one grid, build a [`Graph`] once.
pub fn dijkstra(grid: &Grid, start: CellXY) -> DistanceField {
    Graph::new(grid).dijkstra(start)
}

/// A* from `start` to `goal` over free cells with the octile heuristic; `None` if there is no path.
/// Returns the cost and the cells, both ends included.
pub fn astar(grid: &Grid, start: CellXY, goal: CellXY) -> Option<(u32, Vec<CellXY>)> {
    let (w, h) = (grid.width(), grid.height());
    if start.0 >= w || start.1 >= h || goal.0 >= w || goal.1 >= h {
        return None;
    }
    let heuristic = |(x, y): CellXY| {
        let (dx, dy) = (x.abs_diff(goal.0) as u32, y.abs_diff(goal.1) as u32);
        STRAIGHT * dx.max(dy) + (DIAGONAL - STRAIGHT) * dx.min(dy)
    };
    let mut dist = vec![UNREACHABLE; w * h];
    let mut parent = vec![u32::MAX; w * h];
    let mut open = BinaryHeap::new();
    dist[grid.index(start)] = 0;
    open.push(Reverse((heuristic(start), 0u32, grid.index(start) as u32)));
    while let Some(Reverse((_, g, u))) = open.pop() {
        let u = u as usize;
        if g != dist[u] {
            continue;
        }
        let cell = grid.xy(u);
        if cell == goal {
            let mut path = vec![goal];
            let mut i = u;
            while parent[i] != u32::MAX {
                i = parent[i] as usize;
                path.push(grid.xy(i));
            }
            path.reverse();
            return Some((g, path));
        }
        for (v, c) in moves(grid, cell) {
            let vi = grid.index(v);
            let nd = g + c;
            if nd < dist[vi] {
                dist[vi] = nd;
                parent[vi] = u as u32;
                open.push(Reverse((nd + heuristic(v), nd, vi as u32)));
            }
        }
    }
    None
}

/// The free cell nearest to `from` (Euclidean, between cell centres), looking at most
/// `max_radius` cells away in x and y; ties go to the first found.
pub fn nearest_free(grid: &Grid, from: CellXY, max_radius: usize) -> Option<CellXY> {
    let (fx, fy) = (from.0 as isize, from.1 as isize);
    let mut best: Option<(isize, CellXY)> = None;
    for r in 0..=max_radius as isize {
        // Every cell of ring r is at least r away: nothing further out can beat the best.
        if best.is_some_and(|(d2, _)| r * r > d2) {
            break;
        }
        for dy in -r..=r {
            for dx in -r..=r {
                if dx.abs() != r && dy.abs() != r {
                    continue; // inside the ring: seen already
                }
                let (x, y) = (fx + dx, fy + dy);
                if x < 0 || y < 0 || grid.get((x as usize, y as usize)) != Cell::Free {
                    continue;
                }
                let d2 = dx * dx + dy * dy;
                if best.is_none_or(|(b, _)| d2 < b) {
                    best = Some((d2, (x as usize, y as usize)));
                }
            }
        }
    }
    best.map(|(_, c)| c)
}

/// Whether the straight segment between two cell centres crosses only free cells (checked every
/// quarter cell; the inflation margin covers what lies between the checks).
pub fn line_of_sight(grid: &Grid, a: CellXY, b: CellXY) -> bool {
    let (ax, ay, bx, by) = (
        a.0 as f64 + 0.5,
        a.1 as f64 + 0.5,
        b.0 as f64 + 0.5,
        b.1 as f64 + 0.5,
    );
    let steps = (((bx - ax).abs().max((by - ay).abs())) * 4.0)
        .ceil()
        .max(1.0) as usize;
    (0..=steps).all(|k| {
        let t = k as f64 / steps as f64;
        let (x, y) = (ax + (bx - ax) * t, ay + (by - ay) * t);
        grid.get((x as usize, y as usize)) == Cell::Free
    })
}

/// Shortens a path to straight segments that stay on free cells: from each waypoint, jump to a
/// far cell still in line of sight (found by doubling then bisecting, so a long path costs
/// O(L log L) checks rather than O(L²)). Keeps both ends; every segment is checked clear.
pub fn simplify(grid: &Grid, path: &[CellXY]) -> Vec<CellXY> {
    simplify_by(path, |i, j| line_of_sight(grid, path[i], path[j]))
}

/// Shortens a path to straight segments from waypoint `i` to waypoint `j` wherever
/// `keeps(i, j)` allows (doubling then bisecting the jump from each waypoint, as [`simplify`]
/// does). Keeps both ends.
pub fn simplify_by(path: &[CellXY], keeps: impl Fn(usize, usize) -> bool) -> Vec<CellXY> {
    let Some(&first) = path.first() else {
        return vec![];
    };
    let mut out = vec![first];
    let mut i = 0;
    let last = path.len() - 1;
    while i < last {
        // Doubling: the largest i + 2^k still in sight (i + 1 always is: path steps are adjacent).
        let mut good = i + 1;
        let mut step = 2;
        while i + step <= last && keeps(i, i + step) {
            good = i + step;
            step *= 2;
        }
        // Bisect between the last good and the first bad (or the end).
        let mut bad = (i + step).min(last + 1);
        while bad - good > 1 {
            let mid = (good + bad) / 2;
            if keeps(i, mid) {
                good = mid;
            } else {
                bad = mid;
            }
        }
        out.push(path[good]);
        i = good;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::tests::grid;
    use proptest::prelude::*;

    #[test]
    fn the_flood_fill_reaches_what_the_searches_reach() {
        // Two pockets joined only corner to corner (no corner cutting), and a start on a wall.
        let g = grid(&[
            "#########",
            "#...#...#",
            "#...#...#",
            "####.####",
            "#..#.#..#",
            "#..#....#",
            "#########",
        ]);
        let graph = Graph::new(&g);
        for starts in [
            vec![(1, 1)],
            vec![(5, 5), (1, 1)],
            vec![(0, 0)],
            vec![(4, 3)],
        ] {
            let reach = graph.reachable(&starts);
            for (i, &r) in reach.iter().enumerate() {
                let c = g.xy(i);
                let searched = starts
                    .iter()
                    .any(|&s| graph.dijkstra(s).cost(c) != UNREACHABLE);
                assert_eq!(r, searched, "{starts:?} → {c:?}");
            }
        }
    }

    #[test]
    fn no_corner_cutting_and_diagonals_cost_root_two() {
        let g = grid(&[
            "...", //
            ".#.", "...",
        ]);
        let f = dijkstra(&g, (0, 0));
        assert_eq!(f.cost((1, 0)), STRAIGHT);
        // (2,2) is two diagonals away in open space, but the wall in the middle forbids them.
        assert_eq!(f.cost((2, 2)), 4 * STRAIGHT);
        assert_eq!(f.cost((1, 1)), UNREACHABLE);
        let open = grid(&["...", "...", "..."]);
        assert_eq!(dijkstra(&open, (0, 0)).cost((2, 2)), 2 * DIAGONAL);
        assert_eq!(astar(&g, (0, 0), (2, 2)).unwrap().0, 4 * STRAIGHT);
        assert!(astar(&g, (0, 0), (1, 1)).is_none(), "no path is a result");
    }

    #[test]
    fn paths_are_walked_back_and_simplified() {
        let g = grid(&[
            "..........", //
            "..........",
            "#######...",
            "..........",
        ]);
        let f = dijkstra(&g, (0, 0));
        let p = f.path_to((0, 3)).unwrap();
        assert_eq!(p.first(), Some(&(0, 0)));
        assert_eq!(p.last(), Some(&(0, 3)));
        let s = simplify(&g, &p);
        assert!(s.len() >= 3 && s.len() < p.len(), "{s:?}");
        for w in s.windows(2) {
            assert!(line_of_sight(&g, w[0], w[1]));
        }
    }

    #[test]
    fn nearest_free_finds_the_closest() {
        let g = grid(&[
            "#####", //
            "#####", "##.##", "####.",
        ]);
        assert_eq!(nearest_free(&g, (2, 3), 5), Some((2, 1)));
        assert_eq!(nearest_free(&g, (4, 0), 5), Some((4, 0)));
        assert_eq!(nearest_free(&g, (0, 3), 1), None);
    }

    fn random_grid(cells: &[bool], w: usize) -> crate::grid::Grid {
        let h = cells.len() / w;
        let mut g = crate::grid::Grid::new(w, h, 0.1, [0.0, 0.0], Cell::Free);
        for (i, &wall) in cells.iter().enumerate() {
            if wall {
                g.set((i % w, i / w), Cell::Occupied);
            }
        }
        g
    }

    proptest! {
        #[test]
        fn astar_and_dijkstra_agree_and_paths_stay_free(
            cells in proptest::collection::vec(proptest::bool::weighted(0.3), 20 * 15),
            sx in 0usize..20, sy in 0usize..15, gx in 0usize..20, gy in 0usize..15,
        ) {
            let mut g = random_grid(&cells, 20);
            g.set((sx, sy), Cell::Free);
            g.set((gx, gy), Cell::Free);
            let f = dijkstra(&g, (sx, sy));
            let a = astar(&g, (sx, sy), (gx, gy));
            match a {
                None => prop_assert_eq!(f.cost((gx, gy)), UNREACHABLE),
                Some((cost, path)) => {
                    prop_assert_eq!(cost, f.cost((gx, gy)));
                    let mut sum = 0;
                    for w in path.windows(2) {
                        prop_assert_eq!(g.get(w[1]), Cell::Free);
                        let (dx, dy) = (w[0].0.abs_diff(w[1].0), w[0].1.abs_diff(w[1].1));
                        prop_assert!(dx <= 1 && dy <= 1);
                        if dx == 1 && dy == 1 {
                            prop_assert_eq!(g.get((w[1].0, w[0].1)), Cell::Free, "corner cut");
                            prop_assert_eq!(g.get((w[0].0, w[1].1)), Cell::Free, "corner cut");
                        }
                        sum += if dx + dy == 2 { DIAGONAL } else { STRAIGHT };
                    }
                    prop_assert_eq!(sum, cost);
                    for w in simplify(&g, &path).windows(2) {
                        prop_assert!(line_of_sight(&g, w[0], w[1]));
                    }
                }
            }
        }
    }
}
