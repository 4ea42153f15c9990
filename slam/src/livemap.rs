//! The occupancy map kept in step with a pose graph that moves (the thesis's "two threads"):
//! each new keyframe's cloud is ray-cast into the live map at once; when an optimisation moves
//! keyframes, the whole map is rebuilt from every keyframe at its new pose on a background thread
//! and swapped in when ready, with the keyframes added meanwhile cast into it again. Readers
//! ([`MapHandle`]) see the live map at any moment and never wait for a rebuild.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;

use nalgebra::{Isometry3, Point3};
use nav::grid::Grid;

use crate::occupancy::{OccupancyConfig, VoxelMap};

/// A keyframe's contribution to the map: its cloud (camera frame) and where it was taken.
#[derive(Debug, Clone)]
pub struct NodeCloud {
    /// The keyframe.
    pub node: usize,
    /// Camera to map.
    pub map_from_camera: Isometry3<f64>,
    /// Points in the camera frame.
    pub cloud: Arc<Vec<Point3<f32>>>,
}

/// Shared read access to the live map.
#[derive(Debug, Clone)]
pub struct MapHandle(Arc<Mutex<VoxelMap>>);

impl MapHandle {
    fn lock(&self) -> MutexGuard<'_, VoxelMap> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The 2D grid projected from the live map now (`None` while nothing has been seen).
    pub fn project(&self) -> Option<Grid> {
        self.lock().project()
    }

    /// Runs `f` on the live map (briefly: insertions wait meanwhile).
    pub fn with<R>(&self, f: impl FnOnce(&VoxelMap) -> R) -> R {
        f(&self.lock())
    }
}

struct Rebuild {
    thread: JoinHandle<VoxelMap>,
    /// Keyframes cast into the live map since the rebuild took its snapshot.
    added_since: Vec<usize>,
}

/// What [`LiveMap::poll`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RebuildStatus {
    /// No rebuild running.
    Idle,
    /// A rebuild is running.
    Running,
    /// A rebuild finished and its map replaced the live one.
    Swapped,
    /// A rebuild finished and was swapped in, but the graph moved again meanwhile: call
    /// [`LiveMap::rebuild`] again with the current poses.
    SwappedStale,
}

/// The live occupancy map and its background rebuilds.
pub struct LiveMap {
    config: OccupancyConfig,
    live: MapHandle,
    rebuild: Option<Rebuild>,
    /// The graph moved again while a rebuild was running.
    stale: bool,
    rebuilds: u64,
}

impl LiveMap {
    /// An empty map.
    pub fn new(config: OccupancyConfig) -> Self {
        Self {
            live: MapHandle(Arc::new(Mutex::new(VoxelMap::new(config.clone())))),
            config,
            rebuild: None,
            stale: false,
            rebuilds: 0,
        }
    }

    /// A handle for readers.
    pub fn handle(&self) -> MapHandle {
        self.live.clone()
    }

    /// Rebuilds finished so far.
    pub fn rebuilds(&self) -> u64 {
        self.rebuilds
    }

    /// Whether a rebuild is running.
    pub fn rebuilding(&self) -> bool {
        self.rebuild.is_some()
    }

    /// Casts a new keyframe into the live map.
    pub fn insert(&mut self, node: &NodeCloud) {
        self.live
            .lock()
            .insert_cloud(&node.map_from_camera, &node.cloud);
        if let Some(r) = &mut self.rebuild {
            r.added_since.push(node.node);
        }
    }

    /// Starts rebuilding the map from `nodes` (every keyframe at its current pose) in the
    /// background; if a rebuild is already running, one more follows it (see
    /// [`RebuildStatus::SwappedStale`]).
    pub fn rebuild(&mut self, nodes: Vec<NodeCloud>) {
        if self.rebuild.is_some() {
            self.stale = true;
            return;
        }
        let config = self.config.clone();
        let spawned = std::thread::Builder::new()
            .name("map-rebuild".into())
            .spawn(move || {
                let mut map = VoxelMap::new(config);
                for n in &nodes {
                    map.insert_cloud(&n.map_from_camera, &n.cloud);
                }
                map
            });
        match spawned {
            Ok(thread) => {
                self.rebuild = Some(Rebuild {
                    thread,
                    added_since: vec![],
                });
            }
            Err(e) => tracing::warn!("cannot start a map rebuild: {e}; the live map stays"),
        }
    }

