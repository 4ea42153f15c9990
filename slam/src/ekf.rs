//! An extended Kalman filter for one multirotor (seed 002 ch. 4): it predicts the vehicle's
//! motion from the sticks the station commands, with the model of a multirotor behind a
//! stabilising flight controller (sticks → lean angles, yaw rate and climb rate, each following
//! with a first-order lag; lean accelerates, drag slows), and corrects it with the SLAM pose,
//! the IMU heading and the rangefinder height. Controllers read a smooth pose at the control
//! rate, between camera frames and through short tracking losses.
//!
//! State: position (x, y, z), velocity (vx, vy, vz), roll, pitch, yaw, yaw rate — map frame,
//! body FLU (+ roll banks right, + pitch noses down, + yaw anticlockwise). Measurements that arrive late (a camera frame processed after its capture)
//! are compared with the state at their capture time and the correction applied now.

use std::collections::VecDeque;

use nalgebra::{SMatrix, SVector};

const N: usize = 10;
type State = SVector<f64, N>;
type Cov = SMatrix<f64, N, N>;

/// Indices into the state.
const PX: usize = 0;
const PY: usize = 1;
const PZ: usize = 2;
const VX: usize = 3;
const VZ: usize = 5;
const ROLL: usize = 6;
const PITCH: usize = 7;
const YAW: usize = 8;
const YAW_RATE: usize = 9;

/// Gravity, m/s².
const G: f64 = 9.81;

/// The vehicle model and the noise of everything.
#[derive(Debug, Clone, PartialEq)]
pub struct EkfConfig {
    /// Lean angle at full roll or pitch stick, radians.
    pub max_lean: f64,
    /// Time constant of the attitude response, seconds.
    pub attitude_tau: f64,
    /// Yaw rate at full yaw stick (+ stick = clockwise), rad/s.
    pub max_yaw_rate: f64,
    /// Time constant of the yaw-rate response, seconds.
    pub yaw_tau: f64,
    /// Climb rate at full throttle (altitude hold), m/s.
    pub max_climb: f64,
    /// Time constant of the climb-rate response, seconds.
    pub climb_tau: f64,
    /// Linear drag, 1/s.
    pub drag: f64,
    /// Process noise: horizontal and vertical acceleration (gusts, model error), m/s² per √s.
    pub accel_noise: (f64, f64),
    /// Process noise of the attitude and yaw rate, rad/s per √s.
    pub attitude_noise: f64,
    /// SLAM position noise (1 σ), metres.
    pub slam_position_sigma: f64,
    /// SLAM yaw noise (1 σ), radians.
    pub slam_yaw_sigma: f64,
    /// A SLAM pose registered on fewer matches than this counts for less: its noise is
    /// [`EkfConfig::slam_position_sigma`] and [`EkfConfig::slam_yaw_sigma`] times this over its
    /// inliers, it is gated like any measurement, and it is never taken as a map correction
    /// (a registration on a dozen matches can be a wrong one that looks right: seen in SITL, two
    /// fixes on 14 and 17 inliers 0.26 and 0.13 m off, shifted in as corrections, flew a drone
    /// into a wall). Linear, not with the root of the count: what few inliers risk is a wrong
    /// match, not more noise.
    pub slam_full_inliers: usize,
    /// IMU heading noise (1 σ), radians.
    pub heading_sigma: f64,
    /// Rangefinder height noise (1 σ), metres.
    pub height_sigma: f64,
    /// Noise of the mean velocity visual odometry measures between two frames (1 σ), m/s…
    pub odometry_velocity_sigma: f64,
    /// …registered on this many inliers or more; on fewer, that noise times this over its
    /// inliers (linear, as [`EkfConfig::slam_full_inliers`]). Measured in SITL against the
    /// simulator's truth (703 registrations of lost drones in 16 main-command missions, stop
    /// 91), the velocity was more than 0.2 m/s off in 23 % of those on 15–19 inliers, 16 % on
    /// 20–24, 9 % on 25–29, 5 % on 30–39, and 1–2 % on 40 or more, whose 90th percentile
    /// (0.11 m/s) is about the noise above. Taken at full weight, such steps set a held drone's
    /// brake against drifts that were not there, beside the wall it was lost facing.
    pub odometry_full_inliers: usize,
    /// Visual odometry measuring a faster motion than this is refused, m/s: an indoor drone
    /// never flies that fast (ours at most 0.5 m/s), so it is a wrong registration (in SITL, a
    /// lost drone's step of 0.15 m in 0.1 s, taken as 1.2 m/s just after the loss had widened
    /// the velocity's uncertainty, set the brake against a drift that was not there: 5 of 156
    /// collisions in traced missions came within 3 s of a step faster than 1 m/s).
    pub odometry_max_speed: f64,
    /// Attitude (roll, pitch) noise of the flight controller's estimate, radians.
    pub attitude_sigma: f64,
    /// Measurements whose normalised innovation² exceeds this are outliers (a yaw spike, a
    /// table under the sonar).
    pub gate_chi2: f64,
    /// The pose is valid while the position's standard deviation stays below this, metres.
    pub max_position_sigma: f64,
    /// The horizontal velocity is known while its standard deviation stays below this, m/s:
    /// visual odometry measures it while the position is lost (0.1 m/s each, but 0.3–0.4 s
    /// late: about 0.3 m/s by now, with the gusts the model allows for); on the model alone it
    /// grows past this in about a second.
    pub max_velocity_sigma: f64,
    /// A SLAM fix this far (metres) and five standard deviations from a valid estimate is
    /// refused: loop-closure corrections are real jumps but bounded, a wild pose is not.
    pub max_slam_jump_m: f64,
    /// While the rangefinder holds the height, a SLAM fix further than this (metres) from it is
    /// refused: a registration that wrong in height is wrong (a repeated pattern matched a
    /// block up or down), not a map correction, and taking it as one would fly the vehicle
    /// into the floor.
    pub max_slam_height_error_m: f64,
}

impl Default for EkfConfig {
    fn default() -> Self {
        Self {
            max_lean: 20f64.to_radians(),
            attitude_tau: 0.15,
            max_yaw_rate: 90f64.to_radians(),
            yaw_tau: 0.1,
            max_climb: 1.0,
            climb_tau: 0.3,
            drag: 0.6,
            accel_noise: (0.5, 0.3),
            attitude_noise: 0.2,
            slam_position_sigma: 0.03,
            slam_yaw_sigma: 1.5f64.to_radians(),
            slam_full_inliers: 60,
            heading_sigma: 1f64.to_radians(),
            height_sigma: 0.03,
            odometry_velocity_sigma: 0.1,
            odometry_full_inliers: 40,
            odometry_max_speed: 1.0,
            attitude_sigma: 1f64.to_radians(),
            gate_chi2: 16.0,
            max_position_sigma: 0.35,
            max_velocity_sigma: 0.4,
            max_slam_jump_m: 2.0,
            max_slam_height_error_m: 0.3,
        }
    }
}

/// The sticks as the model reads them: −1…1 each (+ roll = right, + pitch = forward,
/// + yaw = clockwise, + throttle = climb).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Input {
    /// Roll stick.
    pub roll: f64,
    /// Pitch stick.
    pub pitch: f64,
    /// Yaw stick.
    pub yaw: f64,
    /// Throttle stick (altitude hold: climb rate).
    pub throttle: f64,
}

