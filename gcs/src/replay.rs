//! `gcs replay FILE.mcap`: reruns the SLAM on a recorded mission's sensor data (camera frames,
//! IMU heading, sonar height, the filter's poses as relocalisation hints), and the mission
//! planner at each of its recorded decisions on the replayed map, and reports how the result
//! differs from what the mission produced: its final map, the poses it flew on and the goals
//! the drones were given.
//!
//! A log cut short by a crash replays up to its last readable message. Colour was recorded as
//! JPEG, so the replay sees slightly different pixels than the live SLAM did, and its optimiser
//! runs in step with the frames (deterministic) rather than in the background: small
//! differences are expected, large ones point at a problem worth a look.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use nav::grid::{Cell, Grid};
use slam::system::{RobotSetup, Slam, SlamConfig};
use slam::trajectory::Stamped;

use gcs::mission_log::{self, RecordedPlan};
use gcs::outputs;
use gcs::record::DroneState;
use gcs::record::Setup;
use gcs::runtime::RuntimeConfig;
use gcs::runtime::perception::{SensorSample, sensors_at, slam_frame};
use nav::mission::{PlannerConfig, Strategy, centring_comfort};

/// Arguments of `gcs replay`.
#[derive(Args, Debug, Clone)]
pub struct ReplayArgs {
    /// The mission log (`mission.mcap` of `gcs explore`).
    pub log: PathBuf,
    /// Where to write the replayed map, trajectories and report.
    #[arg(long, default_value = "replay-out")]
    pub out: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Map on the simulator's true camera poses recorded in the log (as `gcs explore --poses
    /// truth` did) instead of tracking the cameras.
    #[arg(long)]
    pub truth_poses: bool,
}

/// How the replay compares with the mission, as written to `replay.json`.
#[derive(Debug, serde::Serialize)]
pub struct ReplayReport {
    /// Messages read from the log.
    pub messages: usize,
    /// Whether the log ended early (a crashed writer): replayed up to its last whole message.
    pub truncated: bool,
    /// Camera frames replayed.
    pub frames: usize,
    /// Keyframes and loop closures of the replayed graph.
    pub keyframes: usize,
    /// Loop closures in the replayed graph.
    pub loop_closures: usize,
    /// The replayed map against the mission's last recorded map.
    pub map: Option<MapComparison>,
    /// The planner's decisions made again on the replayed map (`None`: the log records none
    /// that can be made again, as logs before the planner's inputs were recorded).
    pub navigation: Option<NavigationComparison>,
    /// Per drone: the replayed body trajectory against the poses the mission flew on.
    pub drones: Vec<DroneComparison>,
}

/// The mission planner run again at each recorded decision — on the replayed map as it stood
/// then, from the drones' recorded positions, skipping the goals given up by then — against
/// the goals the mission gave.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NavigationComparison {
    /// Decisions made again.
    pub decisions: usize,
    /// Drones' goals compared (one per exploring drone per decision).
    pub goals: usize,
    /// Fraction of those the replay gave the same goal (within [`SAME_GOAL_M`]; no goal in
    /// both counts as the same).
    pub same_goal: f64,
    /// Median distance between the mission's goal and the replay's where both gave one,
    /// metres.
    pub median_goal_shift_m: Option<f64>,
}

/// Two goals this close are the same frontier (the frontier cutting's pieces are 4 m wide).
pub const SAME_GOAL_M: f64 = 0.5;

/// Tallies replayed decisions against recorded ones.
#[derive(Debug, Default)]
struct NavigationTally {
    decisions: usize,
    goals: usize,
    same: usize,
    shifts: Vec<f64>,
}

