//! Live camera frames to the SLAM: the newest frame of each drone, never a backlog.
//!
//! A station reading external cameras (`gcs fly`) must drain every stream as fast as frames
//! come, or they wait in the socket's buffers and in queues, and a frame stamped when it is
//! read is older than its stamp says. The camera threads put each frame in a [`Feed`], which
//! keeps only the newest frame of each drone; the SLAM takes them a drone at a time, in turn,
//! so when it cannot keep up every drone loses frames alike and the frames it gets are fresh.

use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use crate::runtime::perception::CameraFrame;

/// The newest camera frame of each of a fleet's drones, waiting for the SLAM.
pub struct Feed {
    state: Mutex<State>,
    /// Signalled when a frame arrives or the feed closes.
    arrived: Condvar,
}

struct State {
    /// Per drone, its newest frame not yet taken.
    newest: Vec<Option<CameraFrame>>,
    /// Per drone, frames replaced by a newer one before the SLAM took them.
    dropped: Vec<u64>,
    /// The drone to look at first.
    next: usize,
    closed: bool,
}

impl Feed {
    /// An empty feed for `drones` drones.
    pub fn new(drones: usize) -> Self {
        Self {
            state: Mutex::new(State {
                newest: (0..drones).map(|_| None).collect(),
                dropped: vec![0; drones],
                next: 0,
                closed: false,
            }),
            arrived: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Offers `frame`; it replaces its drone's frame still waiting, if any. A frame of a drone
    /// the feed does not know is refused (returned).
    pub fn put(&self, frame: CameraFrame) -> Result<(), CameraFrame> {
        let mut state = self.lock();
        let k = frame.drone;
        let Some(slot) = state.newest.get_mut(k) else {
            return Err(frame);
        };
        if slot.replace(frame).is_some() {
            state.dropped[k] += 1;
        }
        self.arrived.notify_one();
        Ok(())
    }

    /// The next drone's waiting frame in turn, waiting up to `timeout` for one; `None` when
    /// none came, or the feed is closed and empty.
    pub fn take(&self, timeout: Duration) -> Option<CameraFrame> {
        // A timeout too long for an `Instant` waits for ever.
        let deadline = Instant::now().checked_add(timeout);
        let mut state = self.lock();
        loop {
            let n = state.newest.len();
            for i in 0..n {
                let k = (state.next + i) % n;
                if let Some(frame) = state.newest[k].take() {
                    state.next = k + 1;
                    return Some(frame);
                }
            }
            if state.closed {
                return None;
            }
            let wait = match deadline {
                Some(d) => d.checked_duration_since(Instant::now())?,
                None => Duration::from_secs(3600),
            };
            state = self
                .arrived
                .wait_timeout(state, wait)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Ends the feed: [`Self::take`] returns what is waiting, then `None` at once.
    pub fn close(&self) {
        self.lock().closed = true;
        self.arrived.notify_all();
    }

    /// Whether [`Self::close`] was called: the cameras can stop reading.
    pub fn is_closed(&self) -> bool {
        self.lock().closed
    }

    /// Per drone, how many frames a newer one replaced before the SLAM took them.
    pub fn dropped(&self) -> Vec<u64> {
        self.lock().dropped.clone()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use link::camera::{Intrinsics, RgbdFrame};

    use super::*;

    fn frame(drone: usize, stamp: f64) -> CameraFrame {
        CameraFrame {
            drone,
            stamp,
            frame: Arc::new(RgbdFrame {
                vehicle: drone as u8,
                stamp: Duration::from_secs_f64(stamp),
                width: 1,
                height: 1,
                intrinsics: Intrinsics {
                    fx: 1.0,
                    fy: 1.0,
                    cx: 0.5,
                    cy: 0.5,
                },
                rgb: vec![0; 3],
                depth_mm: vec![0],
            }),
            truth: None,
        }
    }

    #[test]
    fn the_slam_gets_each_drones_newest_frame_in_turn() {
        let feed = Feed::new(2);
        for t in 0..5 {
            feed.put(frame(0, f64::from(t))).expect("drone 1 is known");
        }
        feed.put(frame(1, 10.0)).expect("drone 2 is known");
        feed.put(frame(1, 11.0)).expect("drone 2 is known");
        let taken: Vec<(usize, f64)> = std::iter::from_fn(|| feed.take(Duration::ZERO))
            .map(|f| (f.drone, f.stamp))
            .collect();
        assert_eq!(taken, [(0, 4.0), (1, 11.0)]);
        assert_eq!(feed.dropped(), [4, 1]);
        // Drone 2 read last: drone 1 comes first when both wait.
        feed.put(frame(1, 12.0)).expect("known");
        feed.put(frame(0, 5.0)).expect("known");
        assert_eq!(feed.take(Duration::ZERO).map(|f| f.drone), Some(0));
        assert_eq!(feed.take(Duration::ZERO).map(|f| f.drone), Some(1));
    }

    #[test]
    fn a_frame_of_an_unknown_drone_is_refused() {
        let feed = Feed::new(1);
        let refused = feed.put(frame(3, 1.0)).expect_err("only drone 1 is known");
        assert_eq!(refused.drone, 3);
        assert!(feed.take(Duration::ZERO).is_none());
    }

    #[test]
    fn a_reader_waits_for_a_frame_and_hears_the_feed_close() {
        let feed = Arc::new(Feed::new(1));
        let camera = {
            let feed = feed.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(50));
                feed.put(frame(0, 1.0)).expect("known");
                std::thread::sleep(Duration::from_millis(50));
                feed.close();
            })
        };
        let first = feed.take(Duration::MAX).expect("a frame comes");
        assert_eq!(first.stamp, 1.0);
        assert!(feed.take(Duration::MAX).is_none(), "closed");
        assert!(feed.is_closed());
        camera.join().expect("camera thread");
        // Nothing waiting and a short timeout: `None`, without waiting for ever.
        let open = Feed::new(1);
        assert!(open.take(Duration::from_millis(10)).is_none());
    }
}