/// The filtered pose for controllers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Position in the map, metres.
    pub position: [f64; 3],
    /// Velocity in the map, m/s.
    pub velocity: [f64; 3],
    /// Roll, pitch, yaw, radians.
    pub attitude: [f64; 3],
    /// Yaw rate, rad/s.
    pub yaw_rate: f64,
    /// Standard deviation of the horizontal position, metres.
    pub position_sigma: f64,
    /// Standard deviation of the horizontal velocity, m/s.
    pub velocity_sigma: f64,
}

/// What a measurement did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Update {
    /// Used.
    Applied,
    /// Rejected by the innovation gate.
    Outlier,
    /// A SLAM pose too far from the estimate to be noise, taken as a correction of the map
    /// (after a loop closure): position and heading moved to it, velocity kept.
    Corrected,
    /// The filter has no fix yet, or the measurement is older than the history.
    Ignored,
}

/// A displacement measured along one horizontal direction only, as the depth of a blank wall
/// measures it (how far the body moved toward it, nothing of how far along it):
/// [`Ekf::update_odometry_along`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Along {
    /// The direction, a unit vector (forward, left) in the body's levelled frame at the earlier
    /// frame.
    pub direction: [f64; 2],
    /// How far the body moved along it, metres.
    pub displacement: f64,
    /// Its noise (1 σ), metres.
    pub sigma: f64,
}

/// The filter of one vehicle.
#[derive(Debug, Clone)]
pub struct Ekf {
    config: EkfConfig,
    x: State,
    p: Cov,
    t: f64,
    input: Input,
    /// A SLAM fix has initialised the horizontal state.
    fixed: bool,
    /// Recent (time, state), to compare late measurements with.
    history: VecDeque<(f64, State)>,
    outliers: u64,
    /// When a rangefinder height was last taken.
    height_at: Option<f64>,
    /// What the filter was told over the last seconds, with the filter after each prediction:
    /// a late SLAM fix is applied where it belongs and what came after it is replayed.
    journal: VecDeque<Entry>,
    /// Replaying the journal (a late fix met on the way is not replayed again).
    replaying: bool,
}

/// One call the filter had, to replay.
#[derive(Debug, Clone, Copy)]
enum Op {
    Predict(f64),
    Input(Input),
    Slam {
        t: f64,
        position: [f64; 3],
        yaw: f64,
        inliers: Option<usize>,
    },
    Heading {
        t: f64,
        yaw: f64,
    },
    Height {
        t: f64,
        height: f64,
    },
    Attitude {
        t: f64,
        roll: f64,
        pitch: f64,
    },
    Odometry {
        since: f64,
        t: f64,
        displacement: [f64; 2],
        inliers: Option<usize>,
    },
    OdometryAlong {
        since: f64,
        t: f64,
        along: [Along; 2],
        count: usize,
    },
}

/// A journal entry: the call, and after a prediction the filter as it then was (its journal
/// left out).
#[derive(Debug, Clone)]
struct Entry {
    op: Op,
    after: Option<Box<Ekf>>,
}

/// No state speed beyond this, m/s.
const MAX_SPEED: f64 = 10.0;

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

impl Ekf {
    /// A filter for a vehicle resting at `position` facing `yaw`, at time `t` (seconds). Until
    /// the first SLAM fix its horizontal position counts as unknown.
    pub fn new(config: EkfConfig, t: f64, position: [f64; 3], yaw: f64) -> Self {
        let mut x = State::zeros();
        x[PX] = position[0];
        x[PY] = position[1];
        x[PZ] = position[2];
        x[YAW] = yaw;
        let mut p = Cov::identity() * 1e-4;
        for i in [PX, PY] {
            p[(i, i)] = 100.0;
        }
        p[(YAW, YAW)] = 1.0;
        Self {
            config,
            x,
            p,
            t,
            input: Input::default(),
            fixed: false,
            history: VecDeque::new(),
            outliers: 0,
            height_at: None,
            journal: VecDeque::new(),
            replaying: false,
        }
    }

    /// The filter as it is, without its journal (a point to replay from).
    fn snapshot(&mut self) -> Ekf {
        let journal = std::mem::take(&mut self.journal);
        let mut copy = self.clone();
        copy.replaying = false;
        self.journal = journal;
        copy
    }

    /// Notes a call in the journal and forgets what is older than the history.
    fn record(&mut self, op: Op) {
        let after = matches!(op, Op::Predict(_)).then(|| Box::new(self.snapshot()));
        self.journal.push_back(Entry { op, after });
        // Kept: from the last prediction more than two seconds old (a base to replay from).
        let oldest = self.t - 2.0;
        if let Some(i) = self
            .journal
            .iter()
            .rposition(|e| e.after.as_ref().is_some_and(|a| a.t < oldest))
        {
            self.journal.drain(..i);
        }
    }

    /// Makes a call again (replaying); what a measurement did.
    fn apply(&mut self, op: Op) -> Option<Update> {
        match op {
            Op::Predict(t) => self.predict(t),
            Op::Input(i) => self.set_input(i),
            Op::Slam {
                t,
                position,
                yaw,
                inliers,
            } => return Some(self.update_slam_on(t, position, yaw, inliers)),
            Op::Heading { t, yaw } => return Some(self.update_heading(t, yaw)),
            Op::Height { t, height } => return Some(self.update_height(t, height)),
            Op::Attitude { t, roll, pitch } => {
                return Some(self.update_attitude(t, roll, pitch));
            }
            Op::Odometry {
                since,
                t,
                displacement,
                inliers,
            } => return Some(self.update_odometry_on(since, t, displacement, inliers)),
            Op::OdometryAlong {
                since,
                t,
                along,
                count,
            } => return Some(self.update_odometry_along(since, t, &along[..count])),
        }
        None
    }

    /// A measurement older than the state (taken at `t`): back to the filter as it was then,
    /// the measurement applied there, then every later call replayed (a SLAM fix 0.3 s late
    /// corrects the past it measured, and the prediction carries the correction forward with
    /// the covariance it should have). `None` when the journal does not reach back that far.
    fn replay_with(&mut self, t: f64, measurement: Op) -> Option<Update> {
        let i = self
            .journal
            .iter()
            .rposition(|e| e.after.as_ref().is_some_and(|a| a.t <= t + 1e-6))?;
        let base = self.journal[i].after.as_deref()?.clone();
        let later: Vec<Op> = self.journal.drain(i + 1..).map(|e| e.op).collect();
        let journal = std::mem::take(&mut self.journal);
        let outliers = self.outliers;
        *self = base;
        self.journal = journal;
        self.replaying = true;
        self.predict(t);
        let before = self.outliers;
        let update = self.apply(measurement).unwrap_or(Update::Ignored);
        let refused = self.outliers - before;
        for op in later {
            self.apply(op);
        }
        self.replaying = false;
        // Replayed measurements were counted the first time.
        self.outliers = outliers + refused;
        Some(update)
    }

    /// The settings.
    pub fn config(&self) -> &EkfConfig {
        &self.config
    }

    /// Time of the state, seconds.
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Measurements rejected so far.
    pub fn outliers(&self) -> u64 {
        self.outliers
    }

