//! Frontiers: free cells next to unknown ones, grouped, each with one goal (thesis §4.4.2,
//! Algorithm 1).

use image::{GrayImage, Luma};
use imageproc::region_labelling::{Connectivity, connected_components};

use crate::grid::{Cell, CellXY, Grid};
use crate::search::nearest_free;

/// One frontier: a connected group of frontier cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Frontier {
    /// How many frontier cells it has.
    pub cells: usize,
    /// Centroid of its cells, map frame, metres.
    pub centroid: [f64; 2],
    /// Where a robot is sent: the free cell nearest to the centroid.
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

/// The frontiers of an (inflated) map: frontier cells grouped 8-connected, groups smaller than
/// `min_cells` dropped, largest first.
pub fn frontiers(grid: &Grid, min_cells: usize) -> Vec<Frontier> {
    let (w, h) = (grid.width() as u32, grid.height() as u32);
    let mask = GrayImage::from_fn(w, h, |x, y| {
        Luma([u8::from(is_frontier_cell(grid, (x as usize, y as usize)))])
    });
    let labels = connected_components(&mask, Connectivity::Eight, Luma([0u8]));
    // label → (cells, sum x, sum y)
    let mut groups: Vec<(usize, f64, f64)> = Vec::new();
    for (x, y, Luma([label])) in labels.enumerate_pixels() {
        if *label == 0 {
            continue;
        }
        let k = *label as usize - 1;
        if groups.len() <= k {
            groups.resize(k + 1, (0, 0.0, 0.0));
        }
        let c = grid.center_of((x as usize, y as usize));
        let g = &mut groups[k];
        g.0 += 1;
        g.1 += c[0];
        g.2 += c[1];
    }
    let reach = grid.width().max(grid.height());
    let mut out: Vec<Frontier> = groups
        .into_iter()
        .filter(|g| g.0 >= min_cells.max(1))
        .filter_map(|(n, sx, sy)| {
            let centroid = [sx / n as f64, sy / n as f64];
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::tests::grid;

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
        let all = frontiers(&g, 1);
        let sizes: Vec<usize> = all.iter().map(|f| f.cells).collect();
        assert_eq!(sizes, vec![4, 3, 1], "{all:?}");
        let big = frontiers(&g, 2);
        assert_eq!(big.len(), 2);
        for f in &big {
            assert_eq!(g.get(f.goal), Cell::Free);
        }
    }

    #[test]
    fn a_fully_known_map_has_no_frontier() {
        let g = grid(&["#####", "#...#", "#####"]);
        assert!(frontiers(&g, 1).is_empty());
    }
}
