//! The SLAM on its own thread: camera frames from every drone come in, each is given what its
//! vehicle measured at the frame's time (IMU heading, rangefinder height, and the filter's
//! prediction for relocalisation), one multi-robot SLAM processes them, and pose fixes go out to
//! the drones' filters. Readers get the latest SLAM state and the live map at any moment.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use link::camera::RgbdFrame;
use nalgebra::Isometry3;
use nav::local::wrap_angle;
use nav::proximity::{ProximityConfig, Reading};
use slam::depth_odometry::{DepthOdometry, DepthOdometryConfig, WallScan};
use slam::livemap::MapHandle;
use slam::system::{Frame, Odometry, RobotEstimate, Slam, SlamStats, Tracking};
use slam::trajectory::Stamped;

use crate::record::{Record, Recorder};

/// One camera frame of one drone, stamped on the mission clock.
#[derive(Debug, Clone)]
pub struct CameraFrame {
    /// The drone (index in the fleet).
    pub drone: usize,
    /// Capture time on the mission clock, seconds.
    pub stamp: f64,
    /// The frame.
    pub frame: Arc<RgbdFrame>,
    /// The camera's true pose, when a simulator knows it (for evaluation only).
    pub truth: Option<Isometry3<f64>>,
}

/// What a vehicle measured at one moment, for the SLAM to read at a frame's time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSample {
    /// Mission clock, seconds.
    pub t: f64,
    /// IMU heading, radians.
    pub heading: Option<f64>,
    /// When the heading arrived, mission clock, seconds (`t` where the link does not stamp
    /// it): telemetry is read at the control rate, so a heading is up to a period older than
    /// the sample.
    pub heading_t: f64,
    /// Rangefinder height above the floor, metres.
    pub height: Option<f64>,
    /// Roll and pitch (FLU, radians): the attitude the vehicle reports, fused with the sticks
    /// in the drone's filter (the filter's alone where the link reports no attitude).
    pub tilt: Option<[f64; 2]>,
    /// The filter's body pose (x, y, z, yaw), if valid.
    pub body: Option<[f64; 4]>,
    /// The horizontal standard deviation of `body`, metres (absent from older logs): the SLAM
    /// relocalises a lost drone no further from `body` than this allows.
    pub body_sigma_m: Option<f64>,
}

/// What the SLAM takes from a vehicle's samples at a camera frame's time ([`sensors_at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameSensors {
    /// The sample nearest the frame, its heading left out if taken while turning faster than
    /// [`MAX_HEADING_RATE`].
    pub sample: SensorSample,
    /// The heading was steady either side of the sample ([`heading_steady`]): fit to be a
    /// prior on the map.
    pub heading_steady: bool,
    /// The heading left out of `sample` for turning, which still turns where the SLAM looks
    /// for the drone when it is lost ([`slam::system::Frame::turning_heading`]).
    pub turning_heading: Option<f64>,
}

/// The recent sensor samples of every drone (written by the control loop).
#[derive(Debug, Default)]
pub struct SensorLog(Mutex<Vec<VecDeque<SensorSample>>>);

impl SensorLog {
    /// A log for `n` drones.
    pub fn new(n: usize) -> Self {
        Self(Mutex::new(vec![VecDeque::new(); n]))
    }

    /// Records a sample of drone `k` (the last 3 s are kept; samples come in time order).
    pub fn push(&self, k: usize, s: SensorSample) {
        let mut log = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(q) = log.get_mut(k) {
            q.push_back(s);
            while q.front().is_some_and(|f| s.t - f.t > 3.0) {
                q.pop_front();
            }
        }
    }

    /// What the SLAM takes from drone `k`'s samples at time `t` ([`sensors_at`]).
    pub fn at(&self, k: usize, t: f64) -> Option<FrameSensors> {
        let mut log = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        sensors_at(log.get_mut(k)?.make_contiguous(), t)
    }
}

