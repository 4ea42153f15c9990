//! How good a map is, against the simulated world it was made of: coverage of the free space
//! the drones could reach, and how far the map's walls lie from the world's.

use image::{GrayImage, Luma};
use imageproc::distance_transform::euclidean_squared_distance_transform;
use nav::grid::{Cell, Grid};
#[cfg(test)]
use sitl::VehicleParams;
use sitl::World;

/// The world's free cells a drone of `radius_m` can sweep from the drones' starts, world cells:
/// the positions its centre can reach without touching a wall (8-connected from each start),
/// and every free cell whose centre lies within the radius plus half a cell's diagonal of one
/// of them (its body overlaps the cell). A room behind a gap narrower than the drone is not
/// counted; the cells along its walls are. (Positions are cell centres, so on a grid as coarse
/// as the radius a cell deep in a corner may be missed.)
pub fn reachable_free(world: &World, radius_m: f64) -> Vec<(i64, i64)> {
    let (w, h) = world.size();
    let res = world.resolution();
    let index = |x: i64, y: i64| y as usize * w + x as usize;
    // Centre to the nearest wall face, metres.
    let room = |x: i64, y: i64| (f64::from(world.clearance(x, y)) - 0.5) * res;
    let mut centre = vec![false; w * h];
    let mut queue = std::collections::VecDeque::new();
    for s in world.starts() {
        let (x, y) = world.cell_of(*s);
        if !world.material(x, y).is_solid() && !centre[index(x, y)] {
            centre[index(x, y)] = true;
            queue.push_back((x, y));
        }
    }
    while let Some((x, y)) = queue.pop_front() {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (nx, ny) = (x + dx, y + dy);
                if world.material(nx, ny).is_solid() || room(nx, ny) < radius_m - 1e-9 {
                    continue;
                }
                let i = index(nx, ny);
                if !centre[i] {
                    centre[i] = true;
                    queue.push_back((nx, ny));
                }
            }
        }
    }
    // Distance of every cell to the nearest reachable centre.
    let centres = GrayImage::from_fn(w as u32, h as u32, |x, y| {
        Luma([u8::from(centre[y as usize * w + x as usize])])
    });
    let d2 = euclidean_squared_distance_transform(&centres);
    let reach = radius_m / res + std::f64::consts::FRAC_1_SQRT_2;
    let mut out = vec![];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let Luma([d2]) = *d2.get_pixel(x as u32, y as u32);
            if !world.material(x, y).is_solid() && d2.sqrt() <= reach + 1e-9 {
                out.push((x, y));
            }
        }
    }
    out
}

/// Fraction of the reachable free space that the map knows as free, measured at the map's
/// resolution: each reachable world cell is sampled at the centres of the map cells it holds
/// (one sample, its centre, on a map as coarse as the world), and a sample counts when the map
/// cell under it is free.
///
/// Samples within one map cell of a wall's face are left out: the face may border or cross the
/// map's cell there, and a map that marks that cell occupied is right. (On a world as fine as
/// the map — HouseExpo's 0.05 m raster — that is the layer of cells along every wall, 5 % of the
/// house; on the apartment's 0.2 m cells, the outer quarter of each cell along a wall.)
///
/// Why per map cell: sampled once, at its centre, a 0.2 m world cell read the 0.05 m map exactly
/// at the corner four map cells share, and which of the four came down to rounding. A wall
/// drawn two map cells thick then cost the whole world cell beside it on the north and east
/// sides of a room and nothing on the others.
pub fn coverage(reachable: &[(i64, i64)], world: &World, map: &Grid) -> f64 {
    let (r, o) = (world.resolution(), world.origin());
    let band = map.resolution();
    // Map cells per world cell along each axis.
    let n = ((r / band).round() as i64).max(1);
    let step = r / n as f64;
    // World cells a wall may lie in and be within the band of a sample of this one.
    let reach = (band / r).ceil() as i64;
    let (mut counted, mut known) = (0usize, 0usize);
    for &(x, y) in reachable {
        for j in 0..n {
            for i in 0..n {
                // The sample, from the cell's lower left corner.
                let s = [(i as f64 + 0.5) * step, (j as f64 + 0.5) * step];
                if face_within(world, (x, y), s, reach) < band - 1e-9 {
                    continue;
                }
                counted += 1;
                let p = [o[0] + x as f64 * r + s[0], o[1] + y as f64 * r + s[1]];
                known += usize::from(map.cell_of(p).is_some_and(|c| map.get(c) == Cell::Free));
            }
        }
    }
    if counted == 0 {
        return 0.0;
    }
    known as f64 / counted as f64
}

