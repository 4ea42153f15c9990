//! Frontiers: free cells next to unknown ones, grouped, each with one goal (thesis §4.4.2,
//! Algorithm 1).

use image::{GrayImage, Luma};
use imageproc::region_labelling::{Connectivity, connected_components};

use crate::grid::{Cell, CellXY, Grid};
use crate::search::{line_of_sight, nearest_free};

/// One frontier: a connected group of frontier cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Frontier {
    /// How many frontier cells it has.
    pub cells: usize,
    /// Centroid of its cells, map frame, metres.
    pub centroid: [f64; 2],
    /// Where a robot is sent: the free cell nearest to the centroid (the mission planner moves it
    /// to a [`crate::vantage::viewpoint`] when no robot can reach it).
    pub goal: CellXY,
}

/// Whether a cell is a frontier cell: free, with an unknown 4-neighbour.
pub fn is_frontier_cell(grid: &Grid, (x, y): CellXY) -> bool {
    grid.get((x, y)) == Cell::Free
        && [(1, 0), (-1, 0), (0, 1), (0, -1)]
            .iter()
            .any(|&(dx, dy): &(isize, isize)| {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                nx >= 0 && ny >= 0 && grid.get((nx as usize, ny as usize)) == Cell::Unknown
            })
}

/// Which frontiers [`frontiers`] keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrontierLimits {
    /// Groups (and pieces) with fewer cells are dropped.
    pub min_cells: usize,
    /// Groups wider than this, metres, are cut into pieces of at most this width.
    pub max_span_m: f64,
    /// A group whose unknown side is a pocket of at most this many cells is dropped
    /// ([`opens_onto_pocket`]); 0: none is.
    pub max_pocket_cells: usize,
}

/// The frontiers of an (inflated) map: frontier cells grouped 8-connected, groups smaller than
/// `limits.min_cells` or opening onto a pocket of unknown no bigger than
/// `limits.max_pocket_cells` dropped, groups wider than `limits.max_span_m` cut into pieces of
/// at most that width (on square tiles; pieces smaller than `min_cells` dropped), largest first.
///
/// Cutting keeps every goal on its frontier: the frontier around an open hall is one ring whose
/// centroid is the hall's middle, where the robots already are (on willow-full two drones "reached"
/// that goal at once, gave it up and landed with 1.6 % of the building seen); its pieces are
/// targets of their own, a robot each.
pub fn frontiers(grid: &Grid, limits: &FrontierLimits) -> Vec<Frontier> {
    let (w, h) = (grid.width() as u32, grid.height() as u32);
    let mask = GrayImage::from_fn(w, h, |x, y| {
        Luma([u8::from(is_frontier_cell(grid, (x as usize, y as usize)))])
    });
    let labels = connected_components(&mask, Connectivity::Eight, Luma([0u8]));
    // label → its cells
    let mut groups: Vec<Vec<CellXY>> = Vec::new();
    for (x, y, Luma([label])) in labels.enumerate_pixels() {
        if *label == 0 {
            continue;
        }
        let k = *label as usize - 1;
        if groups.len() <= k {
            groups.resize(k + 1, vec![]);
        }
        groups[k].push((x as usize, y as usize));
    }
    let min_cells = limits.min_cells.max(1);
    let reach = grid.width().max(grid.height());
    let mut out: Vec<Frontier> = groups
        .into_iter()
        .filter(|g| g.len() >= min_cells)
        .filter(|g| {
            limits.max_pocket_cells == 0 || !opens_onto_pocket(grid, g, limits.max_pocket_cells)
        })
        .map(|g| g.into_iter().map(|c| grid.center_of(c)).collect())
        .flat_map(|g| pieces(g, limits.max_span_m))
        .filter(|piece| piece.len() >= min_cells)
        .filter_map(|piece| {
            let n = piece.len();
            let sum = piece
                .iter()
                .fold([0.0, 0.0], |s, c| [s[0] + c[0], s[1] + c[1]]);
            let centroid = [sum[0] / n as f64, sum[1] / n as f64];
            let cell = grid.cell_of(centroid)?;
            let goal = nearest_free(grid, cell, reach)?;
            Some(Frontier {
                cells: n,
                centroid,
                goal,
            })
        })
        .collect();
    out.sort_by(|a, b| b.cells.cmp(&a.cells).then(a.goal.cmp(&b.goal)));
    out
}