/// What the SLAM takes from one drone's time-ordered `samples` at a camera frame's time `t`:
/// the sample nearest it (within 0.25 s) with the heading that arrived nearest it, gated for
/// turning and marked steady or not. The live mission and `gcs replay` both read their samples
/// through it.
///
/// A heading is placed at the time it arrived, not at the control tick that read it up to a
/// period later (taken at the tick, headings lagged 0.1–0.15 s in SITL: 2–3° at 12°/s), yet it
/// still lags what the vehicle measured by the telemetry's transport. So it is left out of a
/// sample taken while turning
/// faster than [`MAX_HEADING_RATE`] (a look-around turns at 36°/s; the SLAM's heading prior is
/// 2°), and marked steady as [`heading_steady`] says.
pub fn sensors_at(samples: &[SensorSample], t: f64) -> Option<FrameSensors> {
    let nearest = |times: &[f64]| {
        let after = times.partition_point(|&s| s < t);
        let i = match (after.checked_sub(1), times.get(after)) {
            (Some(b), Some(&a)) if t - times[b] <= a - t => b,
            (Some(b), None) => b,
            (_, Some(_)) => after,
            (None, None) => return None,
        };
        ((times[i] - t).abs() < 0.25).then_some(i)
    };
    // Samples near t, wide enough for the steady window about any heading within 0.25 s.
    let near = &samples
        [samples.partition_point(|s| s.t < t - 1.0)..samples.partition_point(|s| s.t <= t + 1.0)];
    let times: Vec<f64> = near.iter().map(|s| s.t).collect();
    let mut sample = near[nearest(&times)?];
    // Each heading once, at its arrival.
    let mut headings: Vec<(f64, f64)> = near
        .iter()
        .filter_map(|s| s.heading.map(|h| (s.heading_t, h)))
        .collect();
    headings.dedup_by(|later, earlier| later.0 <= earlier.0);
    let times: Vec<f64> = headings.iter().map(|h| h.0).collect();
    let Some(j) = nearest(&times) else {
        sample.heading = None;
        return Some(FrameSensors {
            sample,
            heading_steady: false,
            turning_heading: None,
        });
    };
    let (before, here, next) = (
        headings[j.saturating_sub(1)],
        headings[j],
        headings[(j + 1).min(headings.len() - 1)],
    );
    let turning = next.0 > before.0
        && (wrap_angle(next.1 - before.1) / (next.0 - before.0)).abs() > MAX_HEADING_RATE;
    sample.heading = (!turning).then_some(here.1);
    sample.heading_t = here.0;
    let heading_steady = !turning && heading_steady(headings.iter().copied(), here.0);
    Some(FrameSensors {
        sample,
        heading_steady,
        turning_heading: turning.then_some(here.1),
    })
}

/// The fastest turn at which a telemetry heading still goes to the SLAM, radians per second.
pub const MAX_HEADING_RATE: f64 = 0.17;

/// The fastest turn, radians per second, over [`STEADY_WINDOW`] either side of a heading at
/// which it is still a prior on the map (3°/s: a lag of 0.15 s is then 0.4° off, about the
/// IMU's own noise).
pub const MAX_STEADY_RATE: f64 = 0.05;

/// How long either side of a heading it must have been steady, seconds (longer than the
/// telemetry's lag, so a turn just begun or just ended is seen).
pub const STEADY_WINDOW: f64 = 0.4;

/// Whether the heading at time `t` of the time-ordered `(time, heading)` readings was steady:
/// turning less than [`MAX_STEADY_RATE`] over [`STEADY_WINDOW`] before it and after it.
///
/// Keyframes are taken mostly while turning (every 8°) and drones turn one way more than the
/// other, so headings that lag the camera biased the whole map's yaw as priors (keyframe
/// priors −0.54° off on average gave a trajectory −0.55° off). Only steady headings are priors;
/// relocalisation and the loop-closure check take any heading the turning gate lets through.
pub fn heading_steady(readings: impl Iterator<Item = (f64, f64)>, t: f64) -> bool {
    let window: Vec<(f64, f64)> = readings
        .filter(|&(ts, _)| (ts - t).abs() <= STEADY_WINDOW)
        .collect();
    let Some(&here) = window
        .iter()
        .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
    else {
        return false;
    };
    let rate = |a: (f64, f64), b: (f64, f64)| {
        if b.0 - a.0 > 0.05 {
            (wrap_angle(b.1 - a.1) / (b.0 - a.0)).abs()
        } else {
            0.0
        }
    };
    let (first, last) = (window[0], window[window.len() - 1]);
    rate(first, here).max(rate(here, last)) <= MAX_STEADY_RATE
}

/// A SLAM pose of one drone's body at a frame's time (`None`: tracking lost).
#[derive(Debug, Clone, PartialEq)]
pub struct SlamFix {
    /// The drone.
    pub drone: usize,
    /// The frame's capture time, mission clock.
    pub stamp: f64,
    /// Body to map; `None` while lost (or not yet anchored in the map).
    pub map_from_body: Option<Isometry3<f64>>,
    /// The frame became a keyframe: the camera saw enough to build the map on.
    pub keyframe: bool,
    /// Matches that agreed with the frame's pose when it was tracked (how much of the map the
    /// camera sees: few, and the next frame may be lost, and its pose counts for less);
    /// `None` when relocalised, lost or placed at a known pose.
    pub inliers: Option<usize>,
    /// The pose is a weak registration away from the motion so far ([`Tracking::Weak`]): the
    /// drone is not flown on it (nor taken for lost).
    pub weak: bool,
    /// While lost or weak: how the body moved since the drone's previous frame (visual
    /// odometry).
    pub odometry: Option<Odometry>,
    /// While lost or weak with no visual odometry: how the body moved since the drone's
    /// previous frame along the directions its walls' depth measures ([`wall_scan`]).
    pub depth_odometry: Option<DepthOdometry>,
    /// Half the camera's horizontal field of view, radians (from the frame's intrinsics).
    pub half_fov_rad: f64,
    /// The nearest wall in each direction the camera saw ([`proximity_readings`])…
    pub ranges: Vec<Reading>,
    /// …while the IMU read this heading, radians (`None`: no heading at the frame's time).
    pub heading: Option<f64>,
}

