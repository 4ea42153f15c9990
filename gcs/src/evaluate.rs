//! How good a map is, against the simulated world it was made of: coverage of the free space
//! the drones could reach, and how far the map's walls lie from the world's.

use image::{GrayImage, Luma};
use imageproc::distance_transform::euclidean_squared_distance_transform;
use nav::grid::{Cell, Grid};
use sitl::World;

/// The world's free cells reachable from the drones' starts (4-connected), world cells.
pub fn reachable_free(world: &World) -> Vec<(i64, i64)> {
    let (w, h) = world.size();
    let mut seen = vec![false; w * h];
    let mut queue = std::collections::VecDeque::new();
    for s in world.starts() {
        let (x, y) = world.cell_of(*s);
        if !world.material(x, y).is_solid() {
            seen[y as usize * w + x as usize] = true;
            queue.push_back((x, y));
        }
    }
    let mut out = vec![];
    while let Some((x, y)) = queue.pop_front() {
        out.push((x, y));
        for (nx, ny) in [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)] {
            if !world.material(nx, ny).is_solid() {
                let i = ny as usize * w + nx as usize;
                if !seen[i] {
                    seen[i] = true;
                    queue.push_back((nx, ny));
                }
            }
        }
    }
    out
}

/// Fraction of the reachable free world cells whose centre the map knows as free.
pub fn coverage(reachable: &[(i64, i64)], world: &World, map: &Grid) -> f64 {
    if reachable.is_empty() {
        return 0.0;
    }
    let (r, o) = (world.resolution(), world.origin());
    let known = reachable
        .iter()
        .filter(|(x, y)| {
            let p = [o[0] + (*x as f64 + 0.5) * r, o[1] + (*y as f64 + 0.5) * r];
            map.cell_of(p).is_some_and(|c| map.get(c) == Cell::Free)
        })
        .count();
    known as f64 / reachable.len() as f64
}

/// How far the map's walls lie from the world's.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct WallError {
    /// Occupied map cells measured.
    pub cells: usize,
    /// Median distance of an occupied map cell's centre from the nearest true wall, metres.
    pub median_m: f64,
    /// 95th percentile of that distance, metres.
    pub p95_m: f64,
    /// Fraction of occupied map cells within 0.1 m of a true wall.
    pub within_0_1_m: f64,
}

/// The distance from every occupied cell of `map` to the nearest solid part of the world.
pub fn wall_error(world: &World, map: &Grid) -> Option<WallError> {
    let (w, h) = (map.width() as u32, map.height() as u32);
    if w == 0 || h == 0 {
        return None;
    }
    // The world's solids rasterised on the map's cells (and its outside, which is solid).
    let res = map.resolution();
    let solid = GrayImage::from_fn(w, h, |x, y| {
        let p = map.center_of((x as usize, y as usize));
        let (cx, cy) = world.cell_of(p);
        Luma([u8::from(world.material(cx, cy).is_solid())])
    });
    let d2 = euclidean_squared_distance_transform(&solid);
    let mut distances: Vec<f64> = (0..map.height())
        .flat_map(|y| (0..map.width()).map(move |x| (x, y)))
        .filter(|&c| map.get(c) == Cell::Occupied)
        .map(|(x, y)| {
            // Cell centres to the nearest solid cell's centre, less half a cell: to its edge.
            let d = d2.get_pixel(x as u32, y as u32)[0].sqrt() * res;
            (d - 0.5 * res).max(0.0)
        })
        .collect();
    if distances.is_empty() {
        return None;
    }
    distances.sort_by(f64::total_cmp);
    let at = |q: f64| distances[((distances.len() - 1) as f64 * q).round() as usize];
    Some(WallError {
        cells: distances.len(),
        median_m: at(0.5),
        p95_m: at(0.95),
        within_0_1_m: distances.iter().filter(|&&d| d <= 0.1).count() as f64
            / distances.len() as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_world_as_its_own_map_is_fully_covered_and_exact() {
        let world = World::load("apartment").expect("built-in");
        let truth = world.to_grid();
        let reachable = reachable_free(&world);
        assert!(reachable.len() > 2000);
        assert!((coverage(&reachable, &world, &truth) - 1.0).abs() < 1e-9);
        let e = wall_error(&world, &truth).expect("walls");
        assert_eq!(e.p95_m, 0.0);
        assert_eq!(e.within_0_1_m, 1.0);
        // The same map shifted by 0.4 m along x: walls across the shift lie 0.4 m off (those
        // along it mostly still lie on walls), and some free space is lost.
        let mut shifted = truth.clone();
        let o = truth.origin();
        shifted = Grid::new(
            shifted.width(),
            shifted.height(),
            shifted.resolution(),
            [o[0] + 0.4, o[1]],
            Cell::Unknown,
        );
        for y in 0..truth.height() {
            for x in 0..truth.width() {
                shifted.set((x, y), truth.get((x, y)));
            }
        }
        let e = wall_error(&world, &shifted).expect("walls");
        assert!(e.within_0_1_m < 0.85 && e.p95_m >= 0.35, "{e:?}");
        assert!(coverage(&reachable, &world, &shifted) < 0.95);
    }
}
