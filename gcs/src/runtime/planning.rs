//! The mission planner's work, off the mission loop: projecting the 3D map to the 2D grid and
//! planning on it take a large map a good part of a second (building 31, dev build: up to
//! 1.5 s), and the loop must fly the drones at 10 Hz meanwhile. When it waited for them, the
//! drones went a second and more of mission time without a filter update or a stick command:
//! their filters' heights ran off during take-offs, the poses expired, and both drones landed
//! for "no pose" while their cameras and the SLAM worked.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::time::Instant;

use nav::grid::Grid;
use nav::inflate::inflate;
use nav::mission::{Plan, PlanError, PlannerConfig, plan, plan_first_open};
use nav::search::{astar, metres, nearest_free};
use slam::livemap::MapHandle;

/// What the mission asks of the planner at one step.
#[derive(Debug, Clone)]
pub struct Ask {
    /// Mission time of the step, seconds.
    pub t: f64,
    /// The exploring drones to plan for (indices); none: only the map is wanted.
    pub drones: Vec<usize>,
    /// Where each is (x, y), `None` without a position good enough to plan from.
    pub robots: Vec<Option<[f64; 2]>>,
    /// The planner's settings, widest robot radius first ([`plan_first_open`]), with the goals
    /// given up and the goals held.
    pub configs: Vec<PlannerConfig>,
    /// The mission may end on this step if nothing reachable is left (every drone airborne,
    /// the shortest mission flown).
    pub may_end: bool,
    /// Where each drone asked for started (x, y), to find its way home.
    pub homes: Vec<Option<[f64; 2]>>,
}

/// The planner's answer to an [`Ask`].
#[derive(Debug)]
pub struct Answer {
    /// What was asked.
    pub ask: Ask,
    /// The 2D map, `None` while the SLAM has mapped nothing.
    pub grid: Option<Arc<Grid>>,
    /// The positions planned from: those asked, but `None` for one outside the map.
    pub robots: Vec<Option<[f64; 2]>>,
    /// The plan, when drones were asked for and there is a map.
    pub plan: Option<Result<Plan, PlanError>>,
    /// No reachable frontier is left, every drone could plan, and the mission may end: the
    /// last resorts ([`plan`] with the thinnest settings, looking at frontiers out of reach
    /// from afar) were tried and the plan is theirs if they found something.
    pub ending: bool,
    /// Each drone's way home, metres, on the map inflated by the thinnest robot radius (as a
    /// drone flying home plans): `None` without a plan, a position, a home or a way between
    /// them.
    pub ways_home: Vec<Option<f64>>,
    /// Wall time of the projection and of the planning, seconds.
    pub seconds: [f64; 2],
}

/// When the mission asks the planner for a step: every `period` seconds, and at once (but no
/// sooner than [`Cadence::MIN_GAP_S`] after the last ask) when a drone waits for a plan.
/// A drone done looking around otherwise hovered until the next step, half a period on
/// average, at each of its goals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cadence {
    period: f64,
    next: f64,
    last: f64,
}

impl Cadence {
    /// A waiting drone's ask comes no sooner than this after the last, seconds: the planner
    /// may have no goal for it, and must not be asked without pause meanwhile.
    pub const MIN_GAP_S: f64 = 0.2;

    /// Steps every `period` seconds, the first at `first`.
    pub fn new(period: f64, first: f64) -> Self {
        Self {
            period,
            next: first,
            last: f64::NEG_INFINITY,
        }
    }

    /// Whether to ask for a step at `now`, with `waiting`: a drone waits for a plan. A step
    /// asked early starts the period again from it.
    pub fn due(&mut self, now: f64, waiting: bool) -> bool {
        let due = now >= self.next || (waiting && now - self.last >= Self::MIN_GAP_S);
        if due {
            // A loop that fell far behind (a debugger, a stalled process) does not ask again
            // and again to catch up.
            self.next = if now >= self.next {
                (self.next + self.period).max(now - 1.0)
            } else {
                now + self.period
            };
            self.last = now;
        }
        due
    }
}

/// The planner's thread: one step at a time, the next asked only once the last is answered.
pub struct Planner {
    asks: Sender<Ask>,
    answers: Receiver<Answer>,
    busy: bool,
}

/// The planner's thread ended (it panicked): the mission cannot plan any more.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlannerStopped;