/// The SLAM's state for displays.
#[derive(Debug, Clone, Default)]
pub struct SlamView {
    /// Every robot's estimate.
    pub robots: Vec<RobotEstimate>,
    /// Counters.
    pub stats: SlamStats,
    /// Frames processed.
    pub frames: u64,
    /// Mean SLAM time per frame over the last 100, milliseconds.
    pub ms_per_frame: f64,
}

/// What the SLAM thread leaves behind.
pub struct PerceptionResult {
    /// The SLAM, for the final trajectories, map and graph.
    pub slam: Slam,
    /// Per drone, the true camera poses at its frames (when the source knew them).
    pub truth: Vec<Vec<Stamped>>,
    /// Per drone, the camera poses as estimated when each frame was processed (what the drones
    /// flew on), map frame.
    pub online: Vec<Vec<Stamped>>,
}

/// The SLAM thread.
pub struct Perception {
    thread: Option<JoinHandle<PerceptionResult>>,
    stop: Arc<AtomicBool>,
    fixes: Receiver<SlamFix>,
    view: Arc<Mutex<Arc<SlamView>>>,
    map: MapHandle,
    frames: Arc<AtomicU64>,
}

impl Perception {
    /// Starts the SLAM thread on `frames`; it also ranges the walls in each frame with
    /// `proximity`'s settings.
    pub fn start(
        slam: Slam,
        frames: Receiver<CameraFrame>,
        sensors: Arc<SensorLog>,
        recorder: Option<Recorder>,
        proximity: ProximityConfig,
    ) -> std::io::Result<Self> {
        let (fix_tx, fixes) = channel();
        let view = Arc::new(Mutex::new(Arc::new(SlamView::default())));
        let stop = Arc::new(AtomicBool::new(false));
        let map = slam.map();
        let count = Arc::new(AtomicU64::new(0));
        let thread = {
            let (view, stop, count) = (view.clone(), stop.clone(), count.clone());
            std::thread::Builder::new()
                .name("slam".into())
                .spawn(move || {
                    let io = Io {
                        frames: &frames,
                        sensors: &sensors,
                        fixes: &fix_tx,
                        view: &view,
                        stop: &stop,
                        count: &count,
                        recorder: recorder.as_ref(),
                        proximity: &proximity,
                    };
                    run(slam, &io)
                })?
        };
        Ok(Self {
            thread: Some(thread),
            stop,
            fixes,
            view,
            map,
            frames: count,
        })
    }

    /// The fixes produced since the last call.
    pub fn take_fixes(&self) -> Vec<SlamFix> {
        self.fixes.try_iter().collect()
    }

    /// The SLAM's latest state.
    pub fn view(&self) -> Arc<SlamView> {
        self.view
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// The live map.
    pub fn map(&self) -> MapHandle {
        self.map.clone()
    }

    /// Frames processed so far.
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::Relaxed)
    }

    /// Stops the thread (after the frame in progress) and returns what it built.
    pub fn finish(mut self) -> Option<PerceptionResult> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take()?.join().ok()
    }
}

impl Drop for Perception {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// What the SLAM thread reads from and writes to.
#[derive(Clone, Copy)]
struct Io<'a> {
    frames: &'a Receiver<CameraFrame>,
    sensors: &'a SensorLog,
    fixes: &'a Sender<SlamFix>,
    view: &'a Mutex<Arc<SlamView>>,
    stop: &'a AtomicBool,
    count: &'a AtomicU64,
    recorder: Option<&'a Recorder>,
    proximity: &'a ProximityConfig,
}

