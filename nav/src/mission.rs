//! The mission planner step (thesis §4.4, Algorithms 1–4): from the latest map and every robot's
//! pose, each robot's frontier target and path, a hover, or "exploration complete".

use crate::assignment::{greedy, hungarian, spread};
use crate::clearance::{Comfort, centred_path};
use crate::frontier::{Frontier, FrontierLimits, frontiers, regions};
use crate::grid::{Cell, CellXY, Grid};
use crate::inflate::inflate;
use crate::local::wrap_angle;
use crate::search::{Graph, UNREACHABLE, dijkstra, metres, nearest_free, simplify};
use crate::vantage::{vantage, viewpoint};

/// How robots are matched to frontiers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    /// Least total cost (the Hungarian algorithm).
    Hungarian,
    /// Cheapest pair first (explore_lite-style baseline).
    Greedy,
}

/// Planner settings.
#[derive(Debug, Clone)]
pub struct PlannerConfig {
    /// Obstacles are grown by this much, metres.
    pub robot_radius_m: f64,
    /// Frontiers with fewer cells are ignored.
    pub min_frontier_cells: usize,
    /// Frontiers wider than this (metres) are cut into pieces, each a target of its own (about
    /// the camera's range: from a piece's goal the robot sees all of it).
    pub max_frontier_span_m: f64,
    /// Assignment strategy.
    pub strategy: Strategy,
    /// Frontiers whose goal lies within `blacklist_radius_m` of one of these points are ignored
    /// (places a robot reached without the frontier going away, e.g. unknown space inside solid
    /// furniture), map frame.
    pub blacklist: Vec<[f64; 2]>,
    /// Radius around blacklisted points, metres.
    pub blacklist_radius_m: f64,
    /// A robot looks around from a cell with this much room on every side (the camera's minimum
    /// range and its offset from the body, with a margin), metres: see [`crate::vantage`]. 0
    /// looks around from the frontier's goal itself. (Off for a while: with it, shield missions
    /// mapped walls worse — that was the SLAM back end's rotation-norm fault, since fixed.)
    pub look_around_room_m: f64,
    /// ... found at most this far from its frontier's goal, metres.
    pub look_around_shift_m: f64,
    /// Paths keep this far from the inflated obstacles where they can (through the middle of
    /// a door rather than along its frame), metres: see [`crate::clearance`]. 0 (the default):
    /// shortest paths. The mission runtime can give plans at its thinner radii the difference
    /// to the widest ([`centring_comfort`]; on in `gcs explore` unless `--centre-paths false`),
    /// and [`plan_first_open`] does the same on a path lent by a thinner configuration. (0.3 m on every plan, tried early on, cut collisions on true
    /// poses but mapped less on SLAM poses, when the SLAM was far weaker.)
    pub comfort_m: f64,
    /// Paths keep this far from the unknown where they can, metres (see [`crate::clearance`]):
    /// a wall the camera has not seen yet may begin at its edge, and only walls on the map are
    /// inflated. [`PlannerConfig::comfort_m`] keeps from the unknown too, but at the widest
    /// radius it is 0. 0 (the default): nothing more.
    pub unknown_comfort_m: f64,
    /// A frontier whose goal no robot can reach is given, as its goal, the reachable cell
    /// nearest to it within this range that sees it ([`crate::vantage::viewpoint`]), metres
    /// (within the camera's range: the occupancy map takes depth up to 4 m). 0: such a frontier
    /// stays out of reach.
    pub view_range_m: f64,
    /// Frontiers are found on the map grown by this much (at most the robot radius), metres:
    /// enough to hide the unknown inside walls, not so much that a room seen through a door
    /// at a slant is hidden by the door's jambs.
    pub frontier_margin_m: f64,
    /// Frontiers whose goals lie within this distance of each other, in sight, are one region,
    /// and robots are spread one to a region before any region gets a second
    /// ([`crate::assignment::spread`]), metres: a robot looking around at one goal sees the
    /// others (the camera reaches 4 m). 0 (the default): every frontier is a region of its own.
    /// Off by default: on the apartment (true poses, seeds 0–5) 2.5 m took two drones 206 s on
    /// average against 225 s, but four drones 170 s against 161 s — within the spread of
    /// single runs either way.
    pub region_radius_m: f64,
    /// Per robot (in the order of the robots planned for), the frontier goal it flies to now, if
    /// any, map frame: the frontier whose goal lies nearest it, within [`SAME_FRONTIER_M`], costs
    /// that robot [`PlannerConfig::hold_margin_m`] less in the assignment. Without it two robots
    /// whose costs to two goals nearly tie swap them at every step as they move (building 31:
    /// the same two goals swapped at every plan for 80 s), and each swap restarts the flight.
    /// Empty: no robot holds a goal.
    pub held: Vec<Option<[f64; 2]>>,
    /// What holding on to its goal is worth to a robot, metres of path: another frontier takes
    /// it away only when cheaper by more than this (or when the assignment as a whole gains
    /// more); 0: every step assigns afresh. 0.25 m by default, a few cells of path: enough that
    /// two robots whose costs tie (two goals ahead of both in a corridor cost the same in
    /// either assignment) no longer swap them at every step, too little to keep a robot from a
    /// frontier really nearer. On the main command (two drones, SLAM poses, seeds 0–19) it took
    /// the swaps from 135 to 2 and the mean exploration time from 184 s to 169 s; 1 m had made
    /// missions slower (true poses, seeds 0–1: 155 → 177 s with two drones).
    pub hold_margin_m: f64,
    /// A frontier whose unknown side is an enclosed pocket of at most this much is ignored, m²
    /// ([`crate::frontier::opens_onto_pocket`], on the map the frontiers are found on): the
    /// inside of a pillar or of furniture seen from every side but one, where a robot sent to
    /// look sees a face, not a room. 0: none is.
    pub max_pocket_m2: f64,
    /// Per robot (in the order of the robots planned for), its heading, radians in the map
    /// frame, counter-clockwise from +x; `None` (or missing): no turn is weighed for it (a robot
    /// looking around ends its turn facing who knows where). See [`PlannerConfig::turn_m_per_rad`].
    pub headings: Vec<Option<f64>>,
    /// What turning on the spot costs a robot, metres of path per radian: a frontier whose path
    /// sets off more than [`PlannerConfig::turn_on_spot_rad`] away from the robot's heading costs
    /// it the whole turn as well as the path. A drone whose camera looks where it flies turns to
    /// face such a path before it moves (36°/s, while it would fly 0.45 m/s: 0.7 m/rad); a
    /// frontier behind it is 2 m dearer than its path says. 0: paths alone are weighed. 0.7 by
    /// default (it weighs nothing until [`PlannerConfig::headings`] are given).
    pub turn_m_per_rad: f64,
    /// A path that sets off within this of the robot's heading is flown while turning, radians:
    /// no turn is weighed for it. The mission gives its path follower's
    /// [`crate::local::FollowerConfig::turn_threshold_rad`]; 90° by default, as the runtime's.
    pub turn_on_spot_rad: f64,
    /// A robot left without a frontier (more robots than frontiers) flies toward the nearest
    /// frontier another robot is headed for and stops this far short of it along its path,
    /// metres ([`STAGE_SPACING_M`] further for each robot nearer it that stages there too):
    /// when that robot's look around opens new frontiers, the one waiting behind it is near
    /// them. 0: it hovers where it is.
    pub stage_back_m: f64,
}

impl PlannerConfig {
    /// The distances its paths keep where they can.
    pub fn comfort(&self) -> Comfort {
        Comfort {
            blocked_m: self.comfort_m,
            unknown_m: self.unknown_comfort_m,
        }
    }
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            robot_radius_m: 0.3,
            min_frontier_cells: 5,
            max_frontier_span_m: 4.0,
            strategy: Strategy::Hungarian,
            blacklist: vec![],
            blacklist_radius_m: 0.5,
            look_around_room_m: 0.7,
            look_around_shift_m: 1.5,
            comfort_m: 0.0,
            unknown_comfort_m: 0.0,
            view_range_m: 2.5,
            frontier_margin_m: 0.1,
            region_radius_m: 0.0,
            held: vec![],
            hold_margin_m: 0.25,
            max_pocket_m2: 0.5,
            headings: vec![],
            turn_m_per_rad: 0.7,
            turn_on_spot_rad: std::f64::consts::FRAC_PI_2,
            stage_back_m: 2.0,
        }
    }
}

/// What one robot should do.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotPlan {
    /// Index of its frontier in [`Plan::frontiers`]; `None` to hover, or, with a path, to move
    /// up behind a frontier another robot has ([`PlannerConfig::stage_back_m`]).
    pub frontier: Option<usize>,
    /// Path length to it, metres.
    pub cost_m: Option<f64>,
    /// Its frontier's goal, map frame, metres (what is given up if the frontier stays).
    pub goal: Option<[f64; 2]>,
    /// Waypoints from the robot to where it looks around (its vantage, near the goal), or to
    /// where it waits behind another robot's frontier, map frame, metres (straight segments).
    pub path: Vec<[f64; 2]>,
    /// Why it hovers, when it does.
    pub hover_reason: Option<&'static str>,
}

