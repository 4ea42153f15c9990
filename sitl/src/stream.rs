//! Camera frames to their consumers: in-process subscribers ([`Subscribers`]) and stations in
//! other processes over the TCP frame stream of `link/CAMERA.md` ([`listen`]). Shared by the
//! simulator ([`crate::runner`]) and the camera bridge for external autopilots
//! ([`crate::bridge`]).

use std::io::Write;
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use link::Address;
use link::transport::is_timeout;

use crate::sim::CameraFrame;

/// Everyone who receives camera frames.
#[derive(Default)]
pub struct Subscribers(Mutex<Vec<(SyncSender<Arc<CameraFrame>>, bool)>>);

impl Subscribers {
    /// Every frame from now on. A lossy subscriber (`lossless == false`, a network client) has
    /// frames dropped when it falls `depth` behind; a lossless one makes [`Self::publish`] wait
    /// for it.
    pub fn add(&self, lossless: bool, depth: usize) -> Receiver<Arc<CameraFrame>> {
        let (tx, rx) = sync_channel(depth);
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((tx, lossless));
        rx
    }

    /// Sends `frames` to every subscriber in order; subscribers that went away are dropped.
    pub fn publish(&self, frames: impl IntoIterator<Item = CameraFrame>) {
        let mut subs = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        for f in frames {
            let f = Arc::new(f);
            subs.retain(|(s, lossless)| {
                if *lossless {
                    // Waits while the receiver is behind; gone receivers are dropped.
                    s.send(f.clone()).is_ok()
                } else {
                    !matches!(s.try_send(f.clone()), Err(TrySendError::Disconnected(_)))
                }
            });
        }
    }
}

/// Frames a network client may fall behind before its frames are dropped.
const CLIENT_QUEUE: usize = 4;

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
