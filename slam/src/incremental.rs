//! Incremental pose-graph optimisation for a running SLAM: add poses and edges as they come,
//! the graph is re-optimised in the background from the last estimate, and readers get the latest
//! published estimate at once, never waiting for an optimisation in progress.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;

use crate::optimize::{OptimizeError, Options, Report, optimize};
use crate::posegraph::{Edge, Graph, Pose, vertex_id};

/// An estimate published by the background optimiser.
#[derive(Debug, Clone)]
pub struct Estimate<P> {
    /// Optimised poses, by index (poses added since are not in it yet).
    pub poses: Vec<P>,
    /// Their vertex ids (robot in the top 8 bits, see [`vertex_id`]).
    pub ids: Vec<u64>,
    /// How many additions (poses + edges) it includes.
    pub generation: u64,
    /// The optimisation that produced it; `None` for the empty start.
    pub report: Option<Report>,
}

struct Pending<P> {
    poses: Vec<(u64, P)>,
    edges: Vec<Edge<P>>,
    added: u64,
    error: Option<String>,
}

struct Shared<P> {
    pending: Mutex<Pending<P>>,
    wake: Condvar,
    latest: Mutex<Arc<Estimate<P>>>,
    busy: AtomicBool,
    stop: AtomicBool,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A pose graph optimised in the background.
pub struct Incremental<P: Pose> {
    shared: Arc<Shared<P>>,
    next_index: Mutex<usize>,
    thread: Option<JoinHandle<()>>,
}

impl<P: Pose> Incremental<P> {
    /// Starts the background optimiser.
    pub fn new(options: Options) -> Self {
        let shared = Arc::new(Shared {
            pending: Mutex::new(Pending {
                poses: vec![],
                edges: vec![],
                added: 0,
                error: None,
            }),
            wake: Condvar::new(),
            latest: Mutex::new(Arc::new(Estimate {
                poses: vec![],
                ids: vec![],
                generation: 0,
                report: None,
            })),
            busy: AtomicBool::new(false),
            stop: AtomicBool::new(false),
        });
        let sh = shared.clone();
        let thread = std::thread::Builder::new()
            .name("pose-graph".into())
            .spawn(move || worker(&sh, &options))
            .ok();
        Self {
            shared,
            next_index: Mutex::new(0),
            thread,
        }
    }

    /// Adds a pose of robot 0 with its initial guess; returns its index.
    pub fn add_pose(&self, initial: P) -> usize {
        self.add_pose_of(0, initial)
    }

    /// Adds a pose of `robot` (one graph for every robot) with its initial guess; returns its
    /// index. Its vertex id is [`vertex_id`]`(robot, index)`.
    pub fn add_pose_of(&self, robot: u8, initial: P) -> usize {
        let mut next = lock(&self.next_index);
        let index = *next;
        *next += 1;
        let mut p = lock(&self.shared.pending);
        p.poses.push((vertex_id(robot, index as u64), initial));
        p.added += 1;
        self.shared.wake.notify_all();
        index
    }

    /// Adds a measurement between two poses already added.
    pub fn add_edge(&self, edge: Edge<P>) {
        let mut p = lock(&self.shared.pending);
        p.edges.push(edge);
        p.added += 1;
        self.shared.wake.notify_all();
    }

    /// Additions so far (poses + edges).
    pub fn generation(&self) -> u64 {
        lock(&self.shared.pending).added
    }

    /// The latest published estimate, at once (a running optimisation is not waited for).
    pub fn latest(&self) -> Arc<Estimate<P>> {
        lock(&self.shared.latest).clone()
    }

    /// Whether an optimisation is running now.
    pub fn busy(&self) -> bool {
        self.shared.busy.load(Ordering::Relaxed)
    }