fn run(mut slam: Slam, io: &Io<'_>) -> PerceptionResult {
    let Io {
        frames,
        sensors,
        fixes,
        view,
        stop,
        count,
        recorder,
        proximity,
    } = *io;
    let n = slam.robots();
    let mut truth = vec![vec![]; n];
    let mut online = vec![vec![]; n];
    let mut times: VecDeque<f64> = VecDeque::new();
    let depth_config = DepthOdometryConfig::default();
    // Per drone, its last frame, scanned for walls only when a registration needs it.
    let mut previous_frames: Vec<Option<WallFrame>> = (0..n).map(|_| None).collect();
    while !stop.load(Ordering::Relaxed) {
        let Ok(f) = frames.recv_timeout(Duration::from_millis(50)) else {
            continue;
        };
        let k = f.drone;
        if let Some(r) = recorder {
            r.send(Record::Camera {
                t: f.stamp,
                drone: k,
                frame: f.frame.clone(),
                truth: f.truth,
            });
        }
        if k >= n {
            tracing::warn!(
                drone = k + 1,
                "camera frame of a drone the SLAM does not know; dropped"
            );
            continue;
        }
        let known = slam.config().known_poses;
        let at_frame = sensors.at(k, f.stamp);
        let heading = at_frame.and_then(|s| s.sample.heading.or(s.turning_heading));
        let body_from_camera = slam.body_from_camera(k);
        let ranges = body_from_camera
            .map(|b| proximity_readings(&f.frame, &b, proximity))
            .unwrap_or_default();
        let tilt = at_frame.and_then(|s| s.sample.tilt).unwrap_or_default();
        let Some(frame) = slam_frame(&f, at_frame, known) else {
            tracing::warn!(drone = k + 1, "malformed camera frame dropped");
            continue;
        };
        let started = std::time::Instant::now();
        let report = match slam.process(frame) {
            Ok(r) => r,
            Err(e) => {
                tracing::warn!(drone = k + 1, "camera frame refused: {e}");
                continue;
            }
        };
        times.push_back(started.elapsed().as_secs_f64());
        if times.len() > 100 {
            times.pop_front();
        }
        match &report.tracking {
            Tracking::Lost(why) => tracing::debug!(drone = k + 1, "tracking lost: {why}"),
            Tracking::Relocalised { keyframe } => {
                tracing::debug!(drone = k + 1, stamp = f.stamp, keyframe, "relocalised");
            }
            Tracking::Weak { inliers } => {
                tracing::debug!(drone = k + 1, stamp = f.stamp, inliers, "weak registration");
            }
            _ => {}
        }
        if let Some(t) = f.truth {
            truth[k].push(Stamped {
                t: f.stamp,
                pose: t,
            });
        }
        // Where the features measured no motion of a drone the map does not place, its
        // walls' depth may.
        let unplaced = matches!(report.tracking, Tracking::Lost(_) | Tracking::Weak { .. });
        let mut current = WallFrame {
            stamp: f.stamp,
            heading,
            tilt,
            frame: Arc::clone(&f.frame),
            scan: None,
        };
        let depth_odometry = match (previous_frames[k].take(), body_from_camera, heading) {
            (Some(mut previous), Some(body_from_camera), Some(heading))
                if unplaced
                    && report.odometry.is_none()
                    && f.stamp > previous.stamp
                    && f.stamp - previous.stamp <= slam.config().odometry_max_gap =>
            {
                let since = previous.stamp;
                previous.heading.and_then(|then| {
                    let before = previous.scan(&body_from_camera, &depth_config);
                    let now = current.scan(&body_from_camera, &depth_config);
                    let turn = wrap_angle(heading - then);
                    slam::depth_odometry::register(since, before, now, turn, &depth_config)
                        .filter(|o| !o.along.is_empty())
                })
            }
            _ => None,
        };
        previous_frames[k] = Some(current);
        let estimate = slam.estimate(k);
        if let Some(pose) = estimate.as_ref().and_then(RobotEstimate::map_from_camera) {
            online[k].push(Stamped { t: f.stamp, pose });
        }
        let _ = fixes.send(SlamFix {
            drone: k,
            stamp: f.stamp,
            map_from_body: estimate.as_ref().and_then(RobotEstimate::map_from_body),
            keyframe: report.keyframe.is_some(),
            inliers: match report.tracking {
                Tracking::Tracked { inliers } | Tracking::Weak { inliers } => Some(inliers),
                _ => None,
            },
            weak: matches!(report.tracking, Tracking::Weak { .. }),
            odometry: report.odometry,
            depth_odometry,
            half_fov_rad: f.frame.intrinsics.half_fov_x(f.frame.width),
            ranges,
            heading,
        });
        let processed = count.fetch_add(1, Ordering::Relaxed) + 1;
        let published = SlamView {
            robots: (0..n).filter_map(|r| slam.estimate(r)).collect(),
            stats: slam.stats(),
            frames: processed,
            ms_per_frame: times.iter().sum::<f64>() / times.len().max(1) as f64 * 1e3,
        };
        *view.lock().unwrap_or_else(PoisonError::into_inner) = Arc::new(published);
    }
    slam.finish();
    PerceptionResult {
        slam,
        truth,
        online,
    }
}

/// A drone's camera frame kept for depth odometry, with what levels it and, once a
/// registration has needed it, its walls.
struct WallFrame {
    stamp: f64,
    heading: Option<f64>,
    tilt: [f64; 2],
    frame: Arc<RgbdFrame>,
    scan: Option<WallScan>,
}

impl WallFrame {
    /// The frame's walls, scanned on first use (most frames are placed by the SLAM and never
    /// need them).
    fn scan(
        &mut self,
        body_from_camera: &Isometry3<f64>,
        config: &DepthOdometryConfig,
    ) -> &WallScan {
        self.scan
            .get_or_insert_with(|| wall_scan(&self.frame, body_from_camera, self.tilt, config))
    }
}

/// The nearest wall in each direction a camera frame sees, from its depth image (every other
/// pixel) placed on the body by `body_from_camera`: what keeps a drone without a pose off the
/// walls ([`nav::proximity`]).
pub fn proximity_readings(
    frame: &RgbdFrame,
    body_from_camera: &Isometry3<f64>,
    config: &ProximityConfig,
) -> Vec<Reading> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let slam::dataset::Pinhole { fx, fy, cx, cy } = pinhole(&frame.intrinsics);
    if w == 0 || h == 0 || frame.depth_mm.len() != w * h || !(fx > 0.0 && fy > 0.0) {
        return vec![];
    }
    // The bearings of the image's side edges, on the body (the right edge is the lower).
    let edge = |u: f64| {
        let ray = body_from_camera.rotation * nalgebra::Vector3::new((u - cx) / fx, 0.0, 1.0);
        ray.y.atan2(ray.x)
    };
    let (a, b) = (edge(0.0), edge(w as f64));
    let points = (0..h).step_by(2).flat_map(|v| {
        (0..w).step_by(2).filter_map(move |u| {
            let z = f64::from(frame.depth_mm[v * w + u]) * 1e-3;
            (z > 0.0).then(|| {
                let in_camera =
                    nalgebra::Point3::new((u as f64 - cx) / fx * z, (v as f64 - cy) / fy * z, z);
                let in_body = body_from_camera * in_camera;
                [in_body.x, in_body.y, in_body.z]
            })
        })
    });
    let camera = body_from_camera.translation.vector;
    nav::proximity::readings(points, [camera.x, camera.y], [a.min(b), a.max(b)], config)
}

