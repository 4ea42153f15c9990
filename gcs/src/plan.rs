//! `gcs plan`: one mission-planner step on a map file, for given robot positions; or one
//! decision of a recorded mission made again, to see why each drone got the goal it got.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use gcs::mission_log;
use nav::mission::plan_first_open;
use nav::{Grid, PlannerConfig, Strategy, explored_part, plan};
use serde_json::json;

/// Assignment strategy on the command line.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum StrategyArg {
    /// Least total path length (Hungarian algorithm).
    Hungarian,
    /// Cheapest pair first (explore_lite-style baseline).
    Greedy,
}

/// Arguments of `gcs plan`.
#[derive(Args, Debug)]
pub struct PlanArgs {
    /// The map: a ROS map_server YAML (with its PGM or PNG beside it).
    #[arg(long, required_unless_present = "log", conflicts_with = "log")]
    map: Option<PathBuf>,
    /// Or a mission log (`mission.mcap` of `gcs explore`): make its planner decision at `--at`
    /// again, on the map it was made on, from where its drones were, skipping the goals given
    /// up by then, with the mission's planner settings (the other planner options do not apply).
    #[arg(long, value_name = "MISSION.mcap", requires = "at")]
    log: Option<PathBuf>,
    /// With `--log`: the first decision at or after this mission time, seconds.
    #[arg(long, value_name = "SECONDS", requires = "log")]
    at: Option<f64>,
    /// A robot's position X,Y in metres (map frame); repeat for each robot; `none` for a robot
    /// whose pose is invalid. With `--log`, instead of the drones' recorded positions.
    #[arg(long = "robot", value_name = "X,Y", required_unless_present = "log")]
    robots: Vec<String>,
    /// Obstacles are grown by this radius, metres.
    #[arg(long, default_value_t = 0.3)]
    robot_radius: f64,
    /// Frontiers with fewer cells are ignored.
    #[arg(long, default_value_t = 5)]
    min_frontier: usize,
    /// Assignment strategy.
    #[arg(long, value_enum, default_value = "hungarian")]
    strategy: StrategyArg,
    /// Frontiers within this distance of each other, in sight, are one region, and robots are
    /// spread one to a region first, metres; 0: off.
    #[arg(long, value_name = "METRES", default_value_t = PlannerConfig::default().region_radius_m)]
    region_radius: f64,
    /// A frontier whose unknown side is an enclosed pocket, walled at least as much as open, of at most
    /// this area is ignored, m²; 0: none is.
    #[arg(long, value_name = "M2", default_value_t = PlannerConfig::default().max_pocket_m2)]
    max_pocket: f64,
    /// Treat the map as the whole building and plan on what the robots would have explored within
    /// this many metres of travel from their positions (to try the planner on a complete map).
    #[arg(long, value_name = "METRES")]
    explored_radius: Option<f64>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Draw the map, frontiers, targets and paths to this PNG.
    #[arg(long, value_name = "OUT.png")]
    png: Option<PathBuf>,
}

/// A point for the text report, or what its absence means.
fn place(p: Option<[f64; 2]>, none: &str) -> String {
    p.map_or(none.into(), |p| format!("({:.2}, {:.2}) m", p[0], p[1]))
}

fn parse_robot(s: &str) -> anyhow::Result<Option<[f64; 2]>> {
    if s.eq_ignore_ascii_case("none") {
        return Ok(None);
    }
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| {
            format!("--robot {s:?}: expected X,Y in metres, e.g. 1.5,-2.0, or none")
        })?;
    match v[..] {
        [x, y] if x.is_finite() && y.is_finite() => Ok(Some([x, y])),
        _ => bail!("--robot {s:?}: expected two finite numbers X,Y, or none"),
    }
}

/// A recorded decision made again: what the mission did, to print beside the replanned one.
struct Recorded {
    decision: mission_log::Decision,
    /// The drones' recorded positions were replaced by `--robot`.
    moved: bool,
}