    /// The estimate now.
    pub fn estimate(&self) -> Estimate {
        Estimate {
            position: [self.x[PX], self.x[PY], self.x[PZ]],
            velocity: [self.x[VX], self.x[VX + 1], self.x[VZ]],
            attitude: [self.x[ROLL], self.x[PITCH], wrap(self.x[YAW])],
            yaw_rate: self.x[YAW_RATE],
            position_sigma: (0.5 * (self.p[(PX, PX)] + self.p[(PY, PY)]))
                .max(0.0)
                .sqrt(),
            velocity_sigma: (0.5 * (self.p[(VX, VX)] + self.p[(VX + 1, VX + 1)]))
                .max(0.0)
                .sqrt(),
        }
    }

    /// The estimate, if good enough to fly on: a SLAM fix was had and the horizontal
    /// uncertainty has not grown past [`EkfConfig::max_position_sigma`] since.
    pub fn valid_estimate(&self) -> Option<Estimate> {
        self.estimate_within(self.config.max_position_sigma)
    }

    /// The estimate if a SLAM fix was had and the horizontal uncertainty is at most
    /// `max_position_sigma` metres since: [`Ekf::valid_estimate`] with another bound, for a use
    /// that tolerates more than flying does (choosing a frontier to fly to).
    pub fn estimate_within(&self, max_position_sigma: f64) -> Option<Estimate> {
        let e = self.estimate();
        (self.fixed && e.position_sigma <= max_position_sigma).then_some(e)
    }

    /// The horizontal velocity in the map (m/s), if known well enough to fly on
    /// ([`EkfConfig::max_velocity_sigma`]) — also after the position is lost, as long as
    /// something (visual odometry) measures it.
    pub fn valid_velocity(&self) -> Option<[f64; 2]> {
        let e = self.estimate();
        (self.fixed && e.velocity_sigma <= self.config.max_velocity_sigma)
            .then_some([e.velocity[0], e.velocity[1]])
    }

    /// Sets the sticks in force from now on.
    pub fn set_input(&mut self, input: Input) {
        self.input = input;
        self.record(Op::Input(input));
    }

    /// A stick as the vehicle flies it (the link sends it past the flight controller's dead
    /// zone: `link::rc`).
    fn stick(&self, v: f64) -> f64 {
        v.clamp(-1.0, 1.0)
    }

    /// The state's time derivative under the current input.
    fn derivative(&self, x: &State) -> State {
        let c = &self.config;
        let u = self.input;
        let mut dx = State::zeros();
        let (roll_t, pitch_t) = (
            self.stick(u.roll) * c.max_lean,
            self.stick(u.pitch) * c.max_lean,
        );
        let rate_t = -self.stick(u.yaw) * c.max_yaw_rate;
        let climb_t = self.stick(u.throttle) * c.max_climb;
        let (s, co) = x[YAW].sin_cos();
        let a_fwd = G * x[PITCH].tan();
        let a_left = -G * x[ROLL].tan();
        dx[PX] = x[VX];
        dx[PY] = x[VX + 1];
        dx[PZ] = x[VZ];
        dx[VX] = a_fwd * co - a_left * s - c.drag * x[VX];
        dx[VX + 1] = a_fwd * s + a_left * co - c.drag * x[VX + 1];
        dx[VZ] = (climb_t - x[VZ]) / c.climb_tau;
        dx[ROLL] = (roll_t - x[ROLL]) / c.attitude_tau;
        dx[PITCH] = (pitch_t - x[PITCH]) / c.attitude_tau;
        dx[YAW] = x[YAW_RATE];
        dx[YAW_RATE] = (rate_t - x[YAW_RATE]) / c.yaw_tau;
        dx
    }

    /// Advances the state to time `t` (seconds; earlier times are ignored).
    pub fn predict(&mut self, t: f64) {
        let mut remaining = t - self.t;
        if !(remaining.is_finite() && remaining > 0.0) {
            return;
        }
        // Steps short against the fastest time constant.
        while remaining > 1e-9 {
            let dt = remaining.min(0.02);
            remaining -= dt;
            let f = self.jacobian(dt);
            self.x += self.derivative(&self.x) * dt;
            self.x[YAW] = wrap(self.x[YAW]);
            let mut q = Cov::zeros();
            let (ah, av) = self.config.accel_noise;
            q[(VX, VX)] = ah * ah * dt;
            q[(VX + 1, VX + 1)] = ah * ah * dt;
            q[(VZ, VZ)] = av * av * dt;
            let an = self.config.attitude_noise;
            for i in [ROLL, PITCH, YAW_RATE] {
                q[(i, i)] = an * an * dt;
            }
            q[(YAW, YAW)] = 0.01 * an * an * dt;
            self.p = f * self.p * f.transpose() + q;
            // The last step lands on `t` exactly (summed steps drift by an ulp or so).
            self.t = if remaining > 1e-9 { self.t + dt } else { t };
            self.keep_physical();
            self.history.push_back((self.t, self.x));
        }
        while self.history.front().is_some_and(|(h, _)| self.t - h > 2.0) {
            self.history.pop_front();
        }
        self.record(Op::Predict(t));
    }

    /// Keeps the state physical whatever the measurements did: lean within twice the flight
    /// controller's limit, speeds within what a multirotor reaches indoors. A state that went
    /// non-finite is dropped: the filter waits for the next SLAM fix.
    fn keep_physical(&mut self) {
        if !(self.x.iter().all(|v| v.is_finite()) && self.p.iter().all(|v| v.is_finite())) {
            let (t, input) = (self.t, self.input);
            *self = Self::new(self.config.clone(), t, [0.0; 3], 0.0);
            self.input = input;
            return;
        }
        let lean = 2.0 * self.config.max_lean;
        for i in [ROLL, PITCH] {
            self.x[i] = self.x[i].clamp(-lean, lean);
        }
        for i in [VX, VX + 1, VZ] {
            self.x[i] = self.x[i].clamp(-MAX_SPEED, MAX_SPEED);
        }
    }

    /// ∂(x + f(x)·dt)/∂x by central differences.
    fn jacobian(&self, dt: f64) -> Cov {
        let mut f = Cov::identity();
        for j in 0..N {
            let h = 1e-6;
            let (mut a, mut b) = (self.x, self.x);
            a[j] += h;
            b[j] -= h;
            let d = (self.derivative(&a) - self.derivative(&b)) / (2.0 * h);
            for i in 0..N {
                f[(i, j)] += d[i] * dt;
            }
        }
        f
    }

    /// The state at time `t`, interpolated in the history (the current state for `t` now or
    /// later); `None` before the history.
    fn state_at(&self, t: f64) -> Option<State> {
        if t >= self.t - 1e-6 {
            return Some(self.x);
        }
        let after = self.history.iter().position(|(h, _)| *h >= t)?;
        let (t1, x1) = self.history[after];
        let Some(&(t0, x0)) = after.checked_sub(1).and_then(|i| self.history.get(i)) else {
            return (t1 - t < 1e-6).then_some(x1);
        };
        let a = ((t - t0) / (t1 - t0).max(1e-9)).clamp(0.0, 1.0);
        let mut x = x0 + (x1 - x0) * a;
        x[YAW] = wrap(x0[YAW] + wrap(x1[YAW] - x0[YAW]) * a);
        Some(x)
    }