/// The result of one planner step.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The inflated map it planned on.
    pub inflated: Grid,
    /// The robot radius that map is inflated by, metres.
    pub robot_radius_m: f64,
    /// The frontiers, largest first (then those [`plan_first_open`] added for robots left without
    /// one).
    pub frontiers: Vec<Frontier>,
    /// Goals of the frontiers left out because they lie near a blacklisted point, map frame.
    pub ignored: Vec<[f64; 2]>,
    /// Robots × frontiers, metres, after the thesis's rules: unreachable → the largest finite cost
    /// plus 1 (strictly more than any reachable frontier, so a tie never sends a robot to a frontier
    /// it cannot reach while it could reach another), invalid pose → largest + 10. A frontier
    /// [`plan_first_open`] added for a robot left without one has the costs of the thinner
    /// configuration that reached it.
    pub costs: Vec<Vec<f64>>,
    /// Per robot, in input order.
    pub robots: Vec<RobotPlan>,
    /// No frontier is left that any robot with a valid pose can reach.
    pub complete: bool,
    /// Some robot had a free cell near it to plan from. Without one the plan cannot tell
    /// whether anything is left (`complete` is false): a robot in a passage narrower than twice
    /// the radius has none.
    pub placed: bool,
}

/// A robot position the planner cannot use.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The position is outside the map.
    #[error(
        "robot {robot} at ({x:.2}, {y:.2}) m is outside the map ({min_x:.2}..{max_x:.2}, {min_y:.2}..{max_y:.2}) m"
    )]
    OutsideMap {
        /// Robot index.
        robot: usize,
        /// Its x.
        x: f64,
        /// Its y.
        y: f64,
        /// Map extent.
        min_x: f64,
        /// Map extent.
        max_x: f64,
        /// Map extent.
        min_y: f64,
        /// Map extent.
        max_y: f64,
    },
}

/// One planner step with a fallback: plans with each configuration in turn (a mission lists
/// them widest robot radius first) and keeps the first plan that leaves a frontier to explore,
/// else the last one (one in which no robot has room to start, [`Plan::placed`], is passed
/// over: else a robot in a passage only a thinner radius fits would hover there for good, the
/// wide plan neither giving it a goal nor ending the mission) — a map whose last frontiers lie behind a narrow door is explored with a
/// thinner margin rather than declared complete; a robot that plan leaves without a frontier
/// gets one a thinner configuration reaches and no other robot has (`lend_to_idle`), on a path
/// that keeps the plan's radius where it can ([`PlannerConfig::comfort_m`] at least the
/// difference of the radii): through the middle of a door only the thinner radius passes, not
/// along a jamb (with 0.25 m for a drone of 0.2 m, a path rounding a jamb leaves 5 cm). Each
/// configuration first finds frontiers on its inflated map alone and reaches them; only when
/// the last finds none at all does it try its last resorts, the frontiers found on the map
/// grown by the thin margin ([`PlannerConfig::frontier_margin_m`]) and those looked at from afar
/// ([`PlannerConfig::view_range_m`]). Earlier, a wider margin would peek through every door it
/// cannot pass instead of handing over to a thinner one that flies through; and with the thin
/// margin always on, two-drone SLAM missions on the apartment completed less often (seeds
/// 0–11: 5 against 8 without it; the cause not pinned down, frontiers along a SLAM map's ragged
/// walls suspected); and trying them as soon as no frontier was reachable (some seen, none
/// reached: the start of a flight) lost the camera bridge's drone early in 3 of 4 runs of
/// `fly_explores_with_an_autopilot_whose_camera_the_bridge_renders_at_its_reported_pose`.
/// `None` only when `configs` is empty.
pub fn plan_first_open(
    map: &Grid,
    robots: &[Option<[f64; 2]>],
    configs: &[PlannerConfig],
) -> Result<Option<Plan>, PlanError> {
    let strict = |config: &PlannerConfig| PlannerConfig {
        view_range_m: 0.0,
        frontier_margin_m: config.robot_radius_m,
        ..config.clone()
    };
    let mut chosen = None;
    for (k, config) in configs.iter().enumerate() {
        let mut step = plan(map, robots, &strict(config))?;
        // A configuration no robot fits where it is says nothing: the next, thinner, one may.
        let (open, none_seen) = (
            !step.complete && (step.placed || k + 1 == configs.len()),
            step.frontiers.is_empty(),
        );
        if open {
            for thinner in &configs[k + 1..] {
                let thinner = PlannerConfig {
                    comfort_m: thinner
                        .comfort_m
                        .max(config.robot_radius_m - thinner.robot_radius_m),
                    ..strict(thinner)
                };
                if !lend_to_idle(map, robots, &thinner, &mut step)? {
                    break;
                }
            }
            stage_idle(map, robots, &strict(config), &mut step);
            chosen = Some(step);
            break;
        }
        chosen = Some(step);
        if k + 1 == configs.len() && none_seen {
            chosen = Some(plan(map, robots, config)?);
        }
    }
    Ok(chosen)
}

/// Two frontier goals this close are the same frontier's, metres: from plans with different
/// robot radii, or from one plan and the next (a frontier's goal moves as the map grows).
pub const SAME_FRONTIER_M: f64 = 1.0;

/// Robots with a pose that the plan `step` left without a frontier, although a thinner
/// configuration (`thinner`) reaches one no other robot of `step` is headed for, are given it
/// (with its path and cost from that configuration): a room behind a door is reachable with
/// one robot radius and not with a wider one, and while another robot still had a frontier
/// the wider configuration's plan left the robot nearest that room hovering (in SITL, beside
/// the apartment's 1 m doors, two drones on true poses spent 94 drone-seconds of a 217 s
/// mission without a goal; 6 with this). Returns whether a robot is still without a frontier.
fn lend_to_idle(
    map: &Grid,
    robots: &[Option<[f64; 2]>],
    thinner: &PlannerConfig,
    step: &mut Plan,
) -> Result<bool, PlanError> {
    let idle = |step: &Plan| -> Vec<bool> {
        step.robots
            .iter()
            .zip(robots)
            .map(|(r, p)| p.is_some() && r.frontier.is_none())
            .collect()
    };
    let waiting = idle(step);
    if !waiting.contains(&true) {
        return Ok(false);
    }
    let busy: Vec<[f64; 2]> = step.robots.iter().filter_map(|r| r.goal).collect();
    let only_waiting: Vec<Option<[f64; 2]>> = robots
        .iter()
        .zip(&waiting)
        .map(|(p, &w)| p.filter(|_| w))
        .collect();
    let config = PlannerConfig {
        blacklist: [thinner.blacklist.as_slice(), &busy].concat(),
        ..thinner.clone()
    };
    let thin = plan(map, &only_waiting, &config)?;
    // Only the waiting robots had a pose in `thin`: the others hover there.
    for (r, planned) in thin.robots.into_iter().enumerate() {
        let (Some(f), Some(goal)) = (planned.frontier, planned.goal) else {
            continue;
        };
        let taken = busy
            .iter()
            .any(|b| (b[0] - goal[0]).hypot(b[1] - goal[1]) <= SAME_FRONTIER_M);
        if taken {
            continue;
        }
        step.frontiers.push(thin.frontiers[f].clone());
        for (row, thin_row) in step.costs.iter_mut().zip(&thin.costs) {
            row.push(thin_row[f]);
        }
        step.robots[r] = RobotPlan {
            frontier: Some(step.frontiers.len() - 1),
            ..planned
        };
    }
    Ok(idle(step).contains(&true))
}

/// How much further back each robot waits than the one before it behind the same frontier,
/// metres ([`PlannerConfig::stage_back_m`]).
pub const STAGE_SPACING_M: f64 = 1.0;

/// A robot is not sent to wait somewhere nearer than this, metres: it hovers where it is.
const STAGE_MIN_MOVE_M: f64 = 0.5;

/// Robots with a pose that `step` leaves without a frontier are sent toward the frontier
/// another robot is headed for that is cheapest for them, to wait
/// [`PlannerConfig::stage_back_m`] short of it along their path ([`STAGE_SPACING_M`] more per
/// robot ahead of them there). In SITL (apartment, four drones on true poses) three drones
/// hovered for about 10 s a mission where the corridor's one frontier had a drone and the
/// rooms off it were not yet seen.
fn stage_idle(map: &Grid, robots: &[Option<[f64; 2]>], config: &PlannerConfig, step: &mut Plan) {
    if config.stage_back_m <= 0.0 {
        return;
    }
    let busy: Vec<usize> = step.robots.iter().filter_map(|r| r.frontier).collect();
    // (robot, frontier, path to that frontier's look-around spot, its length)
    let mut staging: Vec<(usize, usize, Vec<[f64; 2]>, f64)> = vec![];
    for (r, p) in robots.iter().enumerate() {
        let Some(p) = p.filter(|_| step.robots[r].frontier.is_none()) else {
            continue;
        };
        let inflated = &step.inflated;
        let origin = inflated
            .cell_of(p)
            .and_then(|c| free_start(inflated, c, config.robot_radius_m));
        let nearest = busy
            .iter()
            .copied()
            .min_by(|&a, &b| step.costs[r][a].total_cmp(&step.costs[r][b]));
        let (Some(origin), Some(f)) = (origin, nearest) else {
            continue;
        };
        let look_from = vantage(
            map,
            inflated,
            step.frontiers[f].goal,
            config.look_around_room_m,
            config.look_around_shift_m,
        );
        if let Some(cells) = centred_path(inflated, origin, look_from, config.comfort()) {
            let path: Vec<[f64; 2]> = cells.into_iter().map(|c| inflated.center_of(c)).collect();
            let length = path_length(&path);
            staging.push((r, f, path, length));
        }
    }
    staging.sort_by(|a, b| a.3.total_cmp(&b.3));
    let mut ahead = vec![0usize; step.frontiers.len()];
    for (r, f, path, length) in staging {
        let back = config.stage_back_m + STAGE_SPACING_M * ahead[f] as f64;
        ahead[f] += 1;
        if length - back < STAGE_MIN_MOVE_M {
            continue;
        }
        step.robots[r] = RobotPlan {
            frontier: None,
            cost_m: Some(length - back),
            goal: None,
            path: cut_short(&path, back),
            hover_reason: None,
        };
    }
}