    /// Swaps a finished rebuild in; `current` gives the keyframes added meanwhile (at their
    /// current poses) to cast into it again.
    pub fn poll(&mut self, current: impl Fn(usize) -> Option<NodeCloud>) -> RebuildStatus {
        let finished = self
            .rebuild
            .as_ref()
            .is_some_and(|r| r.thread.is_finished());
        if !finished {
            return if self.rebuild.is_some() {
                RebuildStatus::Running
            } else {
                RebuildStatus::Idle
            };
        }
        let Some(r) = self.rebuild.take() else {
            return RebuildStatus::Idle;
        };
        match r.thread.join() {
            Ok(mut map) => {
                for n in r.added_since.iter().filter_map(|&k| current(k)) {
                    map.insert_cloud(&n.map_from_camera, &n.cloud);
                }
                *self.live.lock() = map;
                self.rebuilds += 1;
            }
            Err(_) => tracing::error!("a map rebuild panicked; the live map stays"),
        }
        if std::mem::take(&mut self.stale) {
            RebuildStatus::SwappedStale
        } else {
            RebuildStatus::Swapped
        }
    }

    /// Waits for a running rebuild and swaps it in (for the end of a run).
    pub fn finish(&mut self, current: impl Fn(usize) -> Option<NodeCloud>) -> RebuildStatus {
        while self
            .rebuild
            .as_ref()
            .is_some_and(|r| !r.thread.is_finished())
        {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        self.poll(current)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// A small wall 2 m ahead of a camera looking along map x.
    fn wall_cloud() -> Arc<Vec<Point3<f32>>> {
        let mut c = vec![];
        // Half a voxel apart, so every voxel of the wall gets points whatever the rounding.
        for i in -20..=20 {
            for j in -10..=10 {
                c.push(Point3::new(i as f32 * 0.025, j as f32 * 0.025, 2.0));
            }
        }
        Arc::new(c)
    }

    fn looking_along_x(x: f64, y: f64) -> Isometry3<f64> {
        // Optical z forward = map x, optical x right = map −y, optical y down = map −z.
        let r = UnitQuaternion::from_basis_unchecked(&[
            Vector3::new(0.0, -1.0, 0.0),
            Vector3::new(0.0, 0.0, -1.0),
            Vector3::new(1.0, 0.0, 0.0),
        ]);
        Isometry3::from_parts(Translation3::new(x, y, 1.0), r)
    }

    fn occupied_at(h: &MapHandle, x: f64, y: f64) -> bool {
        let g = h.project().expect("a map");
        g.cell_of([x, y])
            .is_some_and(|c| g.get(c) == nav::grid::Cell::Occupied)
    }

    #[test]
    fn a_rebuild_moves_the_walls_and_keeps_keyframes_added_meanwhile() {
        let mut map = LiveMap::new(OccupancyConfig::default());
        let handle = map.handle();
        let first = NodeCloud {
            node: 0,
            map_from_camera: looking_along_x(0.0, 0.0),
            cloud: wall_cloud(),
        };
        map.insert(&first);
        assert!(occupied_at(&handle, 2.02, 0.0));
        // The optimiser moved keyframe 0 half a metre back: rebuild with its new pose.
        let moved = NodeCloud {
            map_from_camera: looking_along_x(-0.5, 0.0),
            ..first.clone()
        };
        map.rebuild(vec![moved]);
        // A keyframe added while the rebuild runs, 3 m to the left.
        let later = NodeCloud {
            node: 1,
            map_from_camera: looking_along_x(0.0, 3.0),
            cloud: wall_cloud(),
        };
        map.insert(&later);
        let status = map.finish(|k| (k == 1).then(|| later.clone()));
        assert_eq!(status, RebuildStatus::Swapped);
        assert_eq!(map.rebuilds(), 1);
        assert!(
            occupied_at(&handle, 1.52, 0.0),
            "the wall moved with its keyframe"
        );
        assert!(!occupied_at(&handle, 2.02, 0.0), "the old wall is gone");
        assert!(
            occupied_at(&handle, 2.02, 3.0),
            "the keyframe added meanwhile is kept"
        );
        assert_eq!(map.poll(|_| None), RebuildStatus::Idle);
    }

    #[test]
    fn a_second_request_during_a_rebuild_asks_for_another() {
        let mut map = LiveMap::new(OccupancyConfig::default());
        let node = NodeCloud {
            node: 0,
            map_from_camera: looking_along_x(0.0, 0.0),
            cloud: wall_cloud(),
        };
        map.rebuild(vec![node.clone(); 50]);
        map.rebuild(vec![node]);
        assert_eq!(map.finish(|_| None), RebuildStatus::SwappedStale);
        assert!(!map.rebuilding());
    }
}