    /// A measurement of some state components: `rows` pick them, `z` the values, `r` the
    /// variances, `angular` which rows are angles; taken at time `t`.
    fn update<const M: usize>(
        &mut self,
        t: f64,
        rows: [usize; M],
        z: [f64; M],
        r: [f64; M],
        angular: [bool; M],
        force: bool,
    ) -> Update {
        let mut h = SMatrix::<f64, M, N>::zeros();
        for k in 0..M {
            h[(k, rows[k])] = 1.0;
        }
        self.update_linear(t, h, z, r, angular, force)
    }

    /// A measurement `z` of the linear combinations of the state that the rows of `h` take,
    /// with variances `r`; `angular` marks rows that are angles; taken at time `t`.
    fn update_linear<const M: usize>(
        &mut self,
        t: f64,
        h: SMatrix<f64, M, N>,
        z: [f64; M],
        r: [f64; M],
        angular: [bool; M],
        force: bool,
    ) -> Update {
        if !(t.is_finite() && z.iter().all(|v| v.is_finite()) && h.iter().all(|v| v.is_finite())) {
            return Update::Ignored;
        }
        let Some(then) = self.state_at(t) else {
            return Update::Ignored;
        };
        let predicted = h * then;
        let mut y = SVector::<f64, M>::zeros();
        let mut rm = SMatrix::<f64, M, M>::zeros();
        for k in 0..M {
            let d = z[k] - predicted[k];
            y[k] = if angular[k] { wrap(d) } else { d };
            rm[(k, k)] = r[k];
        }
        let s = h * self.p * h.transpose() + rm;
        let Some(s_inv) = s.try_inverse() else {
            return Update::Ignored;
        };
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        if !force && nis > self.config.gate_chi2 * M as f64 {
            self.outliers += 1;
            return Update::Outlier;
        }
        let k = self.p * h.transpose() * s_inv;
        self.x += k * y;
        self.x[YAW] = wrap(self.x[YAW]);
        let i_kh = Cov::identity() - k * h;
        // Joseph form: stays symmetric and positive.
        self.p = i_kh * self.p * i_kh.transpose() + k * rm * k.transpose();
        self.keep_physical();
        Update::Applied
    }

    /// A body pose from SLAM (position and yaw), captured at time `t` (a fix older than the
    /// state is applied at its time and what came after it replayed).
    pub fn update_slam(&mut self, t: f64, position: [f64; 3], yaw: f64) -> Update {
        self.update_slam_on(t, position, yaw, None)
    }

    /// A SLAM pose as [`Ekf::update_slam`], registered on `inliers` matches if known (a
    /// relocalisation, a known start: full weight); on fewer than
    /// [`EkfConfig::slam_full_inliers`] it counts for less.
    pub fn update_slam_on(
        &mut self,
        t: f64,
        position: [f64; 3],
        yaw: f64,
        inliers: Option<usize>,
    ) -> Update {
        let op = Op::Slam {
            t,
            position,
            yaw,
            inliers,
        };
        if !self.replaying
            && t < self.t - 1e-6
            && let Some(update) = self.replay_with(t, op)
        {
            return update;
        }
        let update = self.slam_now(t, position, yaw, inliers);
        self.record(op);
        update
    }

    fn slam_now(&mut self, t: f64, position: [f64; 3], yaw: f64, inliers: Option<usize>) -> Update {
        let full = self.config.slam_full_inliers;
        let weak = inliers.is_some_and(|n| n < full);
        let scale = inliers.map_or(1.0, |n| full as f64 / n.clamp(1, full) as f64);
        let (sp, sy) = (
            (scale * self.config.slam_position_sigma).powi(2),
            (scale * self.config.slam_yaw_sigma).powi(2),
        );
        // Not gated by the innovation test: the SLAM's corrections after a loop closure are
        // real jumps, and a filter that refused them would fly on its own drift from then on.
        // Only what no correction can be (metres away from a confident estimate) is refused.
        if let Some(e) = self.valid_estimate() {
            let jump = (position[0] - e.position[0]).hypot(position[1] - e.position[1]);
            if jump > self.config.max_slam_jump_m.max(5.0 * e.position_sigma) {
                self.outliers += 1;
                return Update::Outlier;
            }
        }
        let z = [position[0], position[1], position[2], yaw];
        if self.height_at.is_some_and(|h| (t - h).abs() < 1.0)
            && let Some(then) = self.state_at(t)
            && (position[2] - then[PZ]).abs() > self.config.max_slam_height_error_m
        {
            self.outliers += 1;
            return Update::Outlier;
        }
        if self.fixed
            && !weak
            && let Some(then) = self.state_at(t)
        {
            // Innovation against the state when the pose was taken, in the measurement's own
            // standard deviations: far beyond noise, the map moved (a loop closure), not the
            // vehicle. A Kalman update would read the jump as motion and wind it into the
            // velocity; shift the estimate instead.
            let rows = [PX, PY, PZ, YAW];
            let mut y = [0.0; 4];
            for (i, &row) in rows.iter().enumerate() {
                y[i] = z[i] - then[row];
            }
            y[3] = wrap(y[3]);
            let normalised = (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) / sp + y[3] * y[3] / sy;
            if normalised > self.config.gate_chi2 * 4.0 {
                for (i, &row) in rows.iter().enumerate() {
                    self.x[row] += y[i];
                }
                self.x[YAW] = wrap(self.x[YAW]);
                for h in &mut self.history {
                    for (i, &row) in rows.iter().enumerate() {
                        h.1[row] += y[i];
                    }
                    h.1[YAW] = wrap(h.1[YAW]);
                }
                for (&row, r) in rows.iter().zip([sp, sp, sp, sy]) {
                    for j in 0..N {
                        self.p[(row, j)] = 0.0;
                        self.p[(j, row)] = 0.0;
                    }
                    self.p[(row, row)] = r;
                }
                return Update::Corrected;
            }
        }
        let u = self.update(
            t,
            [PX, PY, PZ, YAW],
            z,
            [sp, sp, sp, sy],
            [false, false, false, true],
            !weak,
        );
        if u == Update::Applied {
            self.fixed = true;
        }
        u
    }

    /// Visual odometry while the SLAM cannot place the vehicle: between times `since` and `t`
    /// its body moved `displacement` (forward, left; metres, in the body's frame at `since`).
    /// Taken as the mean horizontal velocity over the interval, at its middle: it keeps the
    /// position from drifting on the model alone, but does not fix it (its uncertainty still
    /// grows, slowly). A measurement older than the state is applied where it belongs.
    pub fn update_odometry(&mut self, since: f64, t: f64, displacement: [f64; 2]) -> Update {
        self.update_odometry_on(since, t, displacement, None)
    }