/// The length of a path of straight segments, metres.
pub fn path_length(path: &[[f64; 2]]) -> f64 {
    path.windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum()
}

/// `path` without its last `back_m` metres (just its start if it is no longer than that).
pub fn cut_short(path: &[[f64; 2]], back_m: f64) -> Vec<[f64; 2]> {
    let mut keep = path_length(path) - back_m;
    let mut out = path.first().map(|&p| vec![p]).unwrap_or_default();
    for w in path.windows(2) {
        if keep <= 0.0 {
            break;
        }
        let step = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        if step <= keep {
            out.push(w[1]);
        } else {
            let t = keep / step;
            out.push([
                w[0][0] + t * (w[1][0] - w[0][0]),
                w[0][1] + t * (w[1][1] - w[0][1]),
            ]);
        }
        keep -= step;
    }
    out
}

/// The comfort distance ([`PlannerConfig::comfort_m`]) of a plan at `radius` among the planner's
/// `radii` when paths are `centred`: what the widest of them keeps beyond it (0 when they are
/// not: shortest paths). A plan at the thinnest radius (0.25 m for
/// the 0.2 m drone) is made when a door is too narrow on the map for the wider ones, and its
/// shortest path grazes the door's jamb with 5 cm to spare, more where it turns just past the
/// door and the path follower cuts the corner. On true poses, four drones, drones passed the
/// west doors of the apartment 0.1–0.2 m off their middle, toward the jamb on the inside of the
/// turn, and most near misses were there.
pub fn centring_comfort(centred: bool, radii: &[f64], radius: f64) -> f64 {
    if !centred {
        return 0.0;
    }
    let widest = radii.iter().copied().fold(radius, f64::max);
    widest - radius
}

/// The cell a robot in `cell` of `inflated` starts its paths from: the nearest free one (it may
/// be inside the inflated band around a wall), looking as far as two robot radii.
fn free_start(inflated: &Grid, cell: CellXY, robot_radius_m: f64) -> Option<CellXY> {
    let reach = (robot_radius_m / inflated.resolution()).ceil() as usize * 2 + 2;
    nearest_free(inflated, cell, reach)
}

/// One planner step. `robots[i]` is robot i's position in the map frame, `None` if its pose is
/// invalid (it is planned to hover).
pub fn plan(
    map: &Grid,
    robots: &[Option<[f64; 2]>],
    config: &PlannerConfig,
) -> Result<Plan, PlanError> {
    let starts = robots
        .iter()
        .enumerate()
        .map(|(robot, p)| match p {
            None => Ok(None),
            Some(p) => map.cell_of(*p).map(Some).ok_or_else(|| {
                let o = map.origin();
                PlanError::OutsideMap {
                    robot,
                    x: p[0],
                    y: p[1],
                    min_x: o[0],
                    max_x: o[0] + map.width() as f64 * map.resolution(),
                    min_y: o[1],
                    max_y: o[1] + map.height() as f64 * map.resolution(),
                }
            }),
        })
        .collect::<Result<Vec<Option<CellXY>>, _>>()?;
    let inflated = inflate(map, config.robot_radius_m);
    let graph = Graph::new(&inflated);
    let origins: Vec<Option<CellXY>> = starts
        .iter()
        .map(|s| s.and_then(|c| free_start(&inflated, c, config.robot_radius_m)))
        .collect();
    // Frontiers are found on the map grown by a thin margin only: the strip of a room seen
    // through a door at a slant lies within the robot's radius of the door's jambs, and on the
    // inflated map its frontier vanished (HouseExpo's room 0000: the west half of the house
    // left unexplored in 3 of 12 missions). A goal in the band is moved to the nearest free cell
    // of the inflated map in sight of it.
    let margin = config.frontier_margin_m.clamp(0.0, config.robot_radius_m);
    let limits = FrontierLimits {
        min_cells: config.min_frontier_cells,
        max_span_m: config.max_frontier_span_m,
        max_pocket_cells: (config.max_pocket_m2.max(0.0) / map.resolution().powi(2)) as usize,
    };
    let mut all = if margin < config.robot_radius_m {
        let mut all = frontiers(&inflate(map, margin), &limits);
        let free: Vec<bool> = inflated.cells().iter().map(|c| *c == Cell::Free).collect();
        let band = config.robot_radius_m - margin + 2.0 * map.resolution();
        all.retain_mut(|f| {
            if !free[inflated.index(f.goal)] {
                match viewpoint(map, &free, f.goal, band) {
                    Some(v) => f.goal = v,
                    None => return false,
                }
            }
            true
        });
        all
    } else {
        frontiers(&inflated, &limits)
    };
    if config.view_range_m > 0.0 {
        // A goal no robot can reach is looked at from where one can (a doorway seen at a slant).
        let reachable = graph.reachable(&origins.iter().flatten().copied().collect::<Vec<_>>());
        for f in &mut all {
            if !reachable[inflated.index(f.goal)]
                && let Some(v) = viewpoint(map, &reachable, f.goal, config.view_range_m)
            {
                f.goal = v;
            }
        }
    }
    let (frontiers, ignored): (Vec<Frontier>, Vec<Frontier>) = all.into_iter().partition(|f| {
        let g = inflated.center_of(f.goal);
        config
            .blacklist
            .iter()
            .all(|b| (b[0] - g[0]).hypot(b[1] - g[1]) > config.blacklist_radius_m)
    });
    let ignored = ignored.iter().map(|f| inflated.center_of(f.goal)).collect();
    let goals: Vec<CellXY> = frontiers.iter().map(|f| f.goal).collect();
    // The bearings paths set off on, for the robots whose turn is weighed.
    let bearings_for: Vec<bool> = (0..robots.len())
        .map(|r| config.turn_m_per_rad > 0.0 && config.headings.get(r).copied().flatten().is_some())
        .collect();
    let reached = search_all(&graph, &inflated, &origins, &goals, &bearings_for);
    // Robots × frontiers, metres; `None` where unreachable (a whole row for a robot without a
    // start).
    let raw: Vec<Vec<Option<f64>>> = reached
        .iter()
        .map(|row| {
            (0..goals.len())
                .map(|f| {
                    row.as_ref()
                        .map(|r| r.costs[f])
                        .filter(|&c| c != UNREACHABLE)
                        .map(|c| metres(&inflated, c))
                })
                .collect()
        })
        .collect();
    let costs = thesis_costs(&raw, &reached);
    let assignment = if frontiers.is_empty() {
        vec![None; robots.len()]
    } else {
        let region = regions(map, &frontiers, config.region_radius_m);
        let centres: Vec<[f64; 2]> = goals.iter().map(|&g| inflated.center_of(g)).collect();
        let held = held_frontiers(&raw, &centres, &config.held);
        let turns = turns(&reached, &config.headings, config);
        // What the assignment weighs: the paths with their turns and the held frontiers' margin;
        // the unreachable pairs priced above the dearest of these, not of the paths alone (a
        // half turn adds 2.2 m: a frontier behind a robot then cost more than one it cannot
        // reach, and it hovered).
        let weighed = holding(turning(raw.clone(), &turns), &held, config.hold_margin_m);
        match config.strategy {
            // The thesis pads the matrix to square with zero-cost dummies; the rectangular solver
            // reaches the same optimum without the O(n³) cost of the padding.
            Strategy::Hungarian => spread(&thesis_costs(&weighed, &reached), &region, hungarian),
            Strategy::Greedy => {
                // The baseline only considers pairs that can actually be flown.
                let usable: Vec<Vec<f64>> = weighed
                    .iter()
                    .map(|r| r.iter().map(|c| c.unwrap_or(f64::INFINITY)).collect())
                    .collect();
                spread(&usable, &region, greedy)
            }
        }
    };
    let robots_out = (0..robots.len())
        .map(|r| {
            let Some(origin) = origins[r] else {
                return hover(if starts[r].is_none() {
                    "pose invalid"
                } else {
                    "no free cell near the robot"
                });
            };
            let Some(f) = assignment[r] else {
                return hover(if frontiers.is_empty() {
                    "no frontier"
                } else {
                    "no frontier left for this robot"
                });
            };
            // The path by A* (the same cost as the search's): the searches keep only their costs
            // to the goals, not a field over the whole map per robot (8 bytes a cell: on a
            // 135 × 147 m building eight drones' fields were 0.5 GB).
            let goal = frontiers[f].goal;
            let look_from = vantage(
                map,
                &inflated,
                goal,
                config.look_around_room_m,
                config.look_around_shift_m,
            );
            let (Some(cost), Some(cells)) = (
                raw[r][f],
                centred_path(&inflated, origin, look_from, config.comfort()),
            ) else {
                return hover("assigned frontier unreachable");
            };
            let path = cells.into_iter().map(|c| inflated.center_of(c)).collect();
            RobotPlan {
                frontier: Some(f),
                cost_m: Some(cost),
                goal: Some(inflated.center_of(goal)),
                path,
                hover_reason: None,
            }
        })
        .collect();
    let any_valid = reached.iter().any(Option::is_some);
    let reachable = raw.iter().flatten().any(Option::is_some);
    Ok(Plan {
        inflated,
        robot_radius_m: config.robot_radius_m,
        ignored,
        complete: any_valid && !reachable,
        placed: any_valid,
        frontiers,
        costs,
        robots: robots_out,
    })
}