impl Planner {
    /// Starts the thread, which projects `map` at every step.
    pub fn start(map: MapHandle) -> std::io::Result<Self> {
        let (asks, rx) = channel::<Ask>();
        let (tx, answers) = channel();
        std::thread::Builder::new()
            .name("planner".into())
            .spawn(move || {
                for ask in rx {
                    if tx.send(work(&map, ask)).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            asks,
            answers,
            busy: false,
        })
    }

    /// Asks for a step unless the last is still being worked on; whether it asked.
    pub fn ask(&mut self, ask: Ask) -> Result<bool, PlannerStopped> {
        if self.busy {
            return Ok(false);
        }
        self.asks.send(ask).map_err(|_| PlannerStopped)?;
        self.busy = true;
        Ok(true)
    }

    /// The answer to the step asked, if it has come.
    pub fn answer(&mut self) -> Result<Option<Answer>, PlannerStopped> {
        match self.answers.try_recv() {
            Ok(answer) => {
                self.busy = false;
                Ok(Some(answer))
            }
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => Err(PlannerStopped),
        }
    }

    /// Waits for the answer to the step asked, if one was (tests).
    #[cfg(test)]
    pub fn wait(&mut self) -> Option<Answer> {
        if !self.busy {
            return None;
        }
        self.busy = false;
        self.answers.recv().ok()
    }
}

fn work(map: &MapHandle, ask: Ask) -> Answer {
    let started = Instant::now();
    let grid = map.project().map(Arc::new);
    let projected = started.elapsed().as_secs_f64();
    let robots: Vec<Option<[f64; 2]>> = ask
        .robots
        .iter()
        .map(|p| p.filter(|p| grid.as_ref().is_some_and(|g| g.cell_of(*p).is_some())))
        .collect();
    let mut ending = false;
    let plan = match &grid {
        Some(grid) if !ask.drones.is_empty() => {
            plan_first_open(grid, &robots, &ask.configs)
                .transpose()
                .map(|first| {
                    let first = first?;
                    // Complete only when every exploring drone could plan: one without a pose
                    // might be the only one that can reach what is left.
                    ending = first.complete && ask.may_end && robots.iter().all(Option::is_some);
                    Ok(match ask.configs.last() {
                        Some(last) if ending && !first.frontiers.is_empty() => {
                            last_resorts(grid, &robots, last, first)
                        }
                        _ => first,
                    })
                })
        }
        _ => None,
    };
    let ways_home = match (&grid, &plan, ask.configs.last()) {
        (Some(grid), Some(Ok(plan)), Some(thinnest)) => {
            ways_home(grid, plan, &robots, &ask.homes, thinnest.robot_radius_m)
        }
        _ => vec![None; robots.len()],
    };
    let planned = started.elapsed().as_secs_f64() - projected;
    Answer {
        ask,
        grid,
        robots,
        plan,
        ending,
        ways_home,
        seconds: [projected, planned],
    }
}

/// The length of each robot's shortest way to its home on `grid` inflated by `radius` (the
/// thinnest robot radius: a drone flying home plans with it, and the wider ones may not pass a
/// door it flies through; the plan's own map when it is inflated so), both ends moved to the
/// nearest free cell as the planner moves them; metres.
fn ways_home(
    grid: &Grid,
    plan: &Plan,
    robots: &[Option<[f64; 2]>],
    homes: &[Option<[f64; 2]>],
    radius: f64,
) -> Vec<Option<f64>> {
    let inflated;
    let map = if plan.robot_radius_m == radius {
        &plan.inflated
    } else {
        inflated = inflate(grid, radius);
        &inflated
    };
    let reach = (radius / map.resolution()).ceil() as usize * 2 + 2;
    let free = |p: [f64; 2]| nearest_free(map, map.cell_of(p)?, reach);
    robots
        .iter()
        .zip(homes.iter().chain(std::iter::repeat(&None)))
        .map(|(robot, home)| {
            let (a, b) = (free((*robot)?)?, free((*home)?)?);
            astar(map, a, b).map(|(cost, _)| metres(map, cost))
        })
        .collect()
}

/// Frontiers seen but out of reach (a room glimpsed through a door at a slant, the doorway
/// itself not yet seen as free): before the end, each looked at from the nearest reachable
/// spot in sight of it, with the thin frontier margin. Only here, not whenever nothing is
/// reachable: at the start of a flight that lost the camera bridge's drone (see
/// [`plan_first_open`]). `gcs replay` does not rerun this step.
fn last_resorts(
    grid: &Grid,
    robots: &[Option<[f64; 2]>],
    last: &PlannerConfig,
    first: Plan,
) -> Plan {
    match plan(grid, robots, last) {
        Ok(look) if !look.complete => {
            tracing::debug!(
                out_of_reach = first.frontiers.len(),
                "frontiers out of reach: looked at from where a drone can"
            );
            look
        }
        _ => first,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Point3};
    use slam::livemap::{LiveMap, NodeCloud};
    use slam::occupancy::OccupancyConfig;

    /// A camera 1 m up at the origin that saw a round room of 3 m radius, its wall open to the
    /// east (a quarter of it missing) or closed.
    fn room(open: bool) -> LiveMap {
        let mut map = LiveMap::new(OccupancyConfig::default());
        let cloud: Vec<Point3<f32>> = (0..1440)
            .map(|i| f64::from(i) / 4.0)
            .filter(|deg| !(open && (*deg < 45.0 || *deg >= 315.0)))
            .flat_map(|deg: f64| {
                // A wall spans several voxels of its column (a lone one is noise to the map).
                let a = deg.to_radians();
                [-0.2, -0.1, 0.0, 0.1, 0.2]
                    .map(|z| Point3::new((3.0 * a.cos()) as f32, (3.0 * a.sin()) as f32, z))
            })
            .collect();
        map.insert(&NodeCloud {
            node: 0,
            map_from_camera: Isometry3::translation(0.0, 0.0, 1.0),
            cloud: Arc::new(cloud),
        });
        map
    }

    /// The times in 0..`until` seconds (10 ms ticks) a cadence asks at, a drone waiting from
    /// each of `waits` (start, end) to the other.
    fn asks(cadence: &mut Cadence, until: f64, waits: &[(f64, f64)]) -> Vec<f64> {
        (0..(until * 100.0) as usize)
            .map(|i| i as f64 / 100.0)
            .filter(|&t| cadence.due(t, waits.iter().any(|&(a, b)| t >= a && t < b)))
            .collect()
    }

    #[test]
    fn a_drone_waiting_for_a_plan_is_planned_for_at_once_and_the_period_restarts_from_it() {
        let near = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
        };
        let plain = asks(&mut Cadence::new(1.0, 2.0), 5.0, &[]);
        assert!(near(&plain, &[2.0, 3.0, 4.0]), "{plain:?}");
        // Waiting from 3.3 s until the plan came (3.35 s): asked at 3.3, then a period on.
        let early = asks(&mut Cadence::new(1.0, 2.0), 6.0, &[(3.3, 3.35)]);
        assert!(near(&early, &[2.0, 3.0, 3.3, 4.3, 5.3]), "{early:?}");
        // Still waiting (no goal for it): asked again only every MIN_GAP_S.
        let waiting = asks(&mut Cadence::new(1.0, 2.0), 3.5, &[(2.5, 3.5)]);
        assert!(near(&waiting[..2], &[2.0, 2.5]), "{waiting:?}");
        assert!(waiting.len() >= 6, "asked on while it waits: {waiting:?}");
        assert!(
            waiting[1..]
                .windows(2)
                .all(|w| w[1] - w[0] > 0.19 && w[1] - w[0] < 0.215),
            "every 0.2 s, to the 10 ms tick: {waiting:?}"
        );
        // Not sooner than MIN_GAP_S after a step of the period.
        let just = asks(&mut Cadence::new(1.0, 2.0), 3.0, &[(2.05, 2.1)]);
        assert!(near(&just, &[2.0]), "{just:?}");
    }

