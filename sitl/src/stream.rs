//! Camera frames to their consumers: in-process subscribers ([`Subscribers`]) and stations in
//! other processes over the TCP frame stream of `link/CAMERA.md` ([`listen`]). Shared by the
//! simulator ([`crate::runner`]) and the camera bridge for external autopilots
//! ([`crate::bridge`]).

use std::collections::VecDeque;
use std::io::Write;
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{RecvError, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use link::Address;
use link::transport::is_timeout;

use crate::sim::CameraFrame;

/// Everyone who receives camera frames.
#[derive(Default)]
pub struct Subscribers(Mutex<Vec<Arc<Queue>>>);

impl Subscribers {
    /// Every frame from now on. A lossless subscriber gets every frame in order, and
    /// [`Self::publish`] waits while `depth` wait for it. A lossy one (a network client) keeps
    /// at most `depth` frames of each camera, a new frame dropping that camera's oldest, as a
    /// live stream should (it gets what the cameras see now), and reads the cameras in turn,
    /// so when it cannot keep up every camera loses frames alike, not one camera all of them.
    pub fn add(&self, lossless: bool, depth: usize) -> Subscription {
        let queue = Arc::new(Queue {
            state: Mutex::new(QueueState::default()),
            changed: Condvar::new(),
            depth: depth.max(1),
            lossless,
        });
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(queue.clone());
        Subscription(queue)
    }

    /// Sends `frames` to every subscriber in order; subscribers that went away are dropped.
    pub fn publish(&self, frames: impl IntoIterator<Item = CameraFrame>) {
        let mut subs = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        for f in frames {
            let f = Arc::new(f);
            subs.retain(|q| q.push(&f));
        }
    }
}

impl Drop for Subscribers {
    fn drop(&mut self) {
        for q in self
            .0
            .get_mut()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
        {
            q.lock().sender_gone = true;
            q.changed.notify_all();
        }
    }
}

/// One subscriber's waiting frames.
struct Queue {
    state: Mutex<QueueState>,
    /// Signalled when a frame arrives or leaves, or either side goes.
    changed: Condvar,
    depth: usize,
    lossless: bool,
}

#[derive(Default)]
struct QueueState {
    /// Frames waiting: one queue per camera (by vehicle) when lossy, one in all when lossless.
    frames: Vec<VecDeque<Arc<CameraFrame>>>,
    /// The queue to read first.
    next: usize,
    receiver_gone: bool,
    sender_gone: bool,
}

impl QueueState {
    /// The oldest frame of the next camera in turn that has one.
    fn pop(&mut self) -> Option<Arc<CameraFrame>> {
        let n = self.frames.len();
        (0..n).find_map(|i| {
            let k = (self.next + i) % n;
            let f = self.frames[k].pop_front()?;
            self.next = k + 1;
            Some(f)
        })
    }
}

impl Queue {
    fn lock(&self) -> MutexGuard<'_, QueueState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Queues `frame` (a lossless queue waits for room; a lossy one drops the camera's
    /// oldest). False when the receiver is gone.
    fn push(&self, frame: &Arc<CameraFrame>) -> bool {
        let k = if self.lossless {
            0
        } else {
            usize::from(frame.frame.vehicle)
        };
        let mut state = self.lock();
        if state.frames.len() <= k {
            state.frames.resize_with(k + 1, VecDeque::new);
        }
        while self.lossless && state.frames[k].len() >= self.depth && !state.receiver_gone {
            state = self
                .changed
                .wait(state)
                .unwrap_or_else(PoisonError::into_inner);
        }
        if state.receiver_gone {
            return false;
        }
        let queue = &mut state.frames[k];
        if queue.len() >= self.depth {
            queue.pop_front();
        }
        queue.push_back(frame.clone());
        self.changed.notify_all();
        true
    }
}

/// Camera frames as they come, from [`Subscribers::add`] (and the simulator's and bridge's
/// `subscribe`). Dropping it unsubscribes.
pub struct Subscription(Arc<Queue>);

impl Subscription {
    /// The next frame, waiting as long as it takes; an error once the simulator is gone and
    /// every frame it sent is read.
    pub fn recv(&self) -> Result<Arc<CameraFrame>, RecvError> {
        self.recv_timeout(Duration::MAX).map_err(|_| RecvError)
    }

    /// The next frame, waiting at most `timeout`.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Arc<CameraFrame>, RecvTimeoutError> {
        let q = &self.0;
        // Beyond what an `Instant` holds is for ever.
        let deadline = Instant::now().checked_add(timeout);
        let mut state = q.lock();
        loop {
            if let Some(f) = state.pop() {
                q.changed.notify_all();
                return Ok(f);
            }
            if state.sender_gone {
                return Err(RecvTimeoutError::Disconnected);
            }
            let left = deadline.map_or(Duration::from_secs(3600), |d| {
                d.saturating_duration_since(Instant::now())
            });
            if left.is_zero() {
                return Err(RecvTimeoutError::Timeout);
            }
            state = q
                .changed
                .wait_timeout(state, left)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// The next frame if one is waiting.
    pub fn try_recv(&self) -> Result<Arc<CameraFrame>, TryRecvError> {
        match self.recv_timeout(Duration::ZERO) {
            Ok(f) => Ok(f),
            Err(RecvTimeoutError::Timeout) => Err(TryRecvError::Empty),
            Err(RecvTimeoutError::Disconnected) => Err(TryRecvError::Disconnected),
        }
    }
}

impl Iterator for Subscription {
    type Item = Arc<CameraFrame>;

    /// The next frame, until the simulator is gone.
    fn next(&mut self) -> Option<Arc<CameraFrame>> {
        self.recv().ok()
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        self.0.lock().receiver_gone = true;
        self.0.changed.notify_all();
    }
}

/// Frames of each camera a network client may fall behind before the oldest are dropped.
const CLIENT_QUEUE: usize = 2;

/// Binds the frame stream's listener on `address` (`tcpin:HOST:PORT`, so a taken port fails
/// here) and serves every station that connects, in a thread, until `stop` is set. Returns the
/// address it listens on and the thread.
pub fn listen(
    address: &Address,
    subscribers: Arc<Subscribers>,
    stop: Arc<AtomicBool>,
) -> Result<(SocketAddr, JoinHandle<()>), String> {
    let Address::TcpIn(hp) = address else {
        return Err(format!(
            "{address}: the camera stream listens for stations; give tcpin:HOST:PORT"
        ));
    };
    let listener =
        TcpListener::bind(hp.to_string()).map_err(|e| format!("cannot listen on {hp}: {e}"))?;
    let addr = listener
        .local_addr()
        .map_err(|e| format!("cannot listen on {hp}: {e}"))?;
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("cannot listen on {hp}: {e}"))?;
    let thread = std::thread::Builder::new()
        .name("camera-stream".into())
        .spawn(move || serve(&listener, &subscribers, &stop))
        .map_err(|e| format!("cannot start the camera stream: {e}"))?;
    Ok((addr, thread))
}

/// Accepts stations and gives each a thread that writes it every frame (JPEG colour at quality
/// 90, PNG depth).
fn serve(listener: &TcpListener, subscribers: &Subscribers, stop: &Arc<AtomicBool>) {
    let mut clients: Vec<JoinHandle<()>> = vec![];
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((mut stream, peer)) => {
                tracing::info!(%peer, "camera stream client connected");
                let _ = stream.set_nonblocking(false);
                let _ = stream.set_nodelay(true);
                let rx = subscribers.add(false, CLIENT_QUEUE);
                let stop = stop.clone();
                clients.extend(
                    std::thread::Builder::new()
                        .name("camera-stream-client".into())
                        .spawn(move || {
                            while !stop.load(Ordering::Relaxed) {
                                let Ok(f) = rx.recv_timeout(Duration::from_millis(100)) else {
                                    continue;
                                };
                                let sent =
                                    f.frame.encode(90).map_err(|e| e.to_string()).and_then(|b| {
                                        stream.write_all(&b).map_err(|e| e.to_string())
                                    });
                                if let Err(e) = sent {
                                    tracing::info!(%peer, "camera stream client left: {e}");
                                    return;
                                }
                            }
                        })
                        .ok(),
                );
            }
            Err(e) if is_timeout(&e) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => {
                tracing::warn!("camera stream: accept failed: {e}");
                std::thread::sleep(Duration::from_millis(200));
            }
        }
        clients.retain(|c| !c.is_finished());
    }
    for c in clients {
        let _ = c.join();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use link::camera::{Intrinsics, RgbdFrame};
    use nalgebra::Isometry3;

    /// A 1×1 frame of `vehicle` numbered `n` (in its stamp, milliseconds).
    fn frame(vehicle: u8, n: u64) -> CameraFrame {
        CameraFrame {
            frame: RgbdFrame {
                vehicle,
                stamp: Duration::from_millis(n),
                width: 1,
                height: 1,
                intrinsics: Intrinsics::kinect(1, 1),
                rgb: vec![0; 3],
                depth_mm: vec![0],
            },
            map_from_camera: Isometry3::identity(),
        }
    }

    fn label(f: &CameraFrame) -> (u8, u128) {
        (f.frame.vehicle, f.frame.stamp.as_millis())
    }

    #[test]
    fn a_lossy_subscriber_keeps_the_newest_frames_of_every_vehicle() {
        let subscribers = Subscribers::default();
        let rx = subscribers.add(false, 4);
        // Two vehicles' frames at each instant, far faster than the subscriber reads.
        for n in 0..10 {
            subscribers.publish([frame(0, n), frame(1, n)]);
        }
        let got: Vec<_> = std::iter::from_fn(|| rx.try_recv().ok())
            .map(|f| label(&f))
            .collect();
        let newest: Vec<_> = (6..10).flat_map(|n| [(0, n), (1, n)]).collect();
        assert_eq!(got, newest, "each camera's newest 4, the cameras in turn");
        // A reader that takes one frame an instant (the stream's client when the station is
        // saturated) still gets both vehicles' frames, not the first vehicle's only.
        let mut seen = [0; 2];
        for n in 10..30 {
            subscribers.publish([frame(0, n), frame(1, n)]);
            let f = rx.try_recv().expect("a frame waits");
            seen[usize::from(f.frame.vehicle)] += 1;
        }
        assert_eq!(seen, [10, 10]);
    }

    #[test]
    fn a_lossless_subscriber_holds_the_publisher_until_it_reads_or_leaves() {
        let subscribers = Arc::new(Subscribers::default());
        let rx = subscribers.add(true, 2);
        let publisher = {
            let subscribers = subscribers.clone();
            std::thread::spawn(move || {
                for n in 0..5 {
                    subscribers.publish([frame(0, n)]);
                }
            })
        };
        let got: Vec<_> = (0..3)
            .map(|_| label(&rx.recv_timeout(Duration::from_secs(10)).expect("a frame")))
            .collect();
        assert_eq!(got, [(0, 0), (0, 1), (0, 2)], "every frame, in order");
        // Two more are on their way; leaving releases the publisher whatever it was doing.
        drop(rx);
        publisher.join().expect("the publisher returns");
        subscribers.publish([frame(0, 9)]);
        assert!(
            subscribers.0.lock().expect("lock").is_empty(),
            "left: unsubscribed"
        );
    }

    #[test]
    fn a_subscriber_reads_what_waits_then_hears_the_simulator_is_gone() {
        let subscribers = Subscribers::default();
        let mut rx = subscribers.add(false, 8);
        subscribers.publish([frame(0, 1), frame(1, 1)]);
        drop(subscribers);
        assert_eq!(
            rx.by_ref().map(|f| label(&f)).collect::<Vec<_>>(),
            [(0, 1), (1, 1)]
        );
        assert_eq!(rx.try_recv().err(), Some(TryRecvError::Disconnected));
        assert_eq!(
            rx.recv_timeout(Duration::from_secs(10)).err(),
            Some(RecvTimeoutError::Disconnected)
        );
    }
}