/// Whether all the unknown next to the frontier cells `cells` lies in pockets of at most
/// `max_cells` cells in all, walled at least as much as open: regions of unknown (8-connected)
/// enclosed by cells the map knows, clear of its edge (beyond which the unknown goes on), and
/// bordered by at least as many occupied cell sides as free ones. The inside of a pillar or of a piece
/// of furniture seen from every side but one is such a pocket: a robot sent to look at it sees
/// a face of it, not a room (in SITL, the apartment's pillar sent a drone into the 0.8 m gap
/// beside it in nearly every mission, often last, while the others had landed). A patch of
/// floor not yet seen, free all round, is not.
pub fn opens_onto_pocket(grid: &Grid, cells: &[CellXY], max_cells: usize) -> bool {
    let (w, h) = (grid.width(), grid.height());
    let at = |(x, y): (isize, isize)| {
        (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
            .then(|| ((x as usize, y as usize), grid.get((x as usize, y as usize))))
    };
    const SIDES: [(isize, isize); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];
    let mut pocket = std::collections::HashSet::new();
    let mut queue = std::collections::VecDeque::new();
    for &(x, y) in cells {
        for (dx, dy) in SIDES {
            if let Some((c, Cell::Unknown)) = at((x as isize + dx, y as isize + dy))
                && pocket.insert(c)
            {
                queue.push_back(c);
            }
        }
    }
    // Its border: cell sides onto occupied and onto free cells.
    let (mut walled, mut open) = (0usize, 0usize);
    while let Some((x, y)) = queue.pop_front() {
        if pocket.len() > max_cells || x == 0 || y == 0 || x + 1 == w || y + 1 == h {
            return false;
        }
        for dy in -1..=1 {
            for dx in -1..=1 {
                let Some((c, cell)) = at((x as isize + dx, y as isize + dy)) else {
                    continue;
                };
                match cell {
                    Cell::Unknown if pocket.insert(c) => queue.push_back(c),
                    Cell::Occupied if dx == 0 || dy == 0 => walled += 1,
                    Cell::Free if dx == 0 || dy == 0 => open += 1,
                    _ => {}
                }
            }
        }
    }
    !pocket.is_empty() && walled >= open
}

/// Frontiers grouped into regions, one drone's worth of exploring each: per frontier, the index of
/// its region. Largest frontier first, each frontier not yet in a region starts one and takes in
/// every later one whose goal lies within `radius_m` of its own and in sight of it across cells
/// `map` knows as free (a drone looking around at one goal sees the other frontier too; a wall
/// between them keeps them apart). `radius_m` ≤ 0: every frontier is a region of its own.
pub fn regions(map: &Grid, frontiers: &[Frontier], radius_m: f64) -> Vec<usize> {
    if radius_m.is_nan() || radius_m <= 0.0 {
        return (0..frontiers.len()).collect();
    }
    let mut region = vec![usize::MAX; frontiers.len()];
    let mut next = 0;
    for seed in 0..frontiers.len() {
        if region[seed] != usize::MAX {
            continue;
        }
        region[seed] = next;
        let a = map.center_of(frontiers[seed].goal);
        for other in seed + 1..frontiers.len() {
            let b = map.center_of(frontiers[other].goal);
            if region[other] == usize::MAX
                && (a[0] - b[0]).hypot(a[1] - b[1]) <= radius_m
                && line_of_sight(map, frontiers[seed].goal, frontiers[other].goal)
            {
                region[other] = next;
            }
        }
        next += 1;
    }
    region
}

/// A group of frontier cells (their centres, metres) as is when it fits in `max_span_m` each
/// way, else cut on square tiles of that side laid from its lower corner.
fn pieces(cells: Vec<[f64; 2]>, max_span_m: f64) -> Vec<Vec<[f64; 2]>> {
    let lower = cells
        .iter()
        .fold([f64::INFINITY; 2], |m, c| [m[0].min(c[0]), m[1].min(c[1])]);
    let upper = cells.iter().fold([f64::NEG_INFINITY; 2], |m, c| {
        [m[0].max(c[0]), m[1].max(c[1])]
    });
    let span = (upper[0] - lower[0]).max(upper[1] - lower[1]);
    if max_span_m.is_nan() || max_span_m <= 0.0 || span <= max_span_m {
        return vec![cells];
    }
    let mut tiles: std::collections::BTreeMap<(i64, i64), Vec<[f64; 2]>> = Default::default();
    for c in cells {
        let tile = (
            ((c[0] - lower[0]) / max_span_m).floor() as i64,
            ((c[1] - lower[1]) / max_span_m).floor() as i64,
        );
        tiles.entry(tile).or_default().push(c);
    }
    tiles.into_values().collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::grid::tests::grid;

    /// No pocket dropped.
    fn limits(min_cells: usize, max_span_m: f64) -> FrontierLimits {
        FrontierLimits {
            min_cells,
            max_span_m,
            max_pocket_cells: 0,
        }
    }

    #[test]
    fn toy_map_has_the_hand_counted_frontiers() {
        // Two openings into unknown space (left door: 3 cells; right edge: 4 cells, joined
        // diagonally) and one
        // single-cell peek that the minimum size filters out.
        let g = grid(&[
            "##########", //
            "#???###..?",
            "#...#.....",
            "#.........",
            "#........?",
            "######.###",
            "######?###",
        ]);
        let all = frontiers(&g, &limits(1, 10.0));
        let sizes: Vec<usize> = all.iter().map(|f| f.cells).collect();
        assert_eq!(sizes, vec![4, 3, 1], "{all:?}");
        let big = frontiers(&g, &limits(2, 10.0));
        assert_eq!(big.len(), 2);
        for f in &big {
            assert_eq!(g.get(f.goal), Cell::Free);
        }
    }

    /// An open hall seen from its middle: a free disc of `radius` metres (centre (3, 3)) in
    /// unknown space, 0.1-m cells.
    pub(crate) fn open_hall(radius: f64) -> Grid {
        let mut g = Grid::new(61, 61, 0.1, [0.0, 0.0], Cell::Unknown);
        for y in 0..61 {
            for x in 0..61 {
                let c = g.center_of((x, y));
                if (c[0] - 3.0).hypot(c[1] - 3.0) <= radius {
                    g.set((x, y), Cell::Free);
                }
            }
        }
        g
    }

    #[test]
    fn a_ring_frontier_is_cut_into_pieces_each_with_its_goal_on_it() {
        let g = open_hall(2.5);
        let from_middle = |f: &Frontier| {
            let c = g.center_of(f.goal);
            (c[0] - 3.0).hypot(c[1] - 3.0)
        };
        // Uncut, the ring is one frontier whose goal is the hall's middle.
        let whole = frontiers(&g, &limits(1, 10.0));
        assert_eq!(whole.len(), 1, "{whole:?}");
        assert!(from_middle(&whole[0]) < 0.2, "{whole:?}");
        // Cut at 2 m: pieces of the ring, every goal near the edge, no cell lost.
        let cut = frontiers(&g, &limits(1, 2.0));
        assert!(cut.len() >= 8, "{cut:?}");
        for f in &cut {
            assert_eq!(g.get(f.goal), Cell::Free);
            assert!(
                from_middle(f) > 2.0,
                "{f:?} is {} m from the middle",
                from_middle(f)
            );
        }
        let total: usize = cut.iter().map(|f| f.cells).sum();
        assert_eq!(total, whole[0].cells);
    }

    /// Two rooms side by side (0.1 m cells), openings in their north walls: the west room's at
    /// x ≈ 0.5 m and 1.2 m (near each other, in sight), and at 3.6 m (over 2.5 m from the first);
    /// the east room's at 4.6 m, near the west room's last but behind the wall between them.
    pub(crate) fn two_rooms_with_openings() -> Grid {
        let width = 50;
        let openings = [2..7, 10..15, 34..39, 44..49];
        let top: String = (0..width)
            .map(|x| {
                if openings.iter().any(|o| o.contains(&x)) {
                    '?'
                } else {
                    '#'
                }
            })
            .collect();
        let room: String = (0..width)
            .map(|x| {
                if [0, 40, width - 1].contains(&x) {
                    '#'
                } else {
                    '.'
                }
            })
            .collect();
        let mut rows = vec![top.as_str()];
        rows.extend(std::iter::repeat_n(room.as_str(), 12));
        let bottom = "#".repeat(width);
        rows.push(&bottom);
        grid(&rows)
    }

    #[test]
    fn frontiers_near_each_other_in_sight_are_one_region_and_a_wall_parts_them() {
        let g = two_rooms_with_openings();
        let all = frontiers(&g, &limits(1, 4.0));
        let x = |f: &Frontier| g.center_of(f.goal)[0];
        let mut by_x: Vec<usize> = (0..all.len()).collect();
        by_x.sort_by(|&a, &b| x(&all[a]).total_cmp(&x(&all[b])));
        assert_eq!(by_x.len(), 4, "{all:?}");
        let region = regions(&g, &all, 2.5);
        let r: Vec<usize> = by_x.iter().map(|&f| region[f]).collect();
        // The first two together; the third too far; the fourth near it, but behind the wall.
        assert_eq!(r[0], r[1], "{r:?}");
        assert!(r[2] != r[0] && r[3] != r[2] && r[3] != r[0], "{r:?}");
        // With no radius, each its own; with a large one the wall still parts the rooms.
        let own = regions(&g, &all, 0.0);
        assert_eq!(
            own.iter().collect::<std::collections::HashSet<_>>().len(),
            4
        );
        let wide = regions(&g, &all, 10.0);
        let w: Vec<usize> = by_x.iter().map(|&f| wide[f]).collect();
        assert!(w[0] == w[1] && w[1] == w[2] && w[3] != w[0], "{w:?}");
    }

    #[test]
    fn a_frontier_narrower_than_the_span_is_not_cut() {
        let g = open_hall(0.8);
        assert_eq!(
            frontiers(&g, &limits(1, 2.0)),
            frontiers(&g, &limits(1, 10.0))
        );
        assert_eq!(frontiers(&g, &limits(1, 2.0)).len(), 1);
    }

    #[test]
    fn a_fully_known_map_has_no_frontier() {
        let g = grid(&["#####", "#...#", "#####"]);
        assert!(frontiers(&g, &limits(1, 10.0)).is_empty());
    }

    #[test]
    fn a_frontier_onto_the_inside_of_a_pillar_is_dropped_and_one_onto_a_room_kept() {
        // A hall (0.1 m cells). North, a door onto unknown that goes on past the map's edge;
        // in the middle a pillar whose east face was never seen, its inside unknown (6 cells);
        // east of it a patch of floor not yet seen (2 cells); south, a closet behind a door,
        // unknown (7 cells with its doorway), enclosed.
        let g = grid(&[
            "????????????????",
            "######????######",
            "#..............#",
            "#..............#",
            "#...####.......#",
            "#...#???.......#",
            "#...#???.......#",
            "#...####.......#",
            "#..........??..#",
            "#..............#",
            "###??###########",
            "##?????#########",
            "################",
        ]);
        // The frontiers kept with pockets of up to `max_pocket_cells` dropped, south to north:
        // the closet's (y 0.35 m), the floor patch's (0.45 m), the pillar's (0.7 m), the
        // door's (1.05 m).
        let kept = |max_pocket_cells| {
            let limits = FrontierLimits {
                max_pocket_cells,
                ..limits(1, 10.0)
            };
            let mut ys: Vec<f64> = frontiers(&g, &limits)
                .iter()
                .map(|f| (f.centroid[1] * 100.0).round() / 100.0)
                .collect();
            ys.sort_by(f64::total_cmp);
            ys
        };
        assert_eq!(kept(0), [0.35, 0.45, 0.7, 1.05], "none dropped");
        assert_eq!(kept(6), [0.35, 0.45, 1.05], "the pillar's inside dropped");
        assert_eq!(kept(7), [0.45, 1.05], "the closet's too");
        // The floor patch is open all round, and the unknown past the map's edge no pocket.
        assert_eq!(kept(1000), [0.45, 1.05]);
    }
}