impl NavigationTally {
    /// Makes `recorded` again on `grid` with the mission's planner settings.
    fn replan(&mut self, grid: Option<&Grid>, recorded: &RecordedPlan, configs: &[PlannerConfig]) {
        self.decisions += 1;
        self.goals += recorded.goals.len();
        let robots: Vec<Option<[f64; 2]>> = recorded.goals.iter().map(|g| g.position).collect();
        let configs = recorded.planner_configs(configs);
        // No map yet, or a drone off the replayed map: every goal differs.
        let Some(Ok(Some(plan))) =
            grid.map(|g| nav::mission::plan_first_open(g, &robots, &configs))
        else {
            return;
        };
        for (g, r) in recorded.goals.iter().zip(&plan.robots) {
            match (g.goal, r.goal) {
                (None, None) => self.same += 1,
                (Some(a), Some(b)) => {
                    let d = (a[0] - b[0]).hypot(a[1] - b[1]);
                    self.same += usize::from(d <= SAME_GOAL_M);
                    self.shifts.push(d);
                }
                _ => {}
            }
        }
    }

    fn comparison(mut self) -> Option<NavigationComparison> {
        self.shifts.sort_by(f64::total_cmp);
        (self.decisions > 0).then(|| NavigationComparison {
            decisions: self.decisions,
            goals: self.goals,
            same_goal: self.same as f64 / self.goals.max(1) as f64,
            median_goal_shift_m: self.shifts.get(self.shifts.len() / 2).copied(),
        })
    }
}

/// Two 2D maps cell by cell.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MapComparison {
    /// Cells known (free or occupied) in either map.
    pub cells: usize,
    /// Fraction of those with the same state in both.
    pub agreement: f64,
    /// Free cells of both over free cells of either.
    pub free_iou: f64,
}

/// One drone's replayed trajectory against the recorded one.
#[derive(Debug, serde::Serialize)]
pub struct DroneComparison {
    /// 1-based id.
    pub id: usize,
    /// Recorded poses compared (the filter's, at control ticks with a replayed pose near).
    pub compared: usize,
    /// RMS horizontal distance between them, metres.
    pub rms_m: Option<f64>,
    /// Frames the replayed SLAM could not track.
    pub lost_frames: usize,
}