/// Per robot, the frontier it holds ([`PlannerConfig::held`]): the one it can reach whose goal
/// (`goals`, map frame) lies nearest its held goal, within [`SAME_FRONTIER_M`].
fn held_frontiers(
    raw: &[Vec<Option<f64>>],
    goals: &[[f64; 2]],
    held: &[Option<[f64; 2]>],
) -> Vec<Option<usize>> {
    raw.iter()
        .enumerate()
        .map(|(r, row)| {
            let h = held.get(r).copied().flatten()?;
            goals
                .iter()
                .enumerate()
                .filter(|&(f, _)| row[f].is_some())
                .map(|(f, g)| (f, (g[0] - h[0]).hypot(g[1] - h[1])))
                .filter(|&(_, d)| d <= SAME_FRONTIER_M)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(f, _)| f)
        })
        .collect()
}

/// Robots × frontiers, what turning on the spot to face each path costs, metres
/// ([`PlannerConfig::turn_m_per_rad`]): 0 for a path that sets off within
/// [`PlannerConfig::turn_on_spot_rad`] of the robot's heading, for a robot whose heading is not
/// known, or where there is no path.
fn turns(
    reached: &[Option<Reached>],
    headings: &[Option<f64>],
    config: &PlannerConfig,
) -> Vec<Vec<f64>> {
    reached
        .iter()
        .enumerate()
        .map(|(r, row)| {
            let heading = headings.get(r).copied().flatten();
            row.as_ref().map_or_else(Vec::new, |row| {
                row.bearings
                    .iter()
                    .map(|b| match (heading, b) {
                        (Some(h), Some(b)) => {
                            let turn = wrap_angle(b - h).abs();
                            if turn > config.turn_on_spot_rad {
                                turn * config.turn_m_per_rad
                            } else {
                                0.0
                            }
                        }
                        _ => 0.0,
                    })
                    .collect()
            })
        })
        .collect()
}

/// Robots × frontiers, `cost` (metres, `None` where unreachable) after the thesis's rules, as
/// [`Plan::costs`] gives them: unreachable → the largest cost plus 1, a robot without a start
/// (no search: `reached[r]` is `None`) → the largest plus 10.
fn thesis_costs(cost: &[Vec<Option<f64>>], reached: &[Option<Reached>]) -> Vec<Vec<f64>> {
    let largest = cost.iter().flatten().flatten().copied().fold(0.0, f64::max);
    cost.iter()
        .zip(reached)
        .map(|(row, searched)| {
            row.iter()
                .map(|c| match searched {
                    None => largest + 10.0,
                    Some(_) => c.unwrap_or(largest + 1.0),
                })
                .collect()
        })
        .collect()
}

/// `cost` (robots × frontiers, `None` where unreachable) with each robot's turns (`turns`, as
/// [`turns`] gives them) added.
fn turning(mut cost: Vec<Vec<Option<f64>>>, turns: &[Vec<f64>]) -> Vec<Vec<Option<f64>>> {
    for (row, turns) in cost.iter_mut().zip(turns) {
        for (c, t) in row.iter_mut().zip(turns) {
            if let Some(c) = c {
                *c += t;
            }
        }
    }
    cost
}

/// `cost` (robots × frontiers, `None` where unreachable) with each robot's held frontier
/// `margin` cheaper (not below 0).
fn holding(
    mut cost: Vec<Vec<Option<f64>>>,
    held: &[Option<usize>],
    margin: f64,
) -> Vec<Vec<Option<f64>>> {
    for (row, f) in cost.iter_mut().zip(held) {
        if let Some(Some(c)) = f.and_then(|f| row.get_mut(f)) {
            *c = (*c - margin).max(0.0);
        }
    }
    cost
}

/// A collision-free route from `from` to `to` (map frame, metres) on `map` with obstacles grown
/// by `robot_radius_m`, keeping the `comfort` distances where it can ([`centred_path`]), both ends
/// moved to the nearest free cell, in straight segments. `None` when either end is off the map
/// or no route exists. The global planner for a drone flying home.
pub fn route(
    map: &Grid,
    from: [f64; 2],
    to: [f64; 2],
    robot_radius_m: f64,
    comfort: Comfort,
) -> Option<Vec<[f64; 2]>> {
    let inflated = inflate(map, robot_radius_m);
    let reach = (robot_radius_m / map.resolution()).ceil() as usize * 2 + 2;
    let a = nearest_free(&inflated, map.cell_of(from)?, reach)?;
    let b = nearest_free(&inflated, map.cell_of(to)?, reach)?;
    Some(
        centred_path(&inflated, a, b, comfort)?
            .into_iter()
            .map(|c| inflated.center_of(c))
            .collect(),
    )
}

/// What one robot's search found: its cost to every goal ([`UNREACHABLE`] where there is no
/// path) and, when asked for, the bearing its path to each goal sets off on (map frame,
/// radians; `None` where there is no path or the robot stands on its goal).
struct Reached {
    costs: Vec<u32>,
    bearings: Vec<Option<f64>>,
}

/// How far along a path its first straight leg is looked for ([`first_bearing`]), metres: about
/// what a drone flies before the path's first bend would show in its heading.
const SETTING_OFF_M: f64 = 2.0;