    /// Visual odometry as [`Ekf::update_odometry`], registered on `inliers` matches if known;
    /// on fewer than [`EkfConfig::odometry_full_inliers`] it counts for less.
    pub fn update_odometry_on(
        &mut self,
        since: f64,
        t: f64,
        displacement: [f64; 2],
        inliers: Option<usize>,
    ) -> Update {
        let dt = t - since;
        if !(dt > 1e-3 && dt.is_finite() && displacement.iter().all(|d| d.is_finite())) {
            return Update::Ignored;
        }
        let mid = since + 0.5 * dt;
        let op = Op::Odometry {
            since,
            t,
            displacement,
            inliers,
        };
        if !self.replaying
            && mid < self.t - 1e-6
            && let Some(update) = self.replay_with(mid, op)
        {
            return update;
        }
        let update = match self.state_at(since) {
            Some(then) => {
                let (s, c) = then[YAW].sin_cos();
                let [forward, left] = displacement;
                let velocity = [(c * forward - s * left) / dt, (s * forward + c * left) / dt];
                let full = self.config.odometry_full_inliers;
                let scale = inliers.map_or(1.0, |n| full as f64 / n.clamp(1, full) as f64);
                let r = (scale * self.config.odometry_velocity_sigma).powi(2);
                if velocity[0].hypot(velocity[1]) > self.config.odometry_max_speed {
                    Update::Outlier
                } else {
                    self.update(mid, [VX, VX + 1], velocity, [r, r], [false, false], false)
                }
            }
            None => Update::Ignored,
        };
        self.record(op);
        update
    }

    /// Odometry that measured the body's motion between times `since` and `t` only along some
    /// directions ([`Along`]; at most two, the horizontal plane's): the depth of a blank wall
    /// measures how far the body moved toward it and nothing of how far along it. Each is
    /// taken as the mean velocity along its direction over the interval, at its middle, so the
    /// filter knows the drift toward the wall while the rest stays on its model. A
    /// measurement older than the state is applied where it belongs.
    pub fn update_odometry_along(&mut self, since: f64, t: f64, along: &[Along]) -> Update {
        let dt = t - since;
        let count = along.len();
        let finite = along.iter().all(|a| {
            a.direction[0].hypot(a.direction[1]) > 1e-6
                && a.displacement.is_finite()
                && a.sigma.is_finite()
                && a.sigma > 0.0
        });
        if !(dt > 1e-3 && dt.is_finite() && (1..=2).contains(&count) && finite) {
            return Update::Ignored;
        }
        let mid = since + 0.5 * dt;
        let mut kept = [Along::default(); 2];
        kept[..count].copy_from_slice(along);
        let op = Op::OdometryAlong {
            since,
            t,
            along: kept,
            count,
        };
        if !self.replaying
            && mid < self.t - 1e-6
            && let Some(update) = self.replay_with(mid, op)
        {
            return update;
        }
        let update = match self.state_at(since) {
            Some(then) => {
                let (s, c) = then[YAW].sin_cos();
                let row = |a: &Along| {
                    let [forward, left] = a.direction;
                    let norm = forward.hypot(left).max(1e-9);
                    let mut h = SMatrix::<f64, 1, N>::zeros();
                    h[(0, VX)] = (c * forward - s * left) / norm;
                    h[(0, VX + 1)] = (s * forward + c * left) / norm;
                    (h, a.displacement / norm / dt, (a.sigma / norm / dt).powi(2))
                };
                let fast = kept[..count]
                    .iter()
                    .any(|a| row(a).1.abs() > self.config.odometry_max_speed);
                if fast {
                    Update::Outlier
                } else if count == 1 {
                    let (h, z, r) = row(&kept[0]);
                    self.update_linear(mid, h, [z], [r], [false], false)
                } else {
                    let ((h0, z0, r0), (h1, z1, r1)) = (row(&kept[0]), row(&kept[1]));
                    let mut h = SMatrix::<f64, 2, N>::zeros();
                    h.set_row(0, &h0.row(0));
                    h.set_row(1, &h1.row(0));
                    self.update_linear(mid, h, [z0, z1], [r0, r1], [false; 2], false)
                }
            }
            None => Update::Ignored,
        };
        self.record(op);
        update
    }

    /// The IMU heading.
    pub fn update_heading(&mut self, t: f64, yaw: f64) -> Update {
        let r = self.config.heading_sigma.powi(2);
        let update = self.update(t, [YAW], [yaw], [r], [true], false);
        self.record(Op::Heading { t, yaw });
        update
    }

    /// The rangefinder's height above the floor.
    pub fn update_height(&mut self, t: f64, height: f64) -> Update {
        let r = self.config.height_sigma.powi(2);
        let u = self.update(t, [PZ], [height], [r], [false], false);
        if u == Update::Applied {
            self.height_at = Some(t);
        }
        self.record(Op::Height { t, height });
        u
    }