/// Runs `gcs replay`.
pub fn run(args: &ReplayArgs) -> anyhow::Result<()> {
    let log = mission_log::load(&args.log)?;
    if args.truth_poses && log.frames.iter().all(|f| f.truth.is_none()) {
        bail!(
            "{} has no true camera poses (/droneK/camera/truth): it was not recorded in the simulator; replay without --truth-poses",
            args.log.display()
        );
    }
    if log.truncated {
        tracing::warn!(
            "{} ends early (a crashed writer?): replaying its first {} messages",
            args.log.display(),
            log.messages
        );
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    let setups: Vec<RobotSetup> = log
        .setup
        .drones
        .iter()
        .map(|d| {
            let [x, y, z, qx, qy, qz, qw] = d.body_from_camera;
            RobotSetup {
                body_from_camera: Isometry3::from_parts(
                    Translation3::new(x, y, z),
                    UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
                ),
                start: d.start.map(|s| {
                    Isometry3::new(
                        nalgebra::Vector3::new(s[0], s[1], 0.0),
                        nalgebra::Vector3::z() * s[2],
                    )
                }),
            }
        })
        .collect();
    let n = setups.len();
    let mut slam = Slam::new(
        SlamConfig {
            background: false,
            known_poses: args.truth_poses,
            ..SlamConfig::default()
        },
        setups,
    );
    let total = log.frames.len();
    eprintln!(
        "replay: {} frames of {} drone(s) from {}",
        total,
        n,
        args.log.display()
    );
    let planners = planner_configs(&log.setup);
    let mut plans = log.plans.iter().peekable();
    let mut navigation = NavigationTally::default();
    let mut body_tracks: Vec<Vec<(f64, [f64; 2])>> = vec![vec![]; n];
    let samples: Vec<Vec<SensorSample>> = log
        .states
        .iter()
        .map(|states| states.iter().map(sensor_sample).collect())
        .collect();
    for (i, f) in log.frames.iter().enumerate() {
        // The decisions made before this frame, on the map of the frames before it.
        if plans.peek().is_some_and(|p| p.t < f.stamp) {
            let grid = slam.map().project();
            while let Some(p) = plans.next_if(|p| p.t < f.stamp) {
                navigation.replan(grid.as_ref(), p, &planners);
            }
        }
        if f.drone >= n {
            continue;
        }
        let sensors = samples.get(f.drone).and_then(|s| sensors_at(s, f.stamp));
        let Some(frame) = slam_frame(f, sensors, args.truth_poses) else {
            continue;
        };
        if let Err(e) = slam.process(frame) {
            tracing::warn!(
                drone = f.drone + 1,
                "frame at {:.2} s refused: {e}",
                f.stamp
            );
            continue;
        }
        if let Some(b) = slam.estimate(f.drone).and_then(|e| e.map_from_body()) {
            let v = b.translation.vector;
            body_tracks[f.drone].push((f.stamp, [v.x, v.y]));
        }
        if (i + 1) % 200 == 0 || i + 1 == total {
            eprintln!(
                "[{:5.1} %] {} keyframes, {} loops",
                (i + 1) as f64 / total.max(1) as f64 * 100.0,
                slam.stats().keyframes,
                slam.stats().loop_closures
            );
        }
    }
    let grid = slam.map().project();
    for p in plans {
        navigation.replan(grid.as_ref(), p, &planners);
    }
    slam.finish();
    let grid = slam.map().project();
    let stats = slam.stats();
    let report = ReplayReport {
        messages: log.messages,
        truncated: log.truncated,
        frames: total,
        keyframes: stats.keyframes,
        loop_closures: stats.loop_closures,
        map: match (&grid, &log.grid) {
            (Some(a), Some(b)) => compare_maps(a, b),
            _ => None,
        },
        navigation: navigation.comparison(),
        drones: (0..n)
            .map(|k| {
                let (compared, rms_m) = compare_tracks(&body_tracks[k], &log.states[k]);
                DroneComparison {
                    id: k + 1,
                    compared,
                    rms_m,
                    lost_frames: slam.estimate(k).map_or(0, |e| e.lost_frames),
                }
            })
            .collect(),
    };
    if let Some(g) = &grid {
        outputs::write_map(&args.out, g)?;
    }
    for k in 0..n {
        let t: Vec<Stamped> = slam.trajectory(k);
        outputs::write_trajectory(&args.out.join(format!("drone{}.tum", k + 1)), &t)?;
    }
    outputs::write_json(&args.out.join("replay.json"), &report)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "replayed {} frames: {} keyframes, {} loops; map agreement with the mission's: {}; planner: {}; outputs in {}",
            report.frames,
            report.keyframes,
            report.loop_closures,
            report
                .map
                .map_or("-".into(), |m| format!("{:.1} %", m.agreement * 100.0)),
            report
                .navigation
                .map_or("no decisions recorded".into(), |n| format!(
                    "{:.1} % of {} goals the same in {} decisions",
                    n.same_goal * 100.0,
                    n.goals,
                    n.decisions
                )),
            args.out.display()
        );
    }
    Ok(())
}

/// The mission planner's settings, as the log's setup recorded them (the runtime's defaults for
/// what older logs did not record).
pub(crate) fn planner_configs(setup: &Setup) -> Vec<PlannerConfig> {
    let radii = if setup.planner_radii.is_empty() {
        RuntimeConfig::default().planner_radii
    } else {
        setup.planner_radii.clone()
    };
    let strategy = match setup.strategy.as_str() {
        "greedy" => Strategy::Greedy,
        _ => Strategy::Hungarian,
    };
    let centre = setup.centre_paths.unwrap_or(false);
    radii
        .iter()
        .map(|&robot_radius_m| PlannerConfig {
            strategy,
            robot_radius_m,
            // …and planned shortest paths at every radius.
            comfort_m: centring_comfort(centre, &radii, robot_radius_m),
            // …and kept nothing more from the unknown.
            unknown_comfort_m: setup.unknown_comfort_m.unwrap_or(0.0),
            region_radius_m: setup.region_radius_m.unwrap_or(0.0),
            // Logs from before the margin planned without one.
            hold_margin_m: setup.hold_margin_m.unwrap_or(0.0),
            // …and explored every frontier.
            max_pocket_m2: setup.max_pocket_m2.unwrap_or(0.0),
            // …and weighed paths alone.
            turn_m_per_rad: setup.turn_m_per_rad.unwrap_or(0.0),
            // …and hovered without a frontier.
            stage_back_m: setup.stage_back_m.unwrap_or(0.0),
            ..PlannerConfig::default()
        })
        .collect()
}