/// The walls a camera frame sees, placed on the body by `body_from_camera` and levelled by its
/// `tilt` (roll, pitch): what measures the motion of a drone whose camera sees no texture
/// ([`slam::depth_odometry`]).
pub fn wall_scan(
    frame: &RgbdFrame,
    body_from_camera: &Isometry3<f64>,
    tilt: [f64; 2],
    config: &DepthOdometryConfig,
) -> WallScan {
    WallScan::from_depth(
        &frame.depth_mm,
        frame.width as usize,
        frame.height as usize,
        1e-3,
        &pinhole(&frame.intrinsics),
        body_from_camera,
        tilt,
        config,
    )
}

/// A stream's camera intrinsics as the SLAM's pinhole model.
pub fn pinhole(i: &link::camera::Intrinsics) -> slam::dataset::Pinhole {
    slam::dataset::Pinhole {
        fx: f64::from(i.fx),
        fy: f64::from(i.fy),
        cx: f64::from(i.cx),
        cy: f64::from(i.cy),
    }
}

/// The SLAM's input for a camera frame and the vehicle's sample at its time (with the true
/// camera pose only when the SLAM maps on known poses); `None` for a frame of the wrong size.
pub fn slam_frame(f: &CameraFrame, sensors: Option<FrameSensors>, known: bool) -> Option<Frame> {
    let sample = sensors.map(|s| s.sample);
    let rgb = image::RgbImage::from_raw(f.frame.width, f.frame.height, f.frame.rgb.clone())?;
    let grey = image::DynamicImage::ImageRgb8(rgb).into_luma8();
    let predicted = sample.and_then(|s| s.body).map(|b| {
        Isometry3::new(
            nalgebra::Vector3::new(b[0], b[1], b[2]),
            nalgebra::Vector3::z() * b[3],
        )
    });
    Some(Frame {
        robot: f.drone,
        stamp: f.stamp,
        grey,
        depth: f.frame.depth_mm.clone(),
        depth_scale: 0.001,
        camera: pinhole(&f.frame.intrinsics),
        heading: sample.and_then(|s| s.heading),
        heading_steady: sensors.is_some_and(|s| s.heading_steady),
        turning_heading: sensors.and_then(|s| s.turning_heading),
        height: sample.and_then(|s| s.height),
        tilt: sample.and_then(|s| s.tilt),
        predicted_body: predicted,
        predicted_sigma_m: sample.and_then(|s| s.body_sigma_m),
        known_camera_pose: f.truth.filter(|_| known),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nav::proximity::Sight;

    /// The simulator's camera on its drone in the built-in apartment: renders what the drone's
    /// body at (x, y, z) heading `yaw` sees (with the depth's noise of frame `noise` if given).
    struct Apartment {
        world: sitl::World,
        camera: sitl::Camera,
        body_from_camera: Isometry3<f64>,
    }

    impl Apartment {
        fn new() -> Self {
            Self {
                world: sitl::World::load("apartment").expect("the built-in world"),
                camera: sitl::Camera::kinect(320, 240),
                body_from_camera: crate::fleet::sim_body_from_camera(),
            }
        }

        fn frame(&self, [x, y, z]: [f64; 3], yaw: f64, noise: Option<u64>) -> RgbdFrame {
            let map_from_body = Isometry3::new(
                nalgebra::Vector3::new(x, y, z),
                nalgebra::Vector3::z() * yaw,
            );
            sitl::render::render_frame(
                &self.world,
                &(map_from_body * self.body_from_camera),
                &self.camera,
                noise.map(|frame| (7, frame)),
                1,
                Duration::ZERO,
            )
        }
    }

    fn sample(t: f64, heading: f64) -> SensorSample {
        SensorSample {
            t,
            heading: Some(heading),
            heading_t: t,
            height: Some(0.9),
            tilt: None,
            body: None,
            body_sigma_m: None,
        }
    }

    /// A black 4 × 3 frame of drone index `drone` at `stamp` seconds, everything 1 m away.
    fn camera_frame(drone: usize, stamp: u64) -> CameraFrame {
        let (width, height) = (4, 3);
        CameraFrame {
            drone,
            stamp: stamp as f64,
            frame: Arc::new(RgbdFrame {
                vehicle: drone as u8 + 1,
                stamp: Duration::from_secs(stamp),
                width,
                height,
                intrinsics: link::camera::Intrinsics::kinect(width, height),
                rgb: vec![0; 36],
                depth_mm: vec![1000; 12],
            }),
            truth: None,
        }
    }

    #[test]
    fn a_depth_frame_ranges_the_walls_round_the_body_from_the_camera_mount() {
        // A 64 × 48 Kinect-like frame of a flat wall 1 m ahead of the camera, the camera
        // 0.1 m ahead of the body's centre (as on the simulated drone), except a strip of
        // invalid depth (no return) on the image's left quarter.
        let (width, height) = (64u32, 48u32);
        let depth_mm = (0..height)
            .flat_map(|_| (0..width).map(|u| if u < 16 { 0 } else { 1000 }))
            .collect();
        let frame = RgbdFrame {
            vehicle: 1,
            stamp: Duration::ZERO,
            width,
            height,
            intrinsics: link::camera::Intrinsics::kinect(width, height),
            rgb: vec![0; (width * height * 3) as usize],
            depth_mm,
        };
        let body_from_camera = crate::fleet::sim_body_from_camera();
        let config = ProximityConfig::default();
        let r = proximity_readings(&frame, &body_from_camera, &config);
        let half_fov = frame.intrinsics.half_fov_x(width);
        assert_eq!(
            r.len(),
            (2.0 * half_fov / config.bearing_step_rad).ceil() as usize
        );
        let ahead = r
            .iter()
            .min_by(|a, b| a.bearing_rad.abs().total_cmp(&b.bearing_rad.abs()))
            .expect("a direction ahead");
        let range = ahead.sight.range_m().expect("the wall ahead");
        assert!((range - 1.1).abs() < 0.02, "{ahead:?}");
        // Left in the image is left of the body (positive bearings): the invalid strip
        // leaves the leftmost directions blocked (nothing measured), the rightmost have a
        // range.
        let leftmost = r
            .iter()
            .max_by(|a, b| a.bearing_rad.total_cmp(&b.bearing_rad));
        let rightmost = r
            .iter()
            .min_by(|a, b| a.bearing_rad.total_cmp(&b.bearing_rad));
        assert!(leftmost.is_some_and(|l| l.bearing_rad > 0.4 && l.sight == Sight::Blocked));
        assert!(rightmost.is_some_and(|l| l.bearing_rad < -0.4 && l.sight.range_m().is_some()));
        // A frame whose depth does not fit its size: nothing, no panic.
        let broken = RgbdFrame {
            depth_mm: vec![1000; 5],
            ..frame
        };
        assert!(proximity_readings(&broken, &body_from_camera, &config).is_empty());
    }

    #[test]
    fn in_the_simulated_apartment_a_wall_too_near_to_range_is_blocked_and_a_corridor_open() {
        // The simulator's camera on its drone, at every altitude band of an eight-drone fleet:
        // a direction without a wall in range still shows the floor or the ceiling, which is
        // what tells an opening from a wall inside the camera's minimum range.
        let apartment = Apartment::new();
        let config = ProximityConfig::default();
        let look = |x: f64, y: f64, z: f64, yaw: f64| {
            let frame = apartment.frame([x, y, z], yaw, None);
            proximity_readings(&frame, &apartment.body_from_camera, &config)
        };
        let ahead = |r: &[Reading]| -> Vec<Sight> {
            r.iter()
                .filter(|r| r.bearing_rad.abs() < 0.1)
                .map(|r| r.sight)
                .collect()
        };
        for k in 0..8 {
            let z = crate::fleet::altitude_band(crate::fleet::LOWEST_BAND_M, k);
            // East down the corridor (x = 4 m, between its walls at y = 4.0 and 5.4 m), in
            // the directions that miss its sides within 4 m: the far wall is 10 m off, beyond
            // the camera's range.
            let corridor = ahead(&look(4.0, 4.7, z, 0.0));
            assert!(
                !corridor.is_empty() && corridor.iter().all(|s| *s == Sight::Open),
                "{z} m: {corridor:?}"
            );
            // North at its wall, 0.3 m from the body's centre (0.2 m from the camera).
            let wall = ahead(&look(4.0, 5.1, z, std::f64::consts::FRAC_PI_2));
            assert!(
                !wall.is_empty() && wall.iter().all(|s| *s == Sight::Blocked),
                "{z} m: {wall:?}"
            );
            // South at its wall from 0.7 m (0.6 m from the camera): ranged in every direction
            // in view, the outermost too (stop 93: its left one read blocked, so a drone
            // without a pose near a wall leaned off one that was not there).
            let seen = look(4.0, 4.7, z, -std::f64::consts::FRAC_PI_2);
            assert!(
                seen.iter()
                    .all(|r| r.sight.range_m().is_some_and(|m| m > 0.65 && m < 1.0)),
                "{z} m: {seen:?}"
            );
            // So a drone without a pose there leans nowhere: the wall is beyond the margin.
            let mut memory = nav::proximity::Proximity::new(&config);
            memory.observe(0.0, 0.0, &seen, &config);
            assert_eq!(memory.push(0.0, 0.0, &config), [0.0; 2], "{z} m: {seen:?}");
        }
    }

    #[test]
    fn facing_the_simulated_apartments_blank_wall_its_depth_measures_the_drift_toward_it() {
        // The featureless south wall of the south room (its face at y = 0.4 m), 1.2 m ahead
        // of the camera: what drones lost there drifted into. Between two noisy frames the
        // drone comes 1.2 cm nearer, slides 1.5 cm east along the wall and turns half a
        // degree; at every altitude band the walls' depth measures the first and claims
        // nothing of the second.
        let apartment = Apartment::new();
        let config = DepthOdometryConfig::default();
        let south = -std::f64::consts::FRAC_PI_2;
        let look = |x: f64, y: f64, z: f64, yaw: f64, frame: u64| {
            let frame = apartment.frame([x, y, z], yaw, Some(frame));
            wall_scan(&frame, &apartment.body_from_camera, [0.0; 2], &config)
        };
        for k in 0..8 {
            let z = crate::fleet::altitude_band(crate::fleet::LOWEST_BAND_M, k);
            let turn = 0.5f64.to_radians();
            let before = look(6.2, 1.7, z, south, 1);
            let after = look(6.215, 1.688, z, south + turn, 2);
            let o = slam::depth_odometry::register(0.0, &before, &after, turn, &config)
                .expect("the wall registers");
            assert_eq!(o.along.len(), 1, "{z} m: {:?}", o.along);
            let a = o.along[0];
            // Forward (toward the wall) is the body's +x.
            let toward = a.direction[0].signum() * a.displacement;
            assert!(a.direction[0].abs() > 0.99, "{z} m: {a:?}");
            assert!((toward - 0.012).abs() < 0.002, "{z} m: {a:?}");
            assert!(a.sigma <= config.min_sigma_m, "{z} m: {a:?}");
        }
    }

    #[test]
    fn turning_on_the_spot_in_the_simulated_apartment_its_depth_measures_no_slide() {
        // A lost drone's sweep: 3.6° a frame, the IMU's turn a frame behind (its heading is
        // sampled at the control rate, and a frame can read the sample before), at the start
        // of the default mission and before the blank wall. Whatever the walls in view, a turn
        // on the spot is measured as no motion, within twice the noise it states (while it was
        // written, a lone wall's normals' noise, weighed as a measurement, read the turn as a
        // slide of up to 15 cm).
        let apartment = Apartment::new();
        let config = DepthOdometryConfig::default();
        let look = |x: f64, y: f64, yaw: f64, frame: u64| {
            let frame = apartment.frame([x, y, 0.6], yaw, Some(frame));
            wall_scan(&frame, &apartment.body_from_camera, [0.0; 2], &config)
        };
        let step = 3.6f64.to_radians();
        for (x, y) in [(13.1, 2.1), (12.5, 2.6), (6.2, 1.7)] {
            let (mut frames, mut measured) = (0, 0);
            for i in 0u32..30 {
                let yaw = f64::from(i) * 12f64.to_radians();
                let before = look(x, y, yaw, 2 * u64::from(i));
                let after = look(x, y, yaw + step, 2 * u64::from(i) + 1);
                frames += 1;
                let Some(o) = slam::depth_odometry::register(0.0, &before, &after, 0.0, &config)
                else {
                    continue;
                };
                measured += usize::from(!o.along.is_empty());
                assert!((o.turn_rad - step).abs() < 0.2f64.to_radians(), "{o:?}");
                for a in &o.along {
                    let within = a.displacement.abs() <= 2.0 * a.sigma;
                    assert!(within, "({x}, {y}) at {yaw:.2}: {a:?}");
                }
            }
            assert!(
                measured * 10 >= frames * 8,
                "({x}, {y}): {measured} of {frames}"
            );
        }
    }

    #[test]
    fn a_frame_tells_the_slam_where_the_filter_has_the_drone_and_how_sure_it_is() {
        let f = camera_frame(1, 2);
        let mut s = sample(2.0, 0.5);
        s.body = Some([1.0, 2.0, 0.9, 0.5]);
        s.body_sigma_m = Some(0.04);
        let sensors = |sample| FrameSensors {
            sample,
            heading_steady: true,
            turning_heading: None,
        };
        let frame = slam_frame(&f, Some(sensors(s)), false).expect("a frame");
        let p = frame.predicted_body.expect("the filter's pose");
        assert!((p.translation.vector - nalgebra::Vector3::new(1.0, 2.0, 0.9)).norm() < 1e-12);
        assert!((p.rotation.euler_angles().2 - 0.5).abs() < 1e-12);
        assert_eq!(frame.predicted_sigma_m, Some(0.04));
        // No valid pose: nothing predicted, nothing to be sure of.
        let frame = slam_frame(&f, Some(sensors(sample(2.0, 0.5))), false).expect("a frame");
        assert_eq!(
            (frame.predicted_body, frame.predicted_sigma_m),
            (None, None)
        );
    }

    #[test]
    fn sensor_samples_are_found_by_time() {
        let log = SensorLog::new(1);
        for i in 0..10 {
            log.push(0, sample(f64::from(i) * 0.1, 1.0));
        }
        assert_eq!(log.at(0, 0.42).map(|s| s.sample.t), Some(0.4));
        assert_eq!(log.at(0, 0.46).map(|s| s.sample.t), Some(0.5));
        assert_eq!(log.at(0, -0.1).map(|s| s.sample.t), Some(0.0));
        assert_eq!(log.at(0, 1.1).map(|s| s.sample.t), Some(0.9));
        assert_eq!(log.at(0, 0.42).and_then(|s| s.sample.heading), Some(1.0));
        assert!(log.at(0, 1.5).is_none(), "nothing within 0.25 s");
        assert!(log.at(1, 0.4).is_none(), "no such drone");
    }

    #[test]
    fn a_heading_is_placed_at_its_arrival_not_at_the_tick_that_read_it() {
        let log = SensorLog::new(1);
        // Turning at 0.1 rad/s (under the turning gate); the control loop reads telemetry at
        // 10 Hz, each heading having arrived 70 ms before the tick that read it, and one tick
        // finds no new heading (the one of the tick before, again).
        for i in 0..20 {
            let t = f64::from(i) * 0.1;
            let arrived = if i == 12 { t - 0.17 } else { t - 0.07 };
            let mut s = sample(t, 0.1 * arrived);
            s.heading_t = arrived;
            log.push(0, s);
        }
        // A frame at 1.03 s: the tick nearest it read the heading of 0.93 s; the one that
        // arrived at 1.03 s is the heading then.
        let s = log.at(0, 1.03).expect("a sample");
        assert!((s.sample.t - 1.0).abs() < 1e-9, "{s:?}");
        assert!((s.sample.heading_t - 1.03).abs() < 1e-9, "{s:?}");
        let heading = s.sample.heading.expect("slow enough for the SLAM");
        assert!((heading - 0.103).abs() < 1e-9, "{heading}");
        // The heading read twice counts once: the turn's rate is not doubled into a "fast
        // turn", and the frame at 1.12 s gets the heading of 1.03 s (none arrived at 1.13 s).
        let s = log.at(0, 1.12).expect("a sample");
        assert!((s.sample.heading_t - 1.03).abs() < 1e-9, "{s:?}");
        assert!(s.sample.heading.is_some(), "{s:?}");
        // A slow turn is no prior on the map, wherever its headings are placed.
        assert!(!s.heading_steady);
    }

    #[test]
    fn a_heading_taken_while_turning_fast_only_turns_where_a_lost_drone_is_looked_for() {
        let log = SensorLog::new(1);
        // A look-around: 36°/s, through ±180°.
        let yaw = |t: f64| {
            (3.0 + 0.628 * t + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI
        };
        for i in 0..30 {
            let t = f64::from(i) * 0.1;
            log.push(0, sample(t, yaw(t)));
        }
        for t in [0.0, 0.55, 1.0, 2.9] {
            let s = log.at(0, t).expect("a sample");
            assert!(s.sample.heading.is_none(), "t = {t}: {s:?}");
            assert_eq!(s.sample.height, Some(0.9), "the height stays");
            // The heading that arrived nearest the frame, for the SLAM's relocalisation only.
            let arrived = s.sample.heading_t;
            assert!((t - arrived).abs() <= 0.05 + 1e-9, "t = {t}: {s:?}");
            assert_eq!(s.turning_heading, Some(yaw(arrived)), "t = {t}: {s:?}");
        }
        let f = slam_frame(&camera_frame(0, 1), log.at(0, 1.0), false).expect("a frame");
        assert_eq!((f.heading, f.turning_heading), (None, Some(yaw(1.0))));
        // Then hovering, turning 2°/s: the heading goes to the SLAM again.
        for i in 30..40 {
            log.push(0, sample(f64::from(i) * 0.1, 1.0 + f64::from(i) * 0.0035));
        }
        let s = log.at(0, 3.5).expect("a sample");
        assert!(s.sample.heading.is_some());
        assert_eq!(s.turning_heading, None);
    }

    #[test]
    fn a_heading_is_a_prior_only_once_it_has_been_steady_either_side() {
        let log = SensorLog::new(1);
        // Hovering with the IMU's noise (±0.3°, alternating), then turning at 5°/s from 1 s to
        // 2 s, then hovering again (the log keeps 3 s).
        let noise = |i: i32| if i % 2 == 0 { 0.005 } else { -0.005 };
        let yaw = |t: f64| 0.5 + 0.087 * (t.clamp(1.0, 2.0) - 1.0);
        for i in 0..30 {
            let t = f64::from(i) * 0.1;
            log.push(0, sample(t, yaw(t) + noise(i)));
        }
        let steady = |t: f64| {
            let s = log.at(0, t).expect("a sample");
            assert!(
                s.sample.heading.is_some(),
                "t = {t}: slow enough for the SLAM"
            );
            s.heading_steady
        };
        assert!(steady(0.5), "noise is not a turn");
        // A slow turn (a lag of 0.15 s would put it 0.75° off), under way or just ended: its
        // heading is no prior.
        for t in [0.9, 1.5, 2.2] {
            assert!(!steady(t), "t = {t}");
        }
        assert!(steady(2.5), "steady again");
        assert!(steady(2.9), "the newest sample, nothing after it yet");
    }
}