    /// The flight controller's roll and pitch.
    pub fn update_attitude(&mut self, t: f64, roll: f64, pitch: f64) -> Update {
        let r = self.config.attitude_sigma.powi(2);
        let update = self.update(t, [ROLL, PITCH], [roll, pitch], [r, r], [true, true], false);
        self.record(Op::Attitude { t, roll, pitch });
        update
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same model as the filter, integrated finely: the truth to compare with.
    fn truth_run(config: &EkfConfig, input: Input, seconds: f64) -> State {
        let mut e = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 1.0], 0.3);
        e.set_input(input);
        let mut t = 0.0;
        while t < seconds {
            t += 0.001;
            e.x += e.derivative(&e.x) * 0.001;
        }
        e.x
    }

    #[test]
    fn forward_stick_accelerates_to_the_drag_limited_speed() {
        let config = EkfConfig::default();
        let input = Input {
            pitch: 0.5,
            ..Input::default()
        };
        let x = truth_run(&config, input, 15.0);
        // Lean half of 20° (the link sends the stick past the autopilot's dead zone), speed
        // g·tan(lean)/drag along the heading 0.3 rad.
        let lean = 0.5 * 20f64.to_radians();
        let speed = G * lean.tan() / config.drag;
        assert!((x[PITCH] - lean).abs() < 1e-6);
        assert!((x[VX].hypot(x[VX + 1]) - speed).abs() < 0.01, "{}", x[VX]);
        assert!((x[VX + 1].atan2(x[VX]) - 0.3).abs() < 1e-3);
    }

    #[test]
    fn slam_fixes_track_a_moving_vehicle_and_dead_reckoning_bridges_a_gap() {
        let config = EkfConfig::default();
        let input = Input {
            pitch: 0.3,
            yaw: -0.2,
            ..Input::default()
        };
        // Truth: the model itself, finely integrated, sampled every 0.1 s.
        let mut truth = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 1.0], 0.0);
        truth.set_input(input);
        let mut ekf = Ekf::new(config.clone(), 0.0, [0.5, -0.5, 1.0], 0.2);
        ekf.set_input(input);
        assert!(ekf.valid_estimate().is_none(), "no fix yet");
        for step in 1..=100 {
            let t = step as f64 * 0.1;
            while truth.t < t - 1e-9 {
                let dt = 0.001;
                truth.x += truth.derivative(&truth.x) * dt;
                truth.t += dt;
            }
            ekf.predict(t);
            // Camera fixes for 6 s, then none (tracking lost) for 1 s, then fixes again.
            if !(6.0..7.0).contains(&t) {
                ekf.update_slam(t, [truth.x[PX], truth.x[PY], truth.x[PZ]], truth.x[YAW]);
            }
            ekf.update_heading(t, truth.x[YAW]);
            if (6.0..7.0).contains(&t) {
                let e = ekf.valid_estimate().expect("a 1 s gap stays within bounds");
                let err = (e.position[0] - truth.x[PX]).hypot(e.position[1] - truth.x[PY]);
                assert!(err < 0.15, "dead reckoning drifted {err:.3} m at {t:.1} s");
            }
        }
        let e = ekf.valid_estimate().expect("valid");
        let err = (e.position[0] - truth.x[PX]).hypot(e.position[1] - truth.x[PY]);
        assert!(err < 0.02, "{err}");
        let v_err = (e.velocity[0] - truth.x[VX]).hypot(e.velocity[1] - truth.x[VX + 1]);
        assert!(v_err < 0.1, "velocity {v_err}");
    }

    #[test]
    fn odometry_along_two_square_directions_is_visual_odometry() {
        // Two perpendicular directions measured alike are the whole plane: the same update as a
        // displacement measured in full, whichever way the pair is turned.
        let config = EkfConfig::default();
        let start = || {
            let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 0.9], 0.7);
            ekf.update_slam(0.0, [0.0, 0.0, 0.9], 0.7);
            for step in 1..=10 {
                ekf.predict(f64::from(step) * 0.1);
            }
            ekf
        };
        let (forward, left) = (0.02, -0.01);
        let mut full = start();
        assert_eq!(
            full.update_odometry(0.9, 1.0, [forward, left]),
            Update::Applied
        );
        let sigma = config.odometry_velocity_sigma * 0.1;
        let (s, c) = 0.4f64.sin_cos();
        let along = [
            Along {
                direction: [c, s],
                displacement: c * forward + s * left,
                sigma,
            },
            Along {
                direction: [-s, c],
                displacement: -s * forward + c * left,
                sigma,
            },
        ];
        let mut split = start();
        assert_eq!(
            split.update_odometry_along(0.9, 1.0, &along),
            Update::Applied
        );
        assert!((full.x - split.x).norm() < 1e-9, "{} {}", full.x, split.x);
        assert!((full.p - split.p).norm() < 1e-9);
    }

    #[test]
    fn odometry_along_a_wall_normal_measures_the_drift_toward_the_wall_and_nothing_else() {
        // Lost facing a blank wall, sticks centred, a draught carries the drone 0.12 m/s
        // toward the wall and 0.1 m/s along it. The wall's depth measures only the first
        // (each frame's step 0.3 s late, 2 mm of noise): the filter knows the drift toward the
        // wall, and does not make up the drift along it; without the wall's
        // depth it knows neither.
        let config = EkfConfig::default();
        let yaw: f64 = 0.4;
        let (s, c) = yaw.sin_cos();
        let toward = 0.12;
        let run = |measure: bool| {
            let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 0.9], yaw);
            ekf.update_slam(0.0, [0.0, 0.0, 0.9], yaw);
            for step in 1..=60 {
                let t = f64::from(step) * 0.1;
                ekf.predict(t);
                ekf.update_heading(t, yaw);
                if measure && t >= 0.5 {
                    let noise = 0.002 * (f64::from(step) * 2.39).sin();
                    let along = Along {
                        direction: [1.0, 0.0],
                        displacement: toward * 0.1 + noise,
                        sigma: 0.003,
                    };
                    assert_ne!(
                        ekf.update_odometry_along(t - 0.4, t - 0.3, &[along]),
                        Update::Ignored
                    );
                }
            }
            let v = ekf.estimate().velocity;
            (c * v[0] + s * v[1], -s * v[0] + c * v[1])
        };
        let (measured_toward, measured_sideways) = run(true);
        // (The model, which knows no draught, pulls it toward rest between measurements that
        // come 0.3 s late: about a third low, as with visual odometry.)
        assert!((measured_toward - toward).abs() < 0.05, "{measured_toward}");
        assert!(measured_sideways.abs() < 0.02, "{measured_sideways}");
        let (unmeasured, _) = run(false);
        assert!(unmeasured.abs() < 0.02, "{unmeasured}");
        // A step faster than a drone flies along it is refused, and a third direction in the
        // plane or a direction of no length is no measurement.
        let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 0.9], yaw);
        ekf.update_slam(0.0, [0.0, 0.0, 0.9], yaw);
        ekf.predict(1.0);
        let step = |displacement: f64| Along {
            direction: [0.0, 1.0],
            displacement,
            sigma: 0.003,
        };
        assert_eq!(
            ekf.update_odometry_along(0.9, 1.0, &[step(0.15)]),
            Update::Outlier
        );
        assert_eq!(
            ekf.update_odometry_along(0.9, 1.0, &[step(0.0); 3]),
            Update::Ignored
        );
        let no_sigma = Along {
            sigma: 0.0,
            ..step(0.01)
        };
        let nowhere = Along {
            direction: [0.0; 2],
            ..step(0.01)
        };
        for along in [no_sigma, nowhere] {
            assert_eq!(
                ekf.update_odometry_along(0.9, 1.0, &[along]),
                Update::Ignored
            );
        }
    }

    #[test]
    fn visual_odometry_faster_than_a_drone_flies_is_refused() {
        // Hovering, its last SLAM fix 2 s old (the velocity's uncertainty wide, as just after
        // a loss): a step of 0.15 m in 0.1 s (1.5 m/s) is a wrong registration, not a motion.
        let config = EkfConfig::default();
        let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 0.9], 0.0);
        ekf.update_slam(0.0, [0.0, 0.0, 0.9], 0.0);
        for step in 1..=20 {
            let t = f64::from(step) * 0.1;
            ekf.predict(t);
            ekf.update_heading(t, 0.0);
            ekf.update_height(t, 0.9);
        }
        ekf.predict(2.1);
        assert_eq!(
            ekf.update_odometry(2.0, 2.1, [0.12, -0.09]),
            Update::Outlier
        );
        let v = ekf.estimate().velocity;
        assert!(v[0].hypot(v[1]) < 0.05, "velocity {v:?}");
        // A drift of 0.3 m/s is measured as ever.
        ekf.predict(2.2);
        assert_eq!(ekf.update_odometry(2.1, 2.2, [0.03, 0.0]), Update::Applied);
        assert!(
            ekf.estimate().velocity[0] > 0.1,
            "{:?}",
            ekf.estimate().velocity
        );
    }

    #[test]
    fn visual_odometry_on_few_inliers_counts_for_less() {
        // Hovering on SLAM fixes at 10 Hz, then lost and held still on visual odometry: one
        // registration says the body moved 6 cm in 0.1 s (0.6 m/s, within what a drone flies,
        // so not refused). On the inliers of a sound registration the filter takes most of
        // it; on the 15 of a weak one, whose velocity is more than 0.2 m/s off in one of four
        // (SITL, stop 91), far less.
        let config = EkfConfig::default();
        let velocity_after = |inliers: Option<usize>| {
            let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 0.9], 0.0);
            for step in 0..=20 {
                let t = f64::from(step) * 0.1;
                ekf.predict(t);
                ekf.update_heading(t, 0.0);
                ekf.update_height(t, 0.9);
                ekf.update_slam(t, [0.0, 0.0, 0.9], 0.0);
            }
            // Still, by visual odometry on the full inliers, then the wrong step.
            for step in 21..=25 {
                let t = f64::from(step) * 0.1;
                ekf.predict(t);
                ekf.update_heading(t, 0.0);
                ekf.update_height(t, 0.9);
                let full = Some(config.odometry_full_inliers);
                ekf.update_odometry_on(t - 0.1, t, [0.0, 0.0], full);
            }
            ekf.predict(2.6);
            let update = ekf.update_odometry_on(2.5, 2.6, [0.06, 0.0], inliers);
            assert_eq!(update, Update::Applied, "{inliers:?}");
            ekf.estimate().velocity[0]
        };
        let full = velocity_after(Some(config.odometry_full_inliers));
        assert_eq!(full, velocity_after(None));
        assert_eq!(full, velocity_after(Some(500)));
        let weak = velocity_after(Some(15));
        assert!(full > 0.4, "{full}");
        assert!(weak < 0.5 * full, "{weak} against {full}");
        assert!(weak > 0.0, "{weak}");
    }

    #[test]
    fn visual_odometry_keeps_a_drifting_vehicle_placed_without_fixes() {
        // Hovering with sticks centred, a draught carries the vehicle at 0.3 m/s (the model
        // knows nothing of it) for 20 s after its last SLAM fix. Visual odometry between
        // frames 0.1 s apart (1 cm of noise each, processed 0.3 s late) keeps the estimate
        // valid and on the vehicle, and its velocity known (to brake a drift with); without it
        // the filter gives the pose up within seconds, and the velocity sooner.
        let config = EkfConfig::default();
        let yaw = 0.7;
        let wind = [0.24, -0.18];
        let truth = |t: f64| [wind[0] * t, wind[1] * t];
        let run = |odometry: bool| {
            let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 0.9], yaw);
            ekf.update_slam(0.0, [0.0, 0.0, 0.9], yaw);
            let mut worst: f64 = 0.0;
            let mut valid_until = 0.0;
            let (mut worst_velocity, mut velocity_until): (f64, f64) = (0.0, 0.0);
            for step in 1..=200 {
                let t = f64::from(step) * 0.1;
                ekf.predict(t);
                ekf.update_heading(t, yaw);
                ekf.update_height(t, 0.9);
                if odometry && t >= 0.4 {
                    let (since, until) = (t - 0.4, t - 0.3);
                    let (a, b) = (truth(since), truth(until));
                    // Zero-mean noise of up to 1 cm per frame, uncorrelated in x and y.
                    let noise = |phase: f64| 0.01 * (f64::from(step) * 2.39 + phase).sin();
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let (s, c) = yaw.sin_cos();
                    let displacement =
                        [c * dx + s * dy + noise(0.0), -s * dx + c * dy + noise(1.3)];
                    ekf.update_odometry(since, until, displacement);
                }
                if let Some(e) = ekf.valid_estimate() {
                    valid_until = t;
                    let p = truth(t);
                    worst = worst.max((e.position[0] - p[0]).hypot(e.position[1] - p[1]));
                }
                match ekf.valid_velocity() {
                    Some(v) => {
                        velocity_until = t;
                        if t >= 2.0 {
                            let off = (v[0] - wind[0]).hypot(v[1] - wind[1]);
                            worst_velocity = worst_velocity.max(off);
                        }
                    }
                    None => assert!(
                        !odometry || t < 1.0,
                        "velocity lost at {t:.1} s: {:.3} m/s",
                        ekf.estimate().velocity_sigma
                    ),
                }
            }
            (valid_until, worst, velocity_until, worst_velocity)
        };
        let (valid_until, worst, velocity_until, worst_velocity) = run(true);
        assert!(valid_until > 19.9, "given up at {valid_until:.1} s");
        assert!(worst < 0.15, "{worst:.3} m off");
        assert!(velocity_until > 19.9);
        // Each measurement is up to 0.1 m/s off (1 cm in 0.1 s).
        assert!(worst_velocity < 0.15, "{worst_velocity:.3} m/s off");
        let (valid_until, _, velocity_until, _) = run(false);
        assert!(
            valid_until < 5.0,
            "valid until {valid_until:.1} s on the model alone"
        );
        assert!(
            velocity_until < 2.0,
            "velocity known until {velocity_until:.1} s on the model alone"
        );
    }

    #[test]
    fn yaw_spikes_and_tables_under_the_sonar_are_gated() {
        let mut ekf = Ekf::new(EkfConfig::default(), 0.0, [1.0, 1.0, 1.0], 0.5);
        ekf.update_slam(0.0, [1.0, 1.0, 1.0], 0.5);
        for k in 1..20 {
            let t = k as f64 * 0.1;
            ekf.predict(t);
            ekf.update_slam(t, [1.0, 1.0, 1.0], 0.5);
            assert_eq!(ekf.update_heading(t, 0.5), Update::Applied);
            assert_eq!(ekf.update_height(t, 1.0), Update::Applied);
        }
        // A 60° yaw spike, a 0.7 m table.
        assert_eq!(ekf.update_heading(2.0, 0.5 + 1.05), Update::Outlier);
        assert_eq!(ekf.update_height(2.0, 0.3), Update::Outlier);
        assert_eq!(ekf.outliers(), 2);
        let e = ekf.estimate();
        assert!((e.attitude[2] - 0.5).abs() < 0.01 && (e.position[2] - 1.0).abs() < 0.01);
    }

    #[test]
    fn a_slam_fix_off_the_rangefinder_height_is_refused() {
        let mut ekf = Ekf::new(EkfConfig::default(), 0.0, [1.0, 1.0, 1.0], 0.5);
        ekf.update_slam(0.0, [1.0, 1.0, 1.0], 0.5);
        for k in 1..20 {
            let t = k as f64 * 0.1;
            ekf.predict(t);
            assert_eq!(ekf.update_height(t, 1.0), Update::Applied);
            ekf.update_slam(t, [1.0, 1.0, 1.0], 0.5);
        }
        // Seen in flight: a registration 0.9 m high was taken as a map correction, the
        // rangefinder was then gated out against it, and the height loop flew into the floor.
        assert_eq!(ekf.update_slam(2.0, [1.2, 1.0, 1.9], 0.5), Update::Outlier);
        let e = ekf.estimate();
        assert!((e.position[2] - 1.0).abs() < 0.01, "{e:?}");
        assert_eq!(ekf.update_height(2.0, 1.0), Update::Applied);
        // A correction within the rangefinder's height is still a correction.
        assert_eq!(
            ekf.update_slam(2.0, [2.0, 1.0, 1.05], 0.5),
            Update::Corrected
        );
        // Without a rangefinder, nothing holds the height: the fix is taken.
        let mut blind = Ekf::new(EkfConfig::default(), 0.0, [1.0, 1.0, 1.0], 0.5);
        blind.update_slam(0.0, [1.0, 1.0, 1.0], 0.5);
        assert_ne!(
            blind.update_slam(0.1, [1.0, 1.0, 1.9], 0.5),
            Update::Outlier
        );
    }

    #[test]
    fn a_fix_on_few_inliers_counts_for_less_and_is_never_a_map_correction() {
        // Hovering at (1, 1, 1) on fixes of full weight, the rangefinder holding the height.
        let hover = || {
            let mut ekf = Ekf::new(EkfConfig::default(), 0.0, [1.0, 1.0, 1.0], 0.5);
            ekf.update_slam(0.0, [1.0, 1.0, 1.0], 0.5);
            for k in 1..20 {
                let t = k as f64 * 0.1;
                ekf.predict(t);
                ekf.update_height(t, 1.0);
                ekf.update_slam_on(t, [1.0, 1.0, 1.0], 0.5, Some(200));
            }
            ekf
        };
        let x_after = |ekf: &mut Ekf, inliers: Option<usize>| {
            ekf.predict(2.0);
            let update = ekf.update_slam_on(2.0, [1.26, 1.0, 1.0], 0.5, inliers);
            (update, ekf.estimate().position[0])
        };
        // 0.26 m off on 200 inliers, or relocalised: the map moved, the estimate is shifted.
        for inliers in [Some(200), None] {
            let (update, x) = x_after(&mut hover(), inliers);
            assert_eq!(update, Update::Corrected, "{inliers:?}");
            assert!((x - 1.26).abs() < 1e-6, "{x}");
        }
        // On 15 inliers: a measurement four times as noisy, which moves it a little.
        let mut ekf = hover();
        let (update, x) = x_after(&mut ekf, Some(15));
        assert_eq!(update, Update::Applied);
        assert!(x > 1.0 && x < 1.08, "{x}");
        // Fixes that go on saying so are believed within a second.
        for k in 21..30 {
            let t = k as f64 * 0.1;
            ekf.predict(t);
            ekf.update_height(t, 1.0);
            ekf.update_slam_on(t, [1.26, 1.0, 1.0], 0.5, Some(15));
        }
        let x = ekf.estimate().position[0];
        assert!((x - 1.26).abs() < 0.05, "{x}");
    }

    #[test]
    fn a_late_fix_is_compared_with_the_state_when_it_was_taken() {
        let config = EkfConfig::default();
        let mut ekf = Ekf::new(config, 0.0, [0.0, 0.0, 1.0], 0.0);
        ekf.update_slam(0.0, [0.0, 0.0, 1.0], 0.0);
        ekf.set_input(Input {
            pitch: 0.6,
            ..Input::default()
        });
        for k in 1..=30 {
            ekf.predict(k as f64 * 0.1);
            ekf.update_slam(k as f64 * 0.1, ekf.estimate().position, 0.0);
        }
        let before = ekf.estimate().position[0];
        // A fix of where the vehicle was 0.3 s ago, agreeing with the filter then: no jump back.
        let then = ekf.state_at(2.7).expect("in the history");
        ekf.update_slam(2.7, [then[PX], then[PY], then[PZ]], then[YAW]);
        assert!((ekf.estimate().position[0] - before).abs() < 0.01);
    }

    #[test]
    fn late_fixes_are_applied_where_they_belong_and_the_estimate_settles() {
        // A vehicle at rest at x = 1; the filter believes 1.2; every fix arrives 0.3 s after
        // its frame, ten a second. Compared with the state at their time but added to the
        // state now, each fix re-applied the corrections of the ones before it: the estimate
        // swung between 0.3 and 1.25 m for seconds (seen in flight as 0.2 m of jitter around a
        // drone at rest). Replayed from their time, the estimate overshoots once by what 0.3 s
        // of the velocity learnt extrapolates, and is steady within a second.
        let mut ekf = Ekf::new(EkfConfig::default(), 0.0, [1.2, 1.0, 1.0], 0.0);
        ekf.update_slam(0.0, [1.2, 1.0, 1.0], 0.0);
        let (mut lowest, mut late_error) = (f64::INFINITY, 0.0f64);
        for k in 1..=50 {
            let t = k as f64 * 0.1;
            ekf.predict(t);
            ekf.update_height(t, 1.0);
            if t >= 0.3 {
                assert_ne!(
                    ekf.update_slam(t - 0.3, [1.0, 1.0, 1.0], 0.0),
                    Update::Outlier
                );
            }
            let x = ekf.estimate().position[0];
            lowest = lowest.min(x);
            if t >= 1.3 {
                late_error = late_error.max((x - 1.0).abs());
            }
        }
        assert!(lowest > 0.9, "swung to {lowest:.3}");
        assert!(late_error < 0.01, "still {late_error:.3} m off after 1.3 s");
        assert_eq!(ekf.outliers(), 0);
    }

    #[test]
    fn the_journal_keeps_two_seconds() {
        // A control loop's calls at 10 Hz for ten minutes, with fixes 0.3 s late.
        let mut ekf = Ekf::new(EkfConfig::default(), 0.0, [1.0, 1.0, 1.0], 0.0);
        ekf.update_slam(0.0, [1.0, 1.0, 1.0], 0.0);
        let mut longest = 0;
        for k in 1..=6000 {
            let t = k as f64 * 0.1;
            ekf.predict(t);
            ekf.update_heading(t, 0.0);
            ekf.update_attitude(t, 0.0, 0.0);
            ekf.update_height(t, 1.0);
            ekf.set_input(Input::default());
            ekf.update_slam(t - 0.3, [1.0, 1.0, 1.0], 0.0);
            longest = longest.max(ekf.journal.len());
        }
        // Seven calls a tick (a replayed fix splits a prediction in two), 2 s of ticks and the
        // base before them.
        assert!(longest <= 7 * 22, "{longest} entries");
        let base = ekf
            .journal
            .front()
            .and_then(|e| e.after.as_ref())
            .expect("a base");
        assert!(
            (ekf.time() - base.t - 2.0).abs() <= 0.11,
            "base at {}",
            base.t
        );
    }

    #[test]
    fn without_fixes_the_estimate_becomes_invalid() {
        let mut ekf = Ekf::new(EkfConfig::default(), 0.0, [0.0, 0.0, 1.0], 0.0);
        ekf.update_slam(0.0, [0.0, 0.0, 1.0], 0.0);
        assert!(ekf.valid_estimate().is_some());
        ekf.predict(30.0);
        assert!(ekf.valid_estimate().is_none());
    }

    #[test]
    fn bad_measurements_and_wild_attitudes_leave_a_finite_physical_state() {
        let config = EkfConfig::default();
        let mut ekf = Ekf::new(config.clone(), 0.0, [0.0, 0.0, 1.0], 0.0);
        ekf.update_slam(0.0, [0.0, 0.0, 1.0], 0.0);
        assert_eq!(
            ekf.update_slam(0.1, [f64::NAN, 0.0, 1.0], 0.0),
            Update::Ignored
        );
        assert_eq!(ekf.update_height(0.1, f64::INFINITY), Update::Ignored);
        // A SLAM pose a kilometre away is no loop-closure correction.
        assert_eq!(
            ekf.update_slam(0.1, [1000.0, 0.0, 1.0], 0.0),
            Update::Outlier
        );
        // A real correction of a metre is taken as one: the estimate moves, the velocity
        // does not take the jump for motion.
        assert_eq!(
            ekf.update_slam(0.1, [1.0, 0.0, 1.0], 0.0),
            Update::Corrected
        );
        let e = ekf.estimate();
        assert!((e.position[0] - 1.0).abs() < 1e-9, "{e:?}");
        assert!(e.velocity[0].abs() < 1e-6, "{e:?}");
        // A flight controller reporting a lean of 80° (a crash, or a corrupt sample) must not
        // throw the filter to infinity: lean and speed stay bounded.
        for k in 1..=100 {
            let t = f64::from(k) * 0.1;
            ekf.set_input(Input {
                pitch: 1.0,
                ..Input::default()
            });
            ekf.predict(t);
            ekf.update_attitude(t, 0.0, 80f64.to_radians());
        }
        let e = ekf.estimate();
        assert!(e.attitude[1].abs() <= 2.0 * config.max_lean + 1e-9, "{e:?}");
        assert!(e.velocity.iter().all(|v| v.abs() <= MAX_SPEED), "{e:?}");
        assert!(e.position.iter().all(|v| v.is_finite()), "{e:?}");
    }
}