/// One Dijkstra per robot on `graph` (of the grid `grid`), spread over the available cores:
/// what each robot reaches of `goals`, `None` for a robot without an origin, with the bearings
/// its paths set off on where `bearings_for` says. A field is dropped as soon as it is read, so a
/// core holds one at a time.
fn search_all(
    graph: &Graph,
    grid: &Grid,
    origins: &[Option<CellXY>],
    goals: &[CellXY],
    bearings_for: &[bool],
) -> Vec<Option<Reached>> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(origins.len().max(1));
    let chunk = origins.len().div_ceil(threads).max(1);
    let robots: Vec<(Option<CellXY>, bool)> = origins
        .iter()
        .enumerate()
        .map(|(r, &o)| (o, bearings_for.get(r).copied().unwrap_or(false)))
        .collect();
    std::thread::scope(|scope| {
        let handles: Vec<_> = robots
            .chunks(chunk)
            .map(|part| {
                scope.spawn(move || {
                    part.iter()
                        .map(|&(o, bearings)| {
                            o.map(|c| {
                                let field = graph.dijkstra(c);
                                Reached {
                                    costs: goals.iter().map(|&g| field.cost(g)).collect(),
                                    bearings: goals
                                        .iter()
                                        .map(|&g| {
                                            bearings
                                                .then(|| field.path_to(g))
                                                .flatten()
                                                .and_then(|p| first_bearing(grid, &p))
                                        })
                                        .collect(),
                                }
                            })
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    })
}

/// The bearing a path of cells on `grid` sets off on (map frame, radians): from its first cell
/// to the farthest of its next [`SETTING_OFF_M`] in a straight line of sight, as the path's first
/// straight leg runs; `None` for a path of one cell.
fn first_bearing(grid: &Grid, path: &[CellXY]) -> Option<f64> {
    let cells = ((SETTING_OFF_M / grid.resolution()).ceil() as usize + 1).min(path.len());
    let legs = simplify(grid, &path[..cells]);
    let (&from, &to) = (legs.first()?, legs.get(1)?);
    let (a, b) = (grid.center_of(from), grid.center_of(to));
    Some((b[1] - a[1]).atan2(b[0] - a[0]))
}

fn hover(reason: &'static str) -> RobotPlan {
    RobotPlan {
        frontier: None,
        cost_m: None,
        goal: None,
        path: vec![],
        hover_reason: Some(reason),
    }
}

/// What robots at `seeds` would have mapped of `world` after exploring everything within
/// `radius_m` of travel: free cells reached through free space and the walls around them are
/// known, the rest unknown. For tests, benchmarks and demonstrations on real building maps.
pub fn explored_part(world: &Grid, seeds: &[[f64; 2]], radius_m: f64) -> Grid {
    let mut known = Grid::new(
        world.width(),
        world.height(),
        world.resolution(),
        world.origin(),
        Cell::Unknown,
    );
    let limit = (radius_m / world.resolution() * f64::from(crate::search::STRAIGHT)) as u32;
    for seed in seeds {
        let Some(cell) = world.cell_of(*seed) else {
            continue;
        };
        let f = dijkstra(world, cell);
        for i in 0..world.cells().len() {
            let c = world.xy(i);
            if f.cost(c) > limit {
                continue;
            }
            known.set(c, Cell::Free);
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let (nx, ny) = (c.0 as isize + dx, c.1 as isize + dy);
                    if nx >= 0 && ny >= 0 && world.get((nx as usize, ny as usize)) == Cell::Occupied
                    {
                        known.set((nx as usize, ny as usize), Cell::Occupied);
                    }
                }
            }
        }
    }
    known
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::tests::{data, grid, grid_with};
    use std::f64::consts::{FRAC_PI_2, PI};

    fn toy() -> Grid {
        // Two rooms, each with an opening into unknown space.
        grid_with(
            &[
                "############################",
                "#..........#...............?",
                "#..........#...............?",
                "#..........................?",
                "#..........#...............?",
                "?..........#...............#",
                "?..........#...............#",
                "?..........#...............#",
                "############################",
            ],
            0.25,
        )
    }

    /// A corridor 7.5 × 1 m open at both ends.
    fn corridor() -> Grid {
        grid_with(
            &[
                "##############################",
                "?............................?",
                "?............................?",
                "?............................?",
                "?............................?",
                "##############################",
            ],
            0.25,
        )
    }

    fn toy_config() -> PlannerConfig {
        PlannerConfig {
            robot_radius_m: 0.2,
            min_frontier_cells: 2,
            // The toy maps' rooms are smaller than a pocket.
            max_pocket_m2: 0.0,
            ..Default::default()
        }
    }

    #[test]
    fn two_robots_in_a_room_go_to_two_regions_not_to_two_pieces_of_one() {
        // The west room's openings at x ≈ 0.5 and 1.2 m are one region; the one at 3.6 m another.
        let g = crate::frontier::tests::two_rooms_with_openings();
        let robots = [Some([0.5, 0.5]), Some([1.2, 0.5])];
        let goal_x = |config: &PlannerConfig| -> Vec<f64> {
            let p = plan(&g, &robots, config).unwrap();
            p.robots.iter().map(|r| r.goal.unwrap()[0]).collect()
        };
        let config = PlannerConfig {
            robot_radius_m: 0.2,
            min_frontier_cells: 2,
            region_radius_m: 2.5,
            ..Default::default()
        };
        // Least total path length alone: each to the opening above it.
        let near = goal_x(&PlannerConfig {
            region_radius_m: 0.0,
            ..config.clone()
        });
        assert!(near[0] < 1.0 && (1.0..2.0).contains(&near[1]), "{near:?}");
        // Spread over regions: the robot nearer the far opening takes it.
        let spread = goal_x(&config);
        assert!(spread[0] < 2.0 && spread[1] > 3.0, "{spread:?}");
    }

    /// A hall 5.8 × 2.4 m open to the west, and to the north an unknown room behind a door
    /// 0.8 m wide (x 4.0–4.8 m, y 2.5–2.6 m; closed to a robot radius of 0.45 m, open to one of
    /// 0.25 m), of which the first `seen` rows (0.1 m each, x 3.6–5.2 m) are known free.
    fn hall_and_room(seen: usize) -> Grid {
        let wall = "#".repeat(60);
        let room = format!("#{}#", "?".repeat(58));
        let free = format!("{}{}{}", "#".repeat(36), ".".repeat(16), "#".repeat(8));
        let door = format!("{}{}{}", "#".repeat(40), ".".repeat(8), "#".repeat(12));
        let hall = format!("?{}#", ".".repeat(58));
        let rows: Vec<&str> = [wall.as_str()]
            .into_iter()
            .chain(std::iter::repeat_n(room.as_str(), 13 - seen))
            .chain(std::iter::repeat_n(free.as_str(), seen))
            .chain([door.as_str()])
            .chain([hall.as_str(); 24])
            .chain([wall.as_str()])
            .collect();
        grid_with(&rows, 0.1)
    }

    /// Where `path` crosses the row of [`hall_and_room`]'s door (y = 2.55 m), or None if it
    /// does not.
    fn through_door(path: &[[f64; 2]]) -> Option<f64> {
        path.windows(2).find_map(|w| {
            let ([ax, ay], [bx, by]) = (w[0], w[1]);
            ((ay - 2.55) * (by - 2.55) <= 0.0 && ay != by)
                .then(|| ax + (bx - ax) * (2.55 - ay) / (by - ay))
        })
    }

    #[test]
    fn a_robot_left_without_a_frontier_gets_one_behind_a_door_only_a_thinner_radius_passes() {
        let g = hall_and_room(0);
        let robots = [Some([0.8, 1.5]), Some([4.4, 1.5])];
        let radius = |robot_radius_m| PlannerConfig {
            robot_radius_m,
            min_frontier_cells: 2,
            ..Default::default()
        };
        let (wide, thin) = (radius(0.45), radius(0.25));
        // The wide radius alone: one frontier (the hall's west end), robot 0's; robot 1 has none.
        let p = plan_first_open(&g, &robots, std::slice::from_ref(&wide))
            .unwrap()
            .unwrap();
        assert_eq!(p.frontiers.len(), 1);
        assert!(p.robots[0].goal.unwrap()[0] < 0.5, "{:?}", p.robots[0]);
        assert_eq!(p.robots[1].frontier, None);
        // With the thin radius after it, robot 1 goes through the door.
        let p = plan_first_open(&g, &robots, &[wide, thin])
            .unwrap()
            .unwrap();
        assert!(p.robots[0].goal.unwrap()[0] < 0.5, "{:?}", p.robots[0]);
        let r = &p.robots[1];
        let goal = r.goal.unwrap();
        assert!(
            (4.0..4.8).contains(&goal[0]) && (2.2..2.8).contains(&goal[1]),
            "{goal:?}"
        );
        assert_eq!(r.frontier, Some(1));
        assert_eq!(p.frontiers.len(), 2);
        assert!(p.costs.iter().all(|row| row.len() == 2));
        assert!(r.cost_m.unwrap() > 0.5 && r.path.len() >= 2, "{r:?}");
    }

    #[test]
    fn a_path_lent_by_a_thinner_radius_goes_through_the_middle_of_the_door_not_along_a_jamb() {
        // The room's first 0.6 m seen free; robot 1 comes at the door (x 4.0–4.8 m, y 2.5–2.6 m)
        // from the south-west, so the shortest path would round the west jamb.
        let g = hall_and_room(6);
        let radius = |robot_radius_m| PlannerConfig {
            robot_radius_m,
            min_frontier_cells: 2,
            // Paths end at the frontier's goal, in the room (not where the camera has most room).
            look_around_room_m: 0.0,
            ..Default::default()
        };
        // Lent to robot 1 by the thin radius after the wide one: through the door's middle
        // (0.4 m from either jamb), to the cell.
        let robots = [Some([0.8, 1.5]), Some([1.6, 0.6])];
        let p = plan_first_open(&g, &robots, &[radius(0.45), radius(0.25)])
            .unwrap()
            .unwrap();
        let x = through_door(&p.robots[1].path).unwrap();
        assert!((x - 4.4).abs() < 0.06, "{x} in {:?}", p.robots[1].path);
        // The thin radius alone keeps nothing more: it rounds the west jamb 0.3 m off (the
        // 0.25 m inflation, to the cell).
        let p = plan_first_open(&g, &robots, &[radius(0.25)])
            .unwrap()
            .unwrap();
        let r = p.robots.iter().find(|r| r.goal.is_some_and(|g| g[1] > 2.0));
        let r = r.unwrap_or_else(|| panic!("no robot goes through the door: {:?}", p.robots));
        let x = through_door(&r.path).unwrap();
        assert!(x < 4.32, "{x} in {:?}", r.path);
    }

    #[test]
    fn a_path_planned_at_the_thin_radius_keeps_the_wide_ones_distance_through_the_door() {
        // The hall closed to the west: the room behind the door (x 4.0–4.8 m) is all there is
        // left, and only the thin radius passes the door. The robot comes at it from the
        // south-west.
        let mut g = hall_and_room(6);
        for y in 0..g.height() {
            g.set((0, y), Cell::Occupied);
        }
        let radii = [0.45, 0.25];
        let config = |robot_radius_m: f64, comfort_m: f64| PlannerConfig {
            robot_radius_m,
            comfort_m,
            min_frontier_cells: 2,
            look_around_room_m: 0.0,
            ..Default::default()
        };
        assert_eq!(centring_comfort(true, &radii, 0.45), 0.0);
        assert_eq!(centring_comfort(false, &radii, 0.25), 0.0);
        assert!((centring_comfort(true, &radii, 0.25) - 0.2).abs() < 1e-12);
        let robots = [Some([1.6, 0.6])];
        let crossing = |comfort: &dyn Fn(f64) -> f64| {
            let configs: Vec<PlannerConfig> =
                radii.iter().map(|&r| config(r, comfort(r))).collect();
            let p = plan_first_open(&g, &robots, &configs).unwrap().unwrap();
            let r = &p.robots[0];
            assert!(r.goal.is_some_and(|g| g[1] > 2.6), "into the room: {r:?}");
            through_door(&r.path).unwrap_or_else(|| panic!("not through the door: {r:?}"))
        };
        // Centred: through the door's middle (0.4 m from either jamb), to the cell.
        let x = crossing(&|r| centring_comfort(true, &radii, r));
        assert!((x - 4.4).abs() < 0.06, "{x}");
        // Shortest: round the west jamb at the 0.25 m inflation.
        let x = crossing(&|_| 0.0);
        assert!(x < 4.32, "{x}");
    }

    #[test]
    fn each_robot_goes_to_its_near_frontier() {
        let g = toy();
        let cfg = toy_config();
        // Robot 0 in the left room, robot 1 in the right room, both away from where they will
        // look around from (at (1.0, 1.0) robot 0 would already be there: a path of one point).
        let p = plan(&g, &[Some([2.5, 1.0]), Some([6.0, 1.0])], &cfg).unwrap();
        assert_eq!(p.frontiers.len(), 2);
        assert!(!p.complete);
        let target = |r: usize| p.frontiers[p.robots[r].frontier.unwrap()].centroid;
        assert!(
            target(0)[0] < 1.0,
            "left robot → left opening: {:?}",
            target(0)
        );
        assert!(
            target(1)[0] > 6.0,
            "right robot → right opening: {:?}",
            target(1)
        );
        for r in &p.robots {
            let first = r.path.first().unwrap();
            let last = r.path.last().unwrap();
            assert!(r.cost_m.unwrap() > 0.0 && first != last);
            // Every straight segment stays in free space of the inflated map.
            for w in r.path.windows(2) {
                let (a, b) = (
                    p.inflated.cell_of(w[0]).unwrap(),
                    p.inflated.cell_of(w[1]).unwrap(),
                );
                assert!(crate::search::line_of_sight(&p.inflated, a, b));
            }
        }
        // Greedy gives the same here (the rooms are separate).
        let g2 = plan(
            &g,
            &[Some([2.5, 1.0]), Some([6.0, 1.0])],
            &PlannerConfig {
                strategy: Strategy::Greedy,
                ..cfg.clone()
            },
        )
        .unwrap();
        assert_eq!(
            g2.robots.iter().map(|r| r.frontier).collect::<Vec<_>>(),
            p.robots.iter().map(|r| r.frontier).collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_robot_looks_around_from_where_its_camera_has_room_not_from_the_frontiers_edge() {
        let g = toy();
        let cfg = toy_config();
        let p = plan(&g, &[Some([6.0, 1.0])], &cfg).unwrap();
        let r = &p.robots[0];
        let f = &p.frontiers[r.frontier.unwrap()];
        // The goal given up if the frontier stays is the frontier's own, on its edge...
        assert_eq!(r.goal, Some(p.inflated.center_of(f.goal)));
        assert!(crate::vantage::tests::room(&g, f.goal) < 0.2);
        // ... but the path ends where the camera (blind nearer than 0.4 m) sees every side.
        let end = g.cell_of(*r.path.last().unwrap()).unwrap();
        let room = crate::vantage::tests::room(&g, end);
        assert!(room >= cfg.look_around_room_m, "{end:?}: {room} m of room");
        let [gx, gy] = r.goal.unwrap();
        let [ex, ey] = *r.path.last().unwrap();
        assert!((gx - ex).hypot(gy - ey) <= cfg.look_around_shift_m + 1e-9);
    }

    #[test]
    fn a_room_seen_through_a_door_too_narrow_to_fly_is_looked_into_from_the_door() {
        let g = crate::vantage::tests::doorway_seen_at_a_slant();
        let robot = [Some([1.65, 0.55])];
        let cfg = PlannerConfig {
            look_around_room_m: 0.0,
            ..toy_config()
        };
        // Without viewpoints the strip's frontier is out of reach: "complete".
        let blind = plan(
            &g,
            &robot,
            &PlannerConfig {
                view_range_m: 0.0,
                ..cfg.clone()
            },
        )
        .unwrap();
        assert!(blind.complete && !blind.frontiers.is_empty());
        // With them the robot flies to the door's side and looks in.
        let p = plan(&g, &robot, &cfg).unwrap();
        assert!(!p.complete);
        let r = &p.robots[0];
        let goal = r.goal.expect("a goal");
        assert!(goal[0] > 0.85, "{goal:?} is in the east room");
        assert_eq!(r.path.last(), Some(&goal));
        let f = &p.frontiers[r.frontier.unwrap()];
        assert!(f.centroid[0] < 0.8, "{:?}", f.centroid);
        assert!(crate::search::line_of_sight(
            &g,
            f.goal,
            g.cell_of(f.centroid).unwrap()
        ));
    }

    #[test]
    fn a_door_a_thinner_margin_passes_is_flown_through_not_looked_through() {
        let g = crate::vantage::tests::doorway_seen_at_a_slant();
        let robot = [Some([1.65, 0.55])];
        let radius = |r: f64| PlannerConfig {
            robot_radius_m: r,
            look_around_room_m: 0.0,
            ..toy_config()
        };
        // 0.2 m shuts the 0.4 m door, 0.1 m does not: the robot goes in.
        let p = plan_first_open(&g, &robot, &[radius(0.2), radius(0.1)])
            .unwrap()
            .expect("a plan");
        let goal = p.robots[0].goal.expect("a goal");
        assert!(goal[0] < 0.8, "{goal:?} is in the west room");
        // Shut at every margin, the strip's frontier is seen but out of reach: no last resort
        // (those are for when no frontier is seen at all), nothing to fly to.
        let p = plan_first_open(&g, &robot, &[radius(0.3), radius(0.2)])
            .unwrap()
            .expect("a plan");
        assert!(p.complete && !p.frontiers.is_empty());
        assert_eq!(p.robots[0].goal, None);
    }

    #[test]
    fn a_room_glimpsed_past_a_doors_jambs_still_has_its_frontier() {
        // The map a one-drone mission made of HouseExpo's room 0000 (ground-truth poses) when it
        // "completed" with the west half unseen: past the door (x ≈ 5.1 m, y 3.7–4.4 m) it saw
        // a patch of the west room, all within the robot's radius of the jambs.
        let map = Grid::load(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("testdata/house_door_at_a_slant.yaml"),
        )
        .expect("the fixture");
        let robot = [Some([7.5, 4.5])];
        let cfg = |frontier_margin_m: f64| PlannerConfig {
            robot_radius_m: 0.25,
            frontier_margin_m,
            ..PlannerConfig::default()
        };
        // Found on the inflated map, as before: nothing left.
        let before = plan(&map, &robot, &cfg(0.25)).unwrap();
        assert!(before.complete && before.frontiers.is_empty());
        // On the map grown by the thin margin: a frontier at the door, and a path to it.
        let p = plan(&map, &robot, &cfg(0.1)).unwrap();
        assert!(!p.complete);
        let goal = p.robots[0].goal.expect("a goal");
        assert!(
            (4.8..5.5).contains(&goal[0]) && (3.6..4.5).contains(&goal[1]),
            "{goal:?} is not at the door"
        );
        assert!(!p.robots[0].path.is_empty());
        // As the runtime plans: the margins in turn, the thin frontier margin as a last resort.
        let radii = |map: &Grid| {
            let configs: Vec<PlannerConfig> = [0.45, 0.35, 0.25]
                .iter()
                .map(|&robot_radius_m| PlannerConfig {
                    robot_radius_m,
                    ..PlannerConfig::default()
                })
                .collect();
            plan_first_open(map, &robot, &configs)
                .unwrap()
                .expect("a plan")
        };
        let p = radii(&map);
        let goal = p.robots[0].goal.expect("a goal");
        assert!((4.8..5.5).contains(&goal[0]), "{goal:?} is not at the door");
        // A frontier the inflated map shows (an unseen patch of the hall) goes first: the last
        // resort is not even looked for.
        let mut open = map.clone();
        for y in 40..50 {
            for x in 60..70 {
                open.set((x, y), crate::grid::Cell::Unknown);
            }
        }
        let p = radii(&open);
        assert!(
            p.frontiers
                .iter()
                .all(|f| p.inflated.center_of(f.goal)[0] > 5.5),
            "{:?}",
            p.frontiers
        );
        assert!(!p.complete);
    }

    #[test]
    fn invalid_pose_hovers_and_costs_largest_plus_ten() {
        let g = toy();
        let cfg = toy_config();
        let p = plan(&g, &[None, Some([6.0, 1.0])], &cfg).unwrap();
        assert_eq!(p.robots[0].hover_reason, Some("pose invalid"));
        let largest = p.costs[1].iter().copied().fold(0.0, f64::max);
        assert!(
            p.costs[0]
                .iter()
                .all(|&c| (c - (largest + 10.0)).abs() < 1e-9)
        );
        assert!(p.robots[1].frontier.is_some());
    }

    #[test]
    fn two_robots_in_the_middle_of_an_open_hall_fly_to_two_sides_of_it() {
        // The hall's frontier is one ring around them; before it was cut into pieces both were
        // sent to its centroid, where they already were.
        let hall = crate::frontier::tests::open_hall(2.5);
        let p = plan(&hall, &[Some([2.8, 3.0]), Some([3.2, 3.0])], &toy_config()).unwrap();
        let goals: Vec<[f64; 2]> = p
            .robots
            .iter()
            .map(|r| p.frontiers[r.frontier.expect("a frontier for each robot")].centroid)
            .collect();
        // Pieces up to 4 m wide of a 5-m ring: arcs whose centroids lie 1.6 m or more out.
        for g in &goals {
            assert!((g[0] - 3.0).hypot(g[1] - 3.0) > 1.5, "{goals:?}");
        }
        assert!(
            (goals[0][0] - goals[1][0]).hypot(goals[0][1] - goals[1][1]) > 1.0,
            "{goals:?}"
        );
    }

    #[test]
    fn more_robots_than_frontiers_some_hover() {
        let g = toy();
        let cfg = toy_config();
        let p = plan(
            &g,
            &[Some([1.0, 1.0]), Some([2.0, 1.0]), Some([6.0, 1.0])],
            &cfg,
        )
        .unwrap();
        let assigned: Vec<_> = p.robots.iter().filter_map(|r| r.frontier).collect();
        assert_eq!(assigned.len(), 2);
        assert_eq!(
            p.robots.iter().filter(|r| r.hover_reason.is_some()).count(),
            1
        );
    }

    #[test]
    fn robots_left_without_a_frontier_wait_behind_the_one_that_has_it_one_metre_apart() {
        // A corridor 7.5 × 1 m closed to the east: one frontier, at its west end.
        let mut rows = vec!["#".repeat(30)];
        rows.extend(std::iter::repeat_n(format!("?{}#", ".".repeat(28)), 4));
        rows.push("#".repeat(30));
        let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
        let g = grid_with(&rows, 0.25);
        let robots = [
            Some([1.5, 0.5]),
            Some([6.5, 0.5]),
            Some([5.5, 0.5]),
            Some([2.6, 0.5]),
        ];
        let config = toy_config();
        let p = plan_first_open(&g, &robots, std::slice::from_ref(&config))
            .unwrap()
            .unwrap();
        assert_eq!(p.frontiers.len(), 1);
        assert_eq!(p.robots[0].frontier, Some(0));
        let spot = *p.robots[0].path.last().unwrap();
        // Robot 3, nearest of the rest, would wait 2 m short of the spot robot 0 looks around
        // from: it is nearly there already, so it hovers where it is.
        let near = &p.robots[3];
        assert!(
            near.path.is_empty() && near.hover_reason.is_some(),
            "{near:?}"
        );
        // Robot 2 waits 2 m + 1 m short of it (robot 3 counts as ahead), robot 1 a metre further.
        for (r, back) in [(2, 3.0), (1, 4.0)] {
            let rp = &p.robots[r];
            assert_eq!((rp.frontier, rp.goal, rp.hover_reason), (None, None, None));
            let end = *rp.path.last().unwrap();
            assert!(
                (end[0] - (spot[0] + back)).abs() < 0.3 && (end[1] - spot[1]).abs() < 0.3,
                "robot {r} waits at {end:?}, the spot is {spot:?}"
            );
            assert!((rp.cost_m.unwrap() - path_length(&rp.path)).abs() < 1e-9);
        }
        // Off: the three hover.
        let off = PlannerConfig {
            stage_back_m: 0.0,
            ..config
        };
        let p = plan_first_open(&g, &robots, &[off]).unwrap().unwrap();
        assert!(
            p.robots[1..]
                .iter()
                .all(|r| r.path.is_empty() && r.hover_reason.is_some())
        );
    }

    #[test]
    fn a_path_cut_short_ends_that_far_back_along_it() {
        let path = [[0.0, 0.0], [3.0, 0.0], [3.0, 2.0]];
        assert_eq!(path_length(&path), 5.0);
        assert_eq!(
            cut_short(&path, 1.0),
            vec![[0.0, 0.0], [3.0, 0.0], [3.0, 1.0]]
        );
        assert_eq!(cut_short(&path, 3.5), vec![[0.0, 0.0], [1.5, 0.0]]);
        assert_eq!(cut_short(&path, 0.0), path.to_vec());
        assert_eq!(cut_short(&path, 9.0), vec![[0.0, 0.0]]);
        assert!(cut_short(&[], 1.0).is_empty());
    }

    #[test]
    fn a_frontier_behind_a_robot_costs_it_the_turn_to_face_its_path() {
        // The robot 3.05 m of path from the west end, 3.95 m from the east one.
        let corridor = corridor();
        let robot = [Some([3.3, 0.75])];
        let east = |heading: Option<f64>, turn_m_per_rad: f64| -> bool {
            let p = plan(
                &corridor,
                &robot,
                &PlannerConfig {
                    headings: vec![heading],
                    turn_m_per_rad,
                    ..toy_config()
                },
            )
            .unwrap();
            p.robots[0].goal.expect("a goal")[0] > 3.75
        };
        // Paths alone: the nearer, west end, whichever way it faces.
        assert!(!east(Some(0.0), 0.0));
        // Facing east, the west end costs a half turn as well (0.7 m/rad: 2.2 m): east is nearer.
        assert!(east(Some(0.0), 0.7));
        // Facing 60° off east, the east end's path is flown while turning: still east.
        assert!(east(Some(60f64.to_radians()), 0.7));
        // Facing west, or a heading not known: west.
        assert!(!east(Some(PI), 0.7));
        assert!(!east(None, 0.7));
        // What the plan reports as costs stays metres of path.
        let p = plan(
            &corridor,
            &robot,
            &PlannerConfig {
                headings: vec![Some(0.0)],
                turn_m_per_rad: 0.7,
                ..toy_config()
            },
        )
        .unwrap();
        let cheapest = p.costs[0].iter().copied().fold(f64::INFINITY, f64::min);
        assert!((2.8..3.3).contains(&cheapest), "{:?}", p.costs);
    }

    #[test]
    fn a_path_sets_off_along_its_first_straight_leg() {
        // An L: from (1, 1) north up a corridor, then east. The first leg runs north; a path of
        // one cell sets off nowhere.
        let l = grid_with(
            &[
                "##########",
                "#........#",
                "#.########",
                "#.########",
                "#.########",
                "##########",
            ],
            0.25,
        );
        let field = dijkstra(&l, (1, 1));
        let path = field.path_to((8, 4)).expect("a path");
        let b = first_bearing(&l, &path).expect("a bearing");
        assert!((b - FRAC_PI_2).abs() < 1e-9, "{b}");
        assert_eq!(first_bearing(&l, &path[..1]), None);
    }

    #[test]
    fn a_robot_keeps_its_frontier_unless_another_is_cheaper_by_more_than_the_margin() {
        // Two robots side by side in the corridor's middle nearly tie.
        let corridor = corridor();
        let left = |p: &Plan| -> Vec<bool> {
            p.robots
                .iter()
                .map(|r| r.goal.expect("a goal for each robot")[0] < 3.75)
                .collect()
        };
        let side_by_side = [Some([3.65, 0.75]), Some([3.85, 0.75])];
        let free = plan(&corridor, &side_by_side, &toy_config()).unwrap();
        assert_eq!(
            left(&free),
            [true, false],
            "the one a little left goes left"
        );
        // Each holding the other's end (as the map grew, half a metre off its goal now): to
        // swap would save 0.4 m, less than the margins, so they keep them.
        let goal = |r: usize| free.robots[r].goal.unwrap();
        let off = |g: [f64; 2]| Some([g[0], g[1] + 0.5]);
        let holding = PlannerConfig {
            held: vec![off(goal(1)), off(goal(0))],
            hold_margin_m: 1.0,
            ..toy_config()
        };
        let kept = plan(&corridor, &side_by_side, &holding).unwrap();
        assert_eq!(left(&kept), [false, true]);
        // The held goals are only what the margin makes of them (nothing without one).
        let no_margin = PlannerConfig {
            hold_margin_m: 0.0,
            ..holding.clone()
        };
        assert_eq!(
            left(&plan(&corridor, &side_by_side, &no_margin).unwrap()),
            [true, false]
        );
        // Nor does a goal held too far from any frontier's hold one.
        let far = PlannerConfig {
            held: vec![
                Some([goal(1)[0] - 1.5, 0.75]),
                Some([goal(0)[0] + 1.5, 0.75]),
            ],
            ..holding.clone()
        };
        assert_eq!(
            left(&plan(&corridor, &side_by_side, &far).unwrap()),
            [true, false]
        );
        // Two metres apart, to swap saves 4 m, more than both margins: they swap. The costs
        // reported are the paths', not what the margin made of them.
        let apart = [Some([2.75, 0.75]), Some([4.75, 0.75])];
        let swapped = plan(&corridor, &apart, &holding).unwrap();
        assert_eq!(left(&swapped), [true, false]);
        let unheld = plan(&corridor, &apart, &toy_config()).unwrap();
        assert_eq!(swapped.costs, unheld.costs);
        // The greedy baseline holds its goals too.
        let greedy = PlannerConfig {
            strategy: Strategy::Greedy,
            ..holding.clone()
        };
        assert_eq!(
            left(&plan(&corridor, &side_by_side, &greedy).unwrap()),
            [false, true]
        );
    }

    #[test]
    fn explored_everything_is_complete_and_outside_is_an_error() {
        let g = grid(&["#####", "#...#", "#####"]);
        let p = plan(
            &g,
            &[Some([0.25, 0.15])],
            &PlannerConfig {
                robot_radius_m: 0.0,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(p.complete);
        assert_eq!(p.robots[0].hover_reason, Some("no frontier"));
        let e = plan(&g, &[Some([9.0, 0.1])], &PlannerConfig::default()).unwrap_err();
        assert!(e.to_string().contains("outside the map"), "{e}");
    }

    #[test]
    fn a_robot_in_a_passage_only_a_thinner_radius_fits_is_planned_with_that_radius() {
        // A room explored to its walls and a dead-end passage 0.7 m wide and 4 m long off it,
        // 0.1 m cells; the robot 2 m down the passage. The widest radius has no free cell within
        // reach of it, so it says nothing about what is left; the thinner one does: nothing.
        let room = format!("#{}#", ".".repeat(30));
        let passage = format!("#{}{}", ".".repeat(7), "#".repeat(24));
        let wall = "#".repeat(32);
        let rows: Vec<&str> = [wall.as_str()]
            .into_iter()
            .chain([passage.as_str(); 40])
            .chain([room.as_str(); 20])
            .chain([wall.as_str()])
            .collect();
        let g = grid_with(&rows, 0.1);
        let robot = [Some([0.45, 4.1])];
        let radius = |robot_radius_m| PlannerConfig {
            robot_radius_m,
            ..Default::default()
        };
        let wide = plan(&g, &robot, &radius(0.45)).unwrap();
        assert_eq!(
            wide.robots[0].hover_reason,
            Some("no free cell near the robot")
        );
        assert!(!wide.complete);
        let p = plan_first_open(&g, &robot, &[radius(0.45), radius(0.25)])
            .unwrap()
            .unwrap();
        assert_eq!(p.robot_radius_m, 0.25);
        assert!(p.complete);
        // With somewhere to go, the thinner radius takes the robot there.
        let door = format!("#{}?", ".".repeat(30));
        let mut open = rows.clone();
        open[44..54].fill(&door);
        let g = grid_with(&open, 0.1);
        let p = plan_first_open(&g, &robot, &[radius(0.45), radius(0.25)])
            .unwrap()
            .unwrap();
        assert!(!p.complete);
        assert!(p.robots[0].goal.is_some(), "{:?}", p.robots[0]);
    }

    #[test]
    fn plans_on_real_buildings() {
        for (file, seeds) in [
            ("willow-full.yaml", vec![[12.0, 30.0], [20.0, 30.0]]),
            ("building_31.yaml", vec![[0.0, 0.0], [5.0, 2.0]]),
        ] {
            let world = Grid::load(data(file)).unwrap();
            let seeds: Vec<[f64; 2]> = seeds
                .into_iter()
                .map(|s| {
                    let c = nearest_free(&world, world.cell_of(s).unwrap(), 50).unwrap();
                    world.center_of(c)
                })
                .collect();
            let known = explored_part(&world, &seeds, 8.0);
            let robots: Vec<Option<[f64; 2]>> = seeds.iter().copied().map(Some).collect();
            let p = plan(&known, &robots, &PlannerConfig::default()).unwrap();
            assert!(
                !p.frontiers.is_empty(),
                "{file}: frontiers expected at the edge of what is explored"
            );
            assert!(!p.complete);
            for (r, rp) in p.robots.iter().enumerate() {
                assert!(
                    rp.frontier.is_some(),
                    "{file}: robot {r} hovers: {:?}",
                    rp.hover_reason
                );
                for w in rp.path.windows(2) {
                    let (a, b) = (
                        p.inflated.cell_of(w[0]).unwrap(),
                        p.inflated.cell_of(w[1]).unwrap(),
                    );
                    assert!(
                        crate::search::line_of_sight(&p.inflated, a, b),
                        "{file}: path through an obstacle"
                    );
                }
            }
            // The optimal total is no worse than greedy's.
            let a: Vec<Option<usize>> = p.robots.iter().map(|r| r.frontier).collect();
            let g = plan(
                &known,
                &robots,
                &PlannerConfig {
                    strategy: Strategy::Greedy,
                    ..Default::default()
                },
            )
            .unwrap();
            let b: Vec<Option<usize>> = g.robots.iter().map(|r| r.frontier).collect();
            let cost = |x: &[Option<usize>]| crate::assignment::total(&p.costs, x);
            assert!(
                cost(&a) <= cost(&b) + 1e-9,
                "{file}: Hungarian {} vs greedy {}",
                cost(&a),
                cost(&b)
            );
        }
    }

    #[test]
    fn blacklisted_frontiers_are_ignored() {
        let map = toy();
        let robots = [Some([1.0, 1.0])];
        let all = plan(&map, &robots, &toy_config()).unwrap();
        assert!(all.frontiers.len() >= 2, "{:?}", all.frontiers);
        let first = all.inflated.center_of(all.frontiers[0].goal);
        let config = PlannerConfig {
            blacklist: vec![first],
            ..toy_config()
        };
        let p = plan(&map, &robots, &config).unwrap();
        assert_eq!(p.frontiers.len(), all.frontiers.len() - 1);
        assert!(p.frontiers.iter().all(|f| f.goal != all.frontiers[0].goal));
        assert_eq!(p.ignored, vec![first], "the plan says what it left out");
        assert!(all.ignored.is_empty());
    }

    #[test]
    fn an_unreachable_frontier_never_ties_with_the_farthest_reachable_one() {
        // Robot in the left room; the left room's frontier is reachable; a second frontier is
        // walled off. Unreachable used to cost exactly the largest reachable cost: with one robot
        // and two frontiers that tie went to the first (the unreachable one) and the robot hovered.
        let map = grid_with(
            &[
                "##############",
                "#......#.....?",
                "#......#.....?",
                "#......#######",
                "?.........#..#",
                "?.........#..#",
                "##############",
            ],
            0.25,
        );
        let p = plan(&map, &[Some([0.6, 0.6])], &toy_config()).unwrap();
        assert_eq!(p.frontiers.len(), 2, "{:?}", p.frontiers);
        let r = &p.robots[0];
        assert!(r.frontier.is_some() && !r.path.is_empty(), "{r:?}");
        let reachable = r.frontier.unwrap();
        let other = 1 - reachable;
        assert!(p.costs[0][other] > p.costs[0][reachable], "{:?}", p.costs);
        assert!(!p.complete);
        // Nor does the turn to face a reachable frontier's path make the walled-off one the
        // cheaper: facing east, the west frontier (0.5 m away) weighs 0.5 m + a half turn
        // (2.2 m), more than the largest reachable cost plus 1. The unreachable frontier's cost
        // counted from the paths alone left a drone of a three-drone mission hovering without
        // a goal for 330 s until the timeout, its plan never complete.
        let facing_east = PlannerConfig {
            headings: vec![Some(0.0)],
            turn_m_per_rad: 0.7,
            ..toy_config()
        };
        let p = plan(&map, &[Some([0.6, 0.6])], &facing_east).unwrap();
        let r = &p.robots[0];
        assert_eq!(r.frontier, Some(reachable), "{r:?}");
        assert!(!r.path.is_empty(), "{r:?}");
    }

    #[test]
    fn a_route_keeps_from_the_unknown_when_asked() {
        // A hall 8 × 3 m on a map that knows nothing round it, whose north 0.95 m is not seen
        // yet either (a wall may begin at its edge, y = 2.25 m), crossed just below it.
        let mut map = Grid::new(170, 70, 0.05, [0.0, 0.0], Cell::Unknown);
        for y in 5..65 {
            for x in 5..165 {
                if x == 5 || y == 5 || x == 164 || y == 64 {
                    map.set((x, y), Cell::Occupied);
                } else if y < 45 {
                    map.set((x, y), Cell::Free);
                }
            }
        }
        let (from, to) = ([0.8, 2.15], [7.5, 2.15]);
        let route_with = |comfort| route(&map, from, to, 0.45, comfort).expect("a route");
        let lowest = |path: &[[f64; 2]]| path.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
        let plain = route_with(Comfort::default());
        assert_eq!(
            plain.len(),
            2,
            "the straight line along the unknown: {plain:?}"
        );
        let kept = route_with(Comfort {
            blocked_m: 0.0,
            unknown_m: 0.45,
        });
        assert!(
            lowest(&kept) < 2.25 - 0.35,
            "a route keeping from the unknown dips away from it: {kept:?}"
        );
        for (a, b) in [(plain[0], kept[0]), (plain[1], kept[kept.len() - 1])] {
            assert!((a[0] - b[0]).hypot(a[1] - b[1]) < 1e-9, "same ends");
        }
    }
}
