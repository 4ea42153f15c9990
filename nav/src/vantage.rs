//! Vantage points: where a robot stops to look around when it reaches a frontier.
//!
//! A depth camera sees nothing nearer than its minimum range (0.4 m on the simulated one, about
//! the same on a Kinect or RealSense). A look-around on the spot next to a wall, or next to the
//! unknown (which may be a wall not seen yet), turns the camera to a blank view, and tracking is
//! lost there (seen: 5 of 11 tracking losses in four two-drone missions began facing a wall
//! 0.3–0.6 m away, most during the turn at a goal). A robot can look around instead from the free
//! cell nearest its goal, in sight of it, with room on every side
//! ([`crate::PlannerConfig::look_around_room_m`], 0.7 m by default).
//!
//! A frontier can also lie where no robot can go, yet be seen from where one can: a doorway
//! seen at a slant shows a thin strip of the room behind it, too thin to fly into, and the
//! strip's edge is the frontier (HouseExpo's room 0000: a 0.74 m door left 44 % of the house
//! "out of reach"). Its [`viewpoint`] is the reachable cell nearest to it in sight of it.

use image::{GrayImage, Luma};
use imageproc::distance_transform::euclidean_squared_distance_transform;

use crate::grid::{Cell, CellXY, Grid};
use crate::search::line_of_sight;

