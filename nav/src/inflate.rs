//! Obstacle inflation (thesis Fig. 4-11): binary map (unknown → free), Euclidean distance
//! transform, threshold at the robot radius, fused back with the ternary map.

use image::{GrayImage, Luma};
use imageproc::distance_transform::euclidean_squared_distance_transform;

use crate::grid::{Cell, Grid};

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
    let r_cells = radius_m.max(0.0) / grid.resolution();
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
}
