//! Obstacle inflation (thesis Fig. 4-11): binary map (unknown → free), Euclidean distance
//! transform, threshold at the robot radius, fused back with the ternary map.

use image::{GrayImage, Luma};
use imageproc::distance_transform::euclidean_squared_distance_transform;

use crate::grid::{Cell, Grid, in_cells};

/// The inflated ternary map: every cell whose centre lies within `radius_m` of an occupied cell's
/// centre becomes occupied; other cells keep their value (unknown stays unknown).
pub fn inflate(grid: &Grid, radius_m: f64) -> Grid {
    let (w, h) = (grid.width() as u32, grid.height() as u32);
    let obstacles = GrayImage::from_fn(w, h, |x, y| {
        Luma([u8::from(
            grid.get((x as usize, y as usize)) == Cell::Occupied,
        )])
    });
    let d2 = euclidean_squared_distance_transform(&obstacles);
    // A centre exactly the radius away is within it (divided plainly, 0.35 m of 0.05 m cells
    // is 6.999…, and a straight wall grew by 0.30 m).
    let r_cells = in_cells(radius_m.max(0.0), grid.resolution());
    let limit = r_cells * r_cells;
    let mut out = grid.clone();
    for (x, y, Luma([dist2])) in d2.enumerate_pixels() {
        if *dist2 <= limit {
            out.set((x as usize, y as usize), Cell::Occupied);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::tests::grid;

    #[test]
    fn grows_walls_by_the_radius_and_keeps_unknown() {
        let g = grid(&[
            "?......", //
            ".......", "...#...", ".......", ".......",
        ]);
        // 0.1 m cells, radius 0.15 m: the 4-neighbours (0.1 m) are inside, diagonals (0.141) too,
        // two cells away (0.2 m) not.
        let i = inflate(&g, 0.15);
        let occupied: Vec<_> = (0..i.cells().len())
            .filter(|&k| i.cells()[k] == Cell::Occupied)
            .map(|k| i.xy(k))
            .collect();
        assert_eq!(occupied.len(), 9);
        assert_eq!(i.get((0, 4)), Cell::Unknown);
        assert_eq!(i.get((3, 0)), Cell::Free);
        let i = inflate(&g, 0.21);
        assert_eq!(
            i.cells().iter().filter(|c| **c == Cell::Occupied).count(),
            13
        );
        assert_eq!(inflate(&g, 0.0), g);
    }

    #[test]
    fn a_radius_of_whole_cells_reaches_the_cell_that_far() {
        // A wall along the top row of 0.05 m cells: every radius the missions plan with grows it
        // by its whole length, though 0.35 / 0.05 is 6.999… in floating point.
        let mut g = Grid::new(3, 12, 0.05, [0.0, 0.0], Cell::Free);
        for x in 0..3 {
            g.set((x, 11), Cell::Occupied);
        }
        for (radius, cells) in [(0.25, 5), (0.35, 7), (0.45, 9), (0.15, 3)] {
            let i = inflate(&g, radius);
            let grown = (0..11).filter(|&y| i.get((1, y)) == Cell::Occupied).count();
            assert_eq!(grown, cells, "radius {radius} m");
        }
    }
}