/// Where to look around from near `goal`: the cell nearest to it (within `max_shift_m`, free on
/// `inflated`, in a straight line of free `inflated` cells from the goal) whose distance to
/// anything on `map` that is not known free (a wall, the unknown, the map's edge) is at least
/// `clearance_m`. Without one, the cell of most room among those candidates; the goal itself when
/// nothing near it has more room than it. With no room asked (`clearance_m` ≤ 0), the goal.
pub fn vantage(
    map: &Grid,
    inflated: &Grid,
    goal: CellXY,
    clearance_m: f64,
    max_shift_m: f64,
) -> CellXY {
    if clearance_m <= 0.0 {
        return goal; // no room asked: the goal is its own vantage (the planner's default)
    }
    let res = map.resolution();
    let shift = (max_shift_m.max(0.0) / res).ceil() as isize;
    let half = shift + (clearance_m.max(0.0) / res).ceil() as isize + 1;
    let (gx, gy) = (goal.0 as isize, goal.1 as isize);
    let side = (2 * half + 1) as u32;
    // The window around the goal: 1 where the camera may face something too near (outside the
    // map counts as solid).
    let cell_at = |i: u32, j: u32| {
        let (x, y) = (gx - half + i as isize, gy - half + j as isize);
        if x < 0 || y < 0 {
            Cell::Occupied
        } else {
            map.get((x as usize, y as usize))
        }
    };
    let blocked = GrayImage::from_fn(side, side, |i, j| {
        Luma([u8::from(cell_at(i, j) != Cell::Free)])
    });
    let d2 = euclidean_squared_distance_transform(&blocked);
    // Squared distance (cells²) from a cell's centre to the nearest blocked centre, less half a
    // cell: the blocked cell's edge is half a cell nearer than its centre.
    let room_m = |i: isize, j: isize| {
        let Luma([d]) = *d2.get_pixel((i + half) as u32, (j + half) as u32);
        (d.sqrt() - 0.5).max(0.0) * res
    };
    let mut candidates: Vec<(isize, f64, CellXY)> = vec![];
    for dy in -shift..=shift {
        for dx in -shift..=shift {
            let r2 = dx * dx + dy * dy;
            let (x, y) = (gx + dx, gy + dy);
            if r2 > shift * shift || x < 0 || y < 0 {
                continue;
            }
            let c = (x as usize, y as usize);
            if inflated.get(c) == Cell::Free {
                candidates.push((r2, room_m(dx, dy), c));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
    let in_sight = |c: CellXY| c == goal || line_of_sight(inflated, goal, c);
    if let Some(&(_, _, c)) = candidates
        .iter()
        .find(|&&(_, room, c)| room >= clearance_m && in_sight(c))
    {
        return c;
    }
    // Nowhere with room enough: the most room in sight, if more than the goal's own.
    let own = room_m(0, 0);
    candidates
        .iter()
        .filter(|&&(_, room, c)| room > own && in_sight(c))
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
        .map_or(goal, |&(_, _, c)| c)
}

/// Where to look at an unreachable `goal` from: the cell nearest to it (within `range_m`) that
/// `reachable` marks (indexed like `map`'s cells) and from whose centre the straight line to the
/// goal crosses only cells `map` knows as free. `None` if there is none.
pub fn viewpoint(map: &Grid, reachable: &[bool], goal: CellXY, range_m: f64) -> Option<CellXY> {
    let r = (range_m.max(0.0) / map.resolution()).floor() as isize;
    let (gx, gy) = (goal.0 as isize, goal.1 as isize);
    let mut candidates: Vec<(isize, CellXY)> = vec![];
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, y) = (gx + dx, gy + dy);
            let d2 = dx * dx + dy * dy;
            if d2 > r * r || x < 0 || y < 0 || x as usize >= map.width() {
                continue;
            }
            let c = (x as usize, y as usize);
            if reachable.get(y as usize * map.width() + x as usize) == Some(&true) {
                candidates.push((d2, c));
            }
        }
    }
    candidates.sort_unstable();
    candidates
        .into_iter()
        .map(|(_, c)| c)
        .find(|&c| line_of_sight(map, c, goal))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::grid::tests::grid;
    use crate::inflate::inflate;

    /// Distance (m) from a cell's centre to the nearest cell that is not free, edge to centre.
    pub(crate) fn room(g: &Grid, c: CellXY) -> f64 {
        let mut best = f64::INFINITY;
        for y in 0..g.height() {
            for x in 0..g.width() {
                if g.get((x, y)) != Cell::Free {
                    let dx = (x as f64 - c.0 as f64).abs() - 0.5;
                    let dy = (y as f64 - c.1 as f64).abs() - 0.5;
                    best = best.min(dx.max(0.0).hypot(dy.max(0.0)) * g.resolution());
                }
            }
        }
        best
    }

    fn dist_m(g: &Grid, a: CellXY, b: CellXY) -> f64 {
        (a.0 as f64 - b.0 as f64).hypot(a.1 as f64 - b.1 as f64) * g.resolution()
    }

    #[test]
    fn a_goal_against_a_wall_is_looked_around_from_a_step_back() {
        // 0.1 m cells: a room 2.0 × 1.6 m; the goal 0.2 m from the north wall.
        let wall = "#".repeat(22);
        let inside = format!("#{}#", ".".repeat(20));
        let rows: Vec<&str> = std::iter::once(wall.as_str())
            .chain(std::iter::repeat_n(inside.as_str(), 16))
            .chain(std::iter::once(wall.as_str()))
            .collect();
        let g = grid(&rows);
        let inflated = inflate(&g, 0.15);
        let goal = (10, 15);
        assert!(room(&g, goal) < 0.3);
        let v = vantage(&g, &inflated, goal, 0.6, 1.5);
        assert!(
            room(&g, v) >= 0.6 - 1e-9,
            "{v:?}: {} m of room",
            room(&g, v)
        );
        // The nearest such cell: straight back from the wall, no further than needed.
        assert_eq!(v.0, 10, "{v:?}");
        assert!(dist_m(&g, goal, v) <= 0.5, "{v:?}");
        // No room asked: the goal, wherever it is.
        assert_eq!(vantage(&g, &inflated, goal, 0.0, 1.5), goal);
        // Where there is room already, the goal is its own vantage.
        assert_eq!(vantage(&g, &inflated, (10, 8), 0.6, 1.5), (10, 8));
    }

    #[test]
    fn the_unknown_counts_as_a_wall_and_the_vantage_stays_on_the_goals_side() {
        // A frontier goal next to the unknown (west), a thin wall to the east with a wide free
        // room behind it: the cell of most room is behind the wall, out of sight of the goal.
        let wall = "#".repeat(19);
        let rows: Vec<&str> = std::iter::once(wall.as_str())
            .chain(std::iter::repeat_n("??......#.........#", 7))
            .chain(std::iter::once(wall.as_str()))
            .collect();
        let g = grid(&rows);
        let inflated = inflate(&g, 0.05);
        let goal = (2, 4);
        let v = vantage(&g, &inflated, goal, 0.6, 1.5);
        assert!(v.0 < 8, "{v:?} is behind the wall");
        assert!(line_of_sight(&inflated, goal, v));
        // The room between the unknown and the wall is 0.6 m wide: nowhere has 0.6 m of room,
        // so the vantage is the best there is — its middle, further from the unknown than the goal.
        assert!(room(&g, v) > room(&g, goal), "{v:?}");
        assert!((4..=5).contains(&v.0), "{v:?}");
    }

    #[test]
    fn a_goal_in_a_closed_nook_is_kept() {
        // Nothing near the goal has more room than it: it stays.
        let g = grid(&["#####", "#...#", "#####"]);
        let inflated = g.clone();
        assert_eq!(vantage(&g, &inflated, (2, 1), 0.6, 1.5), (2, 1));
    }

    /// 0.1 m cells: a known room (east) behind a wall with a 0.4 m door (x = 8, rows 4–7 from
    /// the top), and through the door a thin strip of the unknown room (west) seen at a slant.
    pub(crate) fn doorway_seen_at_a_slant() -> Grid {
        grid(&[
            "########################",
            "#???????#..............#",
            "#???????#..............#",
            "#???????#..............#",
            "#??????................#",
            "#????..................#",
            "#??....??..............#",
            "#?....???..............#",
            "#???????#..............#",
            "#???????#..............#",
            "########################",
        ])
    }

    #[test]
    fn an_unreachable_goal_is_looked_at_from_the_nearest_reachable_cell_in_sight() {
        let g = doorway_seen_at_a_slant();
        // Grown by 0.2 m the door is shut: only the east room is reachable.
        let inflated = inflate(&g, 0.2);
        let reachable = crate::search::Graph::new(&inflated).reachable(&[(16, 5)]);
        let at = |(x, y): CellXY| reachable[y * g.width() + x];
        let goal = (2, 3); // the strip's far end, at the edge of the unknown
        assert!(!at(goal) && g.get(goal) == Cell::Free);
        let v = viewpoint(&g, &reachable, goal, 2.5).expect("a cell that sees it");
        assert!(at(v) && v.0 > 8, "{v:?}");
        assert!(line_of_sight(&g, v, goal));
        // Nearest: no reachable cell in sight of the goal is nearer.
        let d2 = |c: CellXY| (c.0 as f64 - 2.0).powi(2) + (c.1 as f64 - 3.0).powi(2);
        for y in 0..g.height() {
            for x in 0..g.width() {
                if at((x, y)) && line_of_sight(&g, (x, y), goal) {
                    assert!(d2((x, y)) >= d2(v), "{:?} is nearer than {v:?}", (x, y));
                }
            }
        }
        // Out of range: none.
        assert_eq!(viewpoint(&g, &reachable, goal, 0.5), None);
        // Behind a wall without a door: none.
        let g = grid(&["#########", "#..#....#", "#..#....#", "#########"]);
        let reachable = crate::search::Graph::new(&g).reachable(&[(6, 1)]);
        assert!(reachable[g.width() + 5] && !reachable[g.width() + 1]);
        assert_eq!(viewpoint(&g, &reachable, (1, 1), 2.5), None);
    }
}