    fn ask(drones: Vec<usize>, robots: Vec<Option<[f64; 2]>>) -> Ask {
        Ask {
            t: 7.0,
            drones,
            robots,
            configs: vec![PlannerConfig::default()],
            may_end: true,
            homes: vec![Some([0.0, 0.0]); 1],
        }
    }

    #[test]
    fn a_step_is_worked_on_the_planners_thread_and_answered_once() {
        let map = room(true);
        let mut planner = Planner::start(map.handle()).expect("a thread");
        // The map alone.
        assert_eq!(planner.ask(ask(vec![], vec![])), Ok(true));
        // One step at a time: asked again before the answer, it is not asked.
        assert_eq!(planner.ask(ask(vec![0], vec![Some([0.0, 0.0])])), Ok(false));
        let answer = planner.wait().expect("an answer");
        assert_eq!(answer.ask.t, 7.0);
        assert!(answer.plan.is_none());
        let grid = answer.grid.expect("the room mapped");
        assert_eq!(grid.resolution(), 0.05);
        assert!(answer.seconds.iter().all(|s| *s >= 0.0));
        assert!(matches!(planner.answer(), Ok(None)));
        // A plan for a drone in the room: to the east, where it saw nothing (the wedge of
        // unknown from the camera out through the opening).
        assert_eq!(planner.ask(ask(vec![0], vec![Some([0.0, 0.0])])), Ok(true));
        let answer = planner.wait().expect("an answer");
        let plan = answer.plan.expect("a plan").expect("planned");
        let goal = plan.robots[0].goal.expect("a goal");
        assert!(goal[0] > 0.0 && goal[1].abs() <= goal[0] + 0.2, "{goal:?}");
        assert!(!answer.ending, "a frontier is left");
        // A drone off the map plans as one without a position, and the mission may not end on
        // a plan it could not take part in.
        assert_eq!(
            planner.ask(ask(vec![0, 1], vec![Some([0.0, 0.0]), Some([50.0, 0.0])])),
            Ok(true)
        );
        let answer = planner.wait().expect("an answer");
        assert_eq!(answer.robots, vec![Some([0.0, 0.0]), None]);
        let plan = answer.plan.expect("a plan").expect("planned");
        assert_eq!(plan.robots[1].hover_reason, Some("pose invalid"));
        assert!(!answer.ending);
    }