/// A drone's recorded state as the sensor sample the live mission gave its SLAM.
fn sensor_sample(s: &DroneState) -> SensorSample {
    SensorSample {
        t: s.t,
        heading: s.yaw_rad.map(f64::from),
        heading_t: s.heading_t.map_or(s.t, |h| h.min(s.t)),
        height: s.height_m.map(f64::from),
        tilt: s.tilt,
        body: s.pose,
        body_sigma_m: s.pose_sigma_m,
    }
}

/// Cell-by-cell agreement of two maps, over the cells either knows (`b`'s cells looked up by
/// their centres in `a`).
fn compare_maps(a: &Grid, b: &Grid) -> Option<MapComparison> {
    let (mut cells, mut same, mut free_both, mut free_either) = (0usize, 0usize, 0usize, 0usize);
    let lookup = |g: &Grid, p: [f64; 2]| g.cell_of(p).map_or(Cell::Unknown, |c| g.get(c));
    // Every cell of either map, visited once: b's cells, then a's cells b does not cover.
    let mut visit = |ca: Cell, cb: Cell| {
        if ca == Cell::Unknown && cb == Cell::Unknown {
            return;
        }
        cells += 1;
        same += usize::from(ca == cb);
        free_both += usize::from(ca == Cell::Free && cb == Cell::Free);
        free_either += usize::from(ca == Cell::Free || cb == Cell::Free);
    };
    for y in 0..b.height() {
        for x in 0..b.width() {
            let p = b.center_of((x, y));
            visit(lookup(a, p), b.get((x, y)));
        }
    }
    for y in 0..a.height() {
        for x in 0..a.width() {
            let p = a.center_of((x, y));
            if b.cell_of(p).is_none() {
                visit(a.get((x, y)), Cell::Unknown);
            }
        }
    }
    (cells > 0).then(|| MapComparison {
        cells,
        agreement: same as f64 / cells as f64,
        free_iou: free_both as f64 / free_either.max(1) as f64,
    })
}