    /// The last optimisation error, if any (e.g. an edge naming a pose never added).
    pub fn last_error(&self) -> Option<String> {
        lock(&self.shared.pending).error.clone()
    }
}

impl<P: Pose> Drop for Incremental<P> {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.shared.wake.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn worker<P: Pose>(shared: &Shared<P>, options: &Options) {
    let mut graph: Graph<P> = Graph {
        ids: vec![],
        poses: vec![],
        edges: vec![],
    };
    let mut generation = 0;
    loop {
        // Take everything added since the last run.
        let (poses, edges, added) = {
            let mut p = lock(&shared.pending);
            while p.added == generation && !shared.stop.load(Ordering::Relaxed) {
                p = shared.wake.wait(p).unwrap_or_else(PoisonError::into_inner);
            }
            if shared.stop.load(Ordering::Relaxed) {
                return;
            }
            (
                std::mem::take(&mut p.poses),
                std::mem::take(&mut p.edges),
                p.added,
            )
        };
        shared.busy.store(true, Ordering::Relaxed);
        for (id, pose) in poses {
            graph.ids.push(id);
            graph.poses.push(pose);
        }
        let n = graph.poses.len();
        let (good, bad): (Vec<_>, Vec<_>) = edges
            .into_iter()
            .partition(|e| e.i < n && e.j < n && e.i != e.j);
        graph.edges.extend(good);
        let result: Result<Report, OptimizeError> = optimize(&mut graph, options);
        generation = added;
        {
            let mut p = lock(&shared.pending);
            p.error = match (&result, bad.len()) {
                (Err(e), _) => Some(e.to_string()),
                (Ok(_), 0) => None,
                (Ok(_), k) => Some(format!(
                    "{k} edges named poses that were never added; they were dropped"
                )),
            };
        }
        let published = Estimate {
            poses: graph.poses.clone(),
            ids: graph.ids.clone(),
            generation,
            report: result.ok(),
        };
        *lock(&shared.latest) = Arc::new(published);
        shared.busy.store(false, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::posegraph::tests::data;
    use crate::posegraph::{AnyGraph, chi2, read_g2o};
    use std::time::{Duration, Instant};

    #[test]
    fn streamed_graph_ends_where_the_batch_solution_is() {
        let AnyGraph::Se2(batch_in) = read_g2o(data("intel.g2o")).unwrap() else {
            panic!("2D")
        };
        let mut batch = batch_in.clone();
        let batch_report = optimize(&mut batch, &Options::default()).unwrap();

        let inc = Incremental::new(Options::default());
        // Stream it as SLAM would: poses in order, each with the edges that close on it.
        let mut by_newest: Vec<Vec<&Edge<_>>> = vec![vec![]; batch_in.poses.len()];
        for e in &batch_in.edges {
            by_newest[e.i.max(e.j)].push(e);
        }
        for (k, p) in batch_in.poses.iter().enumerate() {
            assert_eq!(inc.add_pose(*p), k);
            for e in &by_newest[k] {
                inc.add_edge((*e).clone());
            }
        }
        let total = inc.generation();
        let until = Instant::now() + Duration::from_secs(60);
        while inc.latest().generation < total {
            assert!(
                Instant::now() < until,
                "the background optimiser did not catch up"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        let est = inc.latest();
        assert_eq!(est.poses.len(), batch_in.poses.len());
        assert!(inc.last_error().is_none());
        let streamed = Graph {
            ids: vec![],
            poses: est.poses.clone(),
            edges: batch_in.edges.clone(),
        };
        let c = chi2(&streamed);
        assert!(
            (c - batch_report.final_cost).abs() < 1e-4 * batch_report.final_cost,
            "streamed {c} vs batch {}",
            batch_report.final_cost
        );
    }

    #[test]
    fn reading_does_not_wait_for_a_running_optimisation() {
        let AnyGraph::Se3(torus) = read_g2o(data("torus3D.g2o")).unwrap() else {
            panic!("3D")
        };
        let inc = Incremental::new(Options::default());
        for p in &torus.poses {
            inc.add_pose(*p);
        }
        for e in &torus.edges {
            inc.add_edge(e.clone());
        }
        let until = Instant::now() + Duration::from_secs(10);
        while !inc.busy() {
            assert!(Instant::now() < until, "the optimiser never started");
            std::thread::yield_now();
        }
        // The optimisation takes hundreds of milliseconds; the read returns the previous estimate
        // while it is still running.
        let est = inc.latest();
        let still_busy = inc.busy();
        assert!(
            still_busy,
            "the optimisation ended before the read could overlap it"
        );
        assert!(
            est.generation < inc.generation(),
            "{} of {}",
            est.generation,
            inc.generation()
        );
    }

    #[test]
    fn bad_edges_are_reported_not_fatal() {
        let inc = Incremental::<nalgebra::Isometry2<f64>>::new(Options::default());
        inc.add_pose(nalgebra::Isometry2::identity());
        inc.add_pose_of(
            b'b',
            nalgebra::Isometry2::new(nalgebra::Vector2::new(1.0, 0.0), 0.0),
        );
        let info = vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        inc.add_edge(Edge {
            i: 0,
            j: 7,
            z: nalgebra::Isometry2::identity(),
            info: info.clone(),
        });
        inc.add_edge(Edge {
            i: 0,
            j: 1,
            z: nalgebra::Isometry2::new(nalgebra::Vector2::new(2.0, 0.0), 0.0),
            info,
        });
        let until = Instant::now() + Duration::from_secs(10);
        while inc.latest().generation < inc.generation() {
            assert!(Instant::now() < until);
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(inc.last_error().is_some_and(|e| e.contains("never added")));
        let x = inc.latest().poses[1].translation.vector.x;
        assert_eq!(crate::posegraph::robot_of_id(inc.latest().ids[1]), b'b');
        assert!((x - 2.0).abs() < 1e-6, "the good edge was still used: {x}");
    }
}