    #[test]
    fn a_room_with_nothing_left_to_explore_ends_the_mission_only_when_it_may() {
        let map = room(false);
        let mut planner = Planner::start(map.handle()).expect("a thread");
        for may_end in [false, true] {
            let asked = Ask {
                may_end,
                ..ask(vec![0], vec![Some([0.0, 0.0])])
            };
            assert_eq!(planner.ask(asked), Ok(true));
            let answer = planner.wait().expect("an answer");
            let plan = answer.plan.expect("a plan").expect("planned");
            assert!(plan.complete, "{} frontiers", plan.frontiers.len());
            assert_eq!(answer.ending, may_end);
        }
    }

    #[test]
    fn each_drones_way_home_is_measured_on_the_map() {
        let map = room(false);
        let mut planner = Planner::start(map.handle()).expect("a thread");
        // Three drones in the room, homes across it, at it, and one off the map; a fourth
        // drone off the map itself.
        let asked = Ask {
            homes: vec![
                Some([-1.5, 0.0]),
                Some([0.0, 1.0]),
                Some([40.0, 0.0]),
                Some([0.0, 0.0]),
            ],
            ..ask(
                vec![0, 1, 2, 3],
                vec![
                    Some([1.5, 0.0]),
                    Some([0.0, 1.0]),
                    Some([0.0, 0.0]),
                    Some([0.0, 40.0]),
                ],
            )
        };
        assert_eq!(planner.ask(asked), Ok(true));
        let ways = planner.wait().expect("an answer").ways_home;
        assert_eq!(ways.len(), 4);
        let across = ways[0].expect("a way across the room");
        assert!((across - 3.0).abs() < 0.11, "{across}");
        assert_eq!(ways[1], Some(0.0));
        assert_eq!(ways[2..], [None, None]);
    }

    #[test]
    fn a_way_home_goes_through_a_door_only_the_thinnest_radius_passes() {
        // The closed room split by a wall along x = 0 with a door 0.7 m wide in its middle.
        let mut map = room(false);
        let wall: Vec<Point3<f32>> = (-60..=60)
            .map(|i| f64::from(i) * 0.05)
            .filter(|y| y.abs() > 0.35)
            .flat_map(|y| [-0.2, -0.1, 0.0, 0.1, 0.2].map(|z| Point3::new(0.0, y as f32, z)))
            .collect();
        map.insert(&NodeCloud {
            node: 1,
            map_from_camera: Isometry3::translation(0.0, 0.0, 1.0),
            cloud: Arc::new(wall),
        });
        let mut planner = Planner::start(map.handle()).expect("a thread");
        let radius = |r| PlannerConfig {
            robot_radius_m: r,
            ..PlannerConfig::default()
        };
        let mut ways = vec![];
        for configs in [vec![radius(0.4)], vec![radius(0.4), radius(0.25)]] {
            let asked = Ask {
                configs,
                homes: vec![Some([-1.5, 0.0])],
                ..ask(vec![0], vec![Some([1.5, 0.0])])
            };
            assert_eq!(planner.ask(asked), Ok(true));
            ways.push(planner.wait().expect("an answer").ways_home[0]);
        }
        assert_eq!(ways[0], None, "0.4 m does not pass a door of 0.7 m");
        let through = ways[1].expect("0.25 m passes");
        assert!((3.0..3.3).contains(&through), "{through}");
    }
}