/// Runs the command.
pub fn run(args: &PlanArgs) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();
    let mut robots: Vec<Option<[f64; 2]>> = args
        .robots
        .iter()
        .map(|s| parse_robot(s))
        .collect::<Result<_, _>>()?;
    if !(args.robot_radius.is_finite() && args.robot_radius >= 0.0) {
        bail!("--robot-radius must be zero or more metres");
    }
    if !(args.region_radius.is_finite() && args.region_radius >= 0.0) {
        bail!("--region-radius must be zero (off) or more metres");
    }
    if !(args.max_pocket.is_finite() && args.max_pocket >= 0.0) {
        bail!("--max-pocket must be zero (off) or more square metres");
    }
    let (map, p, elapsed, recorded) = match (&args.map, &args.log, args.at) {
        (Some(_), _, Some(_)) => {
            bail!("--at picks a decision of a mission log: give it with --log, not with --map")
        }
        (Some(path), _, None) => {
            let mut map = Grid::load(path)?;
            if let Some(r) = args.explored_radius {
                if !(r.is_finite() && r > 0.0) {
                    bail!("--explored-radius must be more than zero metres");
                }
                let seeds: Vec<[f64; 2]> = robots.iter().flatten().copied().collect();
                map = explored_part(&map, &seeds, r);
            }
            let config = PlannerConfig {
                robot_radius_m: args.robot_radius,
                min_frontier_cells: args.min_frontier.max(1),
                region_radius_m: args.region_radius,
                max_pocket_m2: args.max_pocket,
                strategy: match args.strategy {
                    StrategyArg::Hungarian => Strategy::Hungarian,
                    StrategyArg::Greedy => Strategy::Greedy,
                },
                ..PlannerConfig::default()
            };
            let t = std::time::Instant::now();
            let p = plan(&map, &robots, &config)?;
            (map, p, t.elapsed().as_secs_f64(), None)
        }
        (None, Some(log), Some(at)) => {
            if !at.is_finite() {
                bail!("--at must be a mission time in seconds");
            }
            let bytes =
                std::fs::read(log).with_context(|| format!("cannot read {}", log.display()))?;
            let decision = mission_log::decision_at(&bytes, &log.display().to_string(), at)?;
            let moved = !robots.is_empty();
            let drones = decision.plan.goals.len();
            if moved && robots.len() != drones {
                bail!(
                    "the decision at {:.1} s planned for {drones} exploring drones: give --robot {drones} times, or not at all",
                    decision.plan.t
                );
            }
            if !moved {
                robots = decision.plan.goals.iter().map(|g| g.position).collect();
            }
            let configs = decision
                .plan
                .planner_configs(&crate::replay::planner_configs(&decision.setup));
            let t = std::time::Instant::now();
            let Some(p) = plan_first_open(&decision.grid, &robots, &configs)? else {
                bail!("{} names no planner radius to plan with", log.display());
            };
            let elapsed = t.elapsed().as_secs_f64();
            let map = decision.grid.clone();
            (map, p, elapsed, Some(Recorded { decision, moved }))
        }
        _ => bail!("give --map with --robot, or --log with --at"),
    };
    let total = p
        .robots
        .iter()
        .filter_map(|r| r.cost_m)
        .fold(0.0, |a, c| a + c);
    if args.json {
        let frontiers: Vec<_> = p
            .frontiers
            .iter()
            .map(|f| {
                let g = p.inflated.center_of(f.goal);
                json!({"x": g[0], "y": g[1], "size": f.cells, "centroid": {"x": f.centroid[0], "y": f.centroid[1]}})
            })
            .collect();
        let robots_json: Vec<_> = p
            .robots
            .iter()
            .enumerate()
            .map(|(id, r)| {
                let target = r.frontier.map(|f| {
                    let g = p.inflated.center_of(p.frontiers[f].goal);
                    json!({"x": g[0], "y": g[1]})
                });
                json!({
                    "id": id,
                    "position": robots[id].map(|p| json!({"x": p[0], "y": p[1]})),
                    "frontier": r.frontier,
                    "target": target,
                    "cost": r.cost_m,
                    "path": r.path,
                    "hover_reason": r.hover_reason,
                })
            })
            .collect();
        let mut out = json!({
            "frontiers": frontiers,
            "robots": robots_json,
            "cost_matrix": p.costs,
            "total_cost": total,
            "complete": p.complete,
            "planning_time_s": elapsed,
        });
        if let Some(r) = &recorded {
            let d = &r.decision;
            out["decision"] = json!({
                "t": d.plan.t,
                "map_t": d.grid_t,
                "given_up": d.plan.given_up.len(),
                "positions": if r.moved { "--robot" } else { "log" },
                "drones": d.plan.goals.iter().map(|g| json!({
                    "id": g.drone + 1,
                    "position": g.position.map(|p| json!({"x": p[0], "y": p[1]})),
                    "held": g.held.map(|p| json!({"x": p[0], "y": p[1]})),
                    "heading_deg": g.heading.map(f64::to_degrees),
                    "goal": g.goal.map(|p| json!({"x": p[0], "y": p[1]})),
                })).collect::<Vec<_>>(),
            });
        }
        writeln!(stdout, "{out}")?;
    } else {
        if let Some(r) = &recorded {
            let d = &r.decision;
            writeln!(
                stdout,
                "the decision at {:.1} s, on the map of {:.1} s, {} goals given up by then{}",
                d.plan.t,
                d.grid_t,
                d.plan.given_up.len(),
                if r.moved {
                    ", from the positions given"
                } else {
                    ""
                }
            )?;
            for (i, g) in d.plan.goals.iter().enumerate() {
                writeln!(
                    stdout,
                    "  robot {i} is drone {}: at {}{}, flying to {}, the mission gave it {}",
                    g.drone + 1,
                    place(g.position, "no position (pose invalid)"),
                    g.heading
                        .map_or(String::new(), |h| format!(" facing {:.0}°", h.to_degrees())),
                    place(g.held, "no goal"),
                    place(g.goal, "no goal")
                )?;
            }
        }
        writeln!(
            stdout,
            "{} frontiers ({} × {} cells of {} m), planned in {:.1} ms",
            p.frontiers.len(),
            map.width(),
            map.height(),
            map.resolution(),
            elapsed * 1e3
        )?;
        for (i, f) in p.frontiers.iter().enumerate().take(20) {
            let g = p.inflated.center_of(f.goal);
            writeln!(
                stdout,
                "  frontier {i:>3}: {:>5} cells, goal ({:7.2}, {:7.2}) m",
                f.cells, g[0], g[1]
            )?;
        }
        if p.frontiers.len() > 20 {
            writeln!(stdout, "  … {} more", p.frontiers.len() - 20)?;
        }
        if !p.frontiers.is_empty() && p.frontiers.len() <= 12 {
            writeln!(stdout, "cost matrix (m), robots × frontiers:")?;
            for (i, row) in p.costs.iter().enumerate() {
                let cells: Vec<String> = row.iter().map(|c| format!("{c:7.2}")).collect();
                writeln!(stdout, "  robot {i}: {}", cells.join(" "))?;
            }
        }
        for (i, r) in p.robots.iter().enumerate() {
            match (r.frontier, r.cost_m) {
                (Some(f), Some(c)) => {
                    let g = p.inflated.center_of(p.frontiers[f].goal);
                    writeln!(
                        stdout,
                        "robot {i} → frontier {f} at ({:.2}, {:.2}) m, path {c:.2} m, {} waypoints",
                        g[0],
                        g[1],
                        r.path.len()
                    )?;
                }
                _ => writeln!(
                    stdout,
                    "robot {i}: hover ({})",
                    r.hover_reason.unwrap_or("no target")
                )?,
            }
        }
        writeln!(
            stdout,
            "total path length {total:.2} m{}",
            if p.complete {
                "; exploration complete"
            } else {
                ""
            }
        )?;
    }
    if let Some(out) = &args.png {
        let img = nav::render::draw_plan(&map, &p, &robots, 1000);
        img.save(out)
            .with_context(|| format!("cannot write {}", out.display()))?;
        if !args.json {
            writeln!(stdout, "picture: {}", out.display())?;
        }
    }
    Ok(())
}