/// Distance from a point `s` (metres from the lower left corner of world cell `(x, y)`) to the
/// nearest solid cell within `reach` cells of it, metres (infinite when there is none).
fn face_within(world: &World, (x, y): (i64, i64), s: [f64; 2], reach: i64) -> f64 {
    let r = world.resolution();
    let mut nearest = f64::INFINITY;
    for dy in -reach..=reach {
        for dx in -reach..=reach {
            if world.material(x + dx, y + dy).is_solid() {
                // The solid cell spans [d·r, (d + 1)·r] on each axis from the corner.
                let gap = |d: i64, v: f64| (d as f64 * r - v).max(v - (d + 1) as f64 * r).max(0.0);
                nearest = nearest.min(gap(dx, s[0]).hypot(gap(dy, s[1])));
            }
        }
    }
    nearest
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

    /// `grid` on cells `k` times finer, each fine cell as the coarse one it lies in, its origin
    /// at `origin`.
    fn upsampled(grid: &Grid, k: usize, origin: [f64; 2]) -> Grid {
        let mut g = Grid::new(
            grid.width() * k,
            grid.height() * k,
            grid.resolution() / k as f64,
            origin,
            Cell::Unknown,
        );
        for y in 0..g.height() {
            for x in 0..g.width() {
                g.set((x, y), grid.get((x / k, y / k)));
            }
        }
        g
    }

    #[test]
    fn a_wall_drawn_thick_costs_the_same_on_every_side_of_a_room() {
        // 0.2 m cells, a room 2.0 × 1.2 m; the map on 0.05 m cells.
        let text = "resolution 0.2\n---\n\
                    ############\n\
                    #..........#\n\
                    #..........#\n\
                    #....1.....#\n\
                    #..........#\n\
                    #..........#\n\
                    #..........#\n\
                    ############\n";
        let world = World::parse_text("room", text).expect("a world");
        let reachable = reachable_free(&world, 0.1);
        let truth = world.to_grid();
        let k = 4;
        let map = upsampled(&truth, k, truth.origin());
        assert!((coverage(&reachable, &world, &map) - 1.0).abs() < 1e-9);
        // The north (last) or south (first) wall of the room drawn `cells` map cells thick.
        let (w, h) = (map.width(), map.height());
        let thick = |north: bool, cells: usize| {
            let mut g = map.clone();
            for d in 0..cells {
                let y = if north { h - k - 1 - d } else { k + d };
                for x in k..w - k {
                    g.set((x, y), Cell::Occupied);
                }
            }
            g
        };
        // One map cell: where a face bordering it puts a depth camera's hits; all of it still.
        for north in [true, false] {
            assert!((coverage(&reachable, &world, &thick(north, 1)) - 1.0).abs() < 1e-9);
        }
        // Two: a strip 5 cm wide lost along a wall 2 m long, the same on either side.
        let (n2, s2) = (
            coverage(&reachable, &world, &thick(true, 2)),
            coverage(&reachable, &world, &thick(false, 2)),
        );
        assert!((n2 - s2).abs() < 1e-9, "north {n2}, south {s2}");
        // Of the room's 40 × 24 map cells, less the band along its walls (38 × 22 counted),
        // the 38 of one row lost.
        assert!((n2 - (1.0 - 38.0 / (38.0 * 22.0))).abs() < 1e-9, "{n2}");
    }

    #[test]
    fn a_room_behind_a_gap_narrower_than_the_drone_is_not_reachable() {
        // 0.1 m cells, rooms 0.8 m wide; the left room's start; a door of 0.6 m into the middle
        // room, a slit of 0.3 m (narrower than a drone of 0.4 m) into the right one.
        let text = "resolution 0.1\n---\n\
                    ############################\n\
                    #........#........#........#\n\
                    #........#........#........#\n\
                    #.................#........#\n\
                    #..1..............#........#\n\
                    #.................#........#\n\
                    #.................#........#\n\
                    #..........................#\n\
                    #..........................#\n\
                    #........#.................#\n\
                    #........#........#........#\n\
                    ############################\n";
        let world = World::parse_text("rooms", text).expect("a world");
        let columns = |cells: &[(i64, i64)]| {
            let mut xs: Vec<i64> = cells.iter().map(|c| c.0).collect();
            xs.sort_unstable();
            xs.dedup();
            xs
        };
        // A drone of 0.1 m fits through both; one of 0.2 m only through the door.
        let small = reachable_free(&world, 0.1);
        assert!(columns(&small).contains(&25), "{:?}", columns(&small));
        let drone = reachable_free(&world, 0.2);
        // Both rooms it reaches, and no further than the slit's own cells (column 18).
        let reached = columns(&drone);
        assert!((1..=17).all(|x| reached.contains(&x)), "{reached:?}");
        assert!(reached.iter().all(|&x| x <= 18), "{reached:?}");
        // The cells along the walls of those rooms count (its body covers them), all but a few
        // deep in the corners.
        let h = world.size().1 as i64;
        for along_a_wall in [
            (1, 5),
            (4, 1),
            (4, h - 2),
            (8, 2),
            (10, 2),
            (13, h - 2),
            (17, 4),
        ] {
            assert!(drone.contains(&along_a_wall), "{along_a_wall:?}");
        }
        let free = (0..h)
            .flat_map(|y| (1..=17).map(move |x| (x, y)))
            .filter(|&(x, y)| !world.material(x, y).is_solid())
            .count();
        let counted = drone.iter().filter(|c| c.0 <= 17).count();
        assert!(
            counted <= free && counted + 8 >= free,
            "{counted} of {free}"
        );
    }

    #[test]
    fn the_world_as_its_own_map_is_fully_covered_and_exact() {
        let world = World::load("apartment").expect("built-in");
        let truth = world.to_grid();
        let reachable = reachable_free(&world, VehicleParams::default().radius);
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
        // Coverage on the SLAM's 0.05 m cells (on the world's own 0.2 m cells the layer along
        // every wall is not counted, see `coverage`): all of it, and the same shift loses some.
        assert!((coverage(&reachable, &world, &upsampled(&truth, 4, o)) - 1.0).abs() < 1e-9);
        let c = coverage(
            &reachable,
            &world,
            &upsampled(&truth, 4, [o[0] + 0.4, o[1]]),
        );
        assert!(c < 0.95, "{c}");
    }

    #[test]
    fn on_a_world_as_fine_as_the_map_the_cells_a_wall_face_crosses_are_not_counted() {
        // 0.05 m cells, a room 1.5 × 1.0 m: the map at the same resolution.
        let wall = "#".repeat(32);
        let inside = format!("#{}#", ".".repeat(30));
        let mut text = String::from("resolution 0.05\nceiling 2.5\n---\n");
        text += &format!("{wall}\n");
        for row in 0..20 {
            let line = if row == 10 {
                format!("#{}1{}#", ".".repeat(15), ".".repeat(14))
            } else {
                inside.clone()
            };
            text += &format!("{line}\n");
        }
        text += &format!("{wall}\n");
        let world = World::parse_text("fine", &text).expect("a world");
        let reachable = reachable_free(&world, VehicleParams::default().radius);
        let truth = world.to_grid();
        assert!((coverage(&reachable, &world, &truth) - 1.0).abs() < 1e-9);
        // Walls grown a cell into the room (where a depth camera's hits on a face that crosses
        // a cell put them): still all of it. Grown twice: a map that lost free space.
        let grow = |g: &Grid| {
            let mut out = g.clone();
            for y in 0..g.height() {
                for x in 0..g.width() {
                    let touches = [(0, 1), (2, 1), (1, 0), (1, 2)].iter().any(|&(dx, dy)| {
                        // Outside the grid reads as occupied.
                        g.get(((x + dx).wrapping_sub(1), (y + dy).wrapping_sub(1)))
                            == Cell::Occupied
                    });
                    if g.get((x, y)) == Cell::Free && touches {
                        out.set((x, y), Cell::Occupied);
                    }
                }
            }
            out
        };
        let thick = grow(&truth);
        assert!((coverage(&reachable, &world, &thick) - 1.0).abs() < 1e-9);
        let thicker = grow(&thick);
        let c = coverage(&reachable, &world, &thicker);
        assert!(c < 0.85, "{c}");
    }
}