/// RMS horizontal distance between the recorded filter poses and the replayed body poses
/// nearest in time (within 0.1 s).
fn compare_tracks(replayed: &[(f64, [f64; 2])], recorded: &[DroneState]) -> (usize, Option<f64>) {
    let (mut sum, mut count) = (0.0, 0usize);
    for s in recorded {
        let Some(p) = s.pose else { continue };
        let i = replayed.partition_point(|(t, _)| *t < s.t);
        let nearest = [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| replayed.get(j))
            .min_by(|a, b| (a.0 - s.t).abs().total_cmp(&(b.0 - s.t).abs()));
        if let Some((t, q)) = nearest
            && (t - s.t).abs() <= 0.1
        {
            sum += (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
            count += 1;
        }
    }
    (count, (count > 0).then(|| (sum / count as f64).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_agrees_with_itself_and_less_with_a_shifted_copy() {
        let mut a = Grid::new(40, 20, 0.05, [0.0, 0.0], Cell::Unknown);
        for y in 0..20 {
            for x in 0..30 {
                a.set((x, y), if x == 29 { Cell::Occupied } else { Cell::Free });
            }
        }
        let same = compare_maps(&a, &a).expect("cells");
        assert_eq!((same.agreement, same.free_iou), (1.0, 1.0));
        let mut b = a.clone();
        for y in 0..20 {
            for x in 20..30 {
                b.set((x, y), Cell::Unknown);
            }
        }
        let part = compare_maps(&a, &b).expect("cells");
        assert!((part.agreement - 20.0 / 30.0).abs() < 1e-9, "{part:?}");
    }

    #[test]
    fn a_decision_made_again_on_the_same_map_gives_the_same_goals_and_a_moved_goal_counts() {
        // A 6 × 2 m room known in its west half: one frontier, on the east.
        let mut grid = Grid::new(120, 40, 0.05, [0.0, 0.0], Cell::Unknown);
        for y in 0..40 {
            for x in 0..60 {
                let wall = y == 0 || y == 39 || x == 0;
                grid.set((x, y), if wall { Cell::Occupied } else { Cell::Free });
            }
        }
        let configs = planner_configs(&Setup {
            version: 1,
            world: None,
            strategy: "hungarian".into(),
            planner_radii: vec![],
            region_radius_m: None,
            hold_margin_m: None,
            max_pocket_m2: None,
            turn_m_per_rad: None,
            stage_back_m: None,
            centre_paths: None,
            unknown_comfort_m: None,
            drones: vec![],
        });
        assert_eq!(configs.len(), RuntimeConfig::default().planner_radii.len());
        // Logs from before regions, goal holding, pockets and turns planned without them; newer
        // ones say what they used.
        assert!(configs.iter().all(|c| c.region_radius_m == 0.0
            && c.hold_margin_m == 0.0
            && c.max_pocket_m2 == 0.0
            && c.turn_m_per_rad == 0.0
            && c.stage_back_m == 0.0
            && c.comfort_m == 0.0
            && c.unknown_comfort_m == 0.0));
        let with_regions = planner_configs(&Setup {
            version: 1,
            world: None,
            strategy: "greedy".into(),
            planner_radii: vec![0.3],
            region_radius_m: Some(2.5),
            hold_margin_m: Some(0.5),
            max_pocket_m2: Some(0.4),
            turn_m_per_rad: Some(0.9),
            stage_back_m: Some(1.5),
            centre_paths: Some(true),
            unknown_comfort_m: Some(0.3),
            drones: vec![],
        });
        assert_eq!(with_regions.len(), 1);
        assert_eq!(with_regions[0].region_radius_m, 2.5);
        assert_eq!(with_regions[0].hold_margin_m, 0.5);
        assert_eq!(with_regions[0].max_pocket_m2, 0.4);
        assert_eq!(with_regions[0].turn_m_per_rad, 0.9);
        assert_eq!(with_regions[0].stage_back_m, 1.5);
        // One radius: no wider one to keep the distance of.
        assert_eq!(with_regions[0].comfort_m, 0.0);
        assert_eq!(with_regions[0].unknown_comfort_m, 0.3);
        assert_eq!(with_regions[0].strategy, Strategy::Greedy);
        let robots = [Some([0.5, 1.0])];
        let live = nav::mission::plan_first_open(&grid, &robots, &configs)
            .expect("plans")
            .expect("a plan");
        let goal = live.robots[0].goal.expect("the frontier is a goal");
        let recorded = |goal: Option<[f64; 2]>, given_up: Vec<[f64; 2]>| RecordedPlan {
            t: 1.0,
            goals: vec![gcs::record::PlannedGoal {
                drone: 0,
                position: robots[0],
                held: None,
                heading: None,
                goal,
                path: vec![],
            }],
            given_up,
        };
        let mut tally = NavigationTally::default();
        tally.replan(Some(&grid), &recorded(Some(goal), vec![]), &configs);
        // The mission had given that goal up: the replay must skip it too (nothing else left).
        tally.replan(Some(&grid), &recorded(None, vec![goal]), &configs);
        // A mission that sent the drone 2 m elsewhere.
        tally.replan(
            Some(&grid),
            &recorded(Some([goal[0], goal[1] + 2.0]), vec![]),
            &configs,
        );
        // No replayed map yet.
        tally.replan(None, &recorded(Some(goal), vec![]), &configs);
        let c = tally.comparison().expect("decisions");
        assert_eq!((c.decisions, c.goals), (4, 4));
        assert!((c.same_goal - 0.5).abs() < 1e-9, "{c:?}");
        // Shifts 0 and 2 m: the upper median.
        assert!(
            (c.median_goal_shift_m.expect("shifts") - 2.0).abs() < 1e-9,
            "{c:?}"
        );
        assert!(NavigationTally::default().comparison().is_none());
    }
}
