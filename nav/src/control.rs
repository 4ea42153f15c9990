//! Controllers: PID with output limits and anti-windup, and the position controller that turns a
//! pose error into stick commands (seed 002 ch. 5; thesis §4.3 height PI, yaw P, pitch/roll PD).
//! Gains are configuration; the defaults are the published ones.

use crate::local::wrap_angle;

/// Gains and limits of one PID loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
    /// Derivative gain.
    pub kd: f64,
    /// The output is clamped to ±this.
    pub output_limit: f64,
    /// The integral term's contribution is clamped to ±this.
    pub integral_limit: f64,
}

impl PidGains {
    /// P only.
    pub const fn p(kp: f64) -> Self {
        Self {
            kp,
            ki: 0.0,
            kd: 0.0,
            output_limit: 1.0,
            integral_limit: 1.0,
        }
    }

    /// Full PID with output and integral limits of 1.
    pub const fn pid(kp: f64, ki: f64, kd: f64) -> Self {
        Self {
            kp,
            ki,
            kd,
            output_limit: 1.0,
            integral_limit: 1.0,
        }
    }
}

/// A PID loop. Anti-windup by conditional integration: while the output is saturated the
/// integral only moves in the direction that brings it back.
#[derive(Debug, Clone)]
pub struct Pid {
    gains: PidGains,
    integral: f64,
    previous: Option<f64>,
}

impl Pid {
    /// A loop at rest.
    pub fn new(gains: PidGains) -> Self {
        Self {
            gains,
            integral: 0.0,
            previous: None,
        }
    }

    /// Forgets the integral and the last error (after a pause or a mode change).
    pub fn reset(&mut self) {
        self.integral = 0.0;
        self.previous = None;
    }

    /// The integral term's current contribution (for displays and tests).
    pub fn integral_term(&self) -> f64 {
        self.gains.ki * self.integral
    }

    /// One update with `error` = setpoint − measurement after `dt` seconds. A non-finite error or
    /// a non-positive `dt` gives 0 and leaves the state alone.
    pub fn update(&mut self, error: f64, dt: f64) -> f64 {
        let rate = self.previous.map_or(0.0, |p| (error - p) / dt);
        self.update_with_rate(error, rate, dt)
    }

    /// One update as [`Pid::update`], with the error's rate of change given (m/s for a
    /// position loop) instead of differenced from the last error. A non-finite rate gives no
    /// derivative term.
    pub fn update_with_rate(&mut self, error: f64, rate: f64, dt: f64) -> f64 {
        self.step(error, rate, dt, true)
    }

    /// [`Pid::update_with_rate`], adding to the integral only if `integrate` (else the loop
    /// flies on what it has integrated so far).
    fn step(&mut self, error: f64, rate: f64, dt: f64, integrate: bool) -> f64 {
        if !(error.is_finite() && dt.is_finite() && dt > 0.0) {
            return 0.0;
        }
        let g = self.gains;
        let derivative = if rate.is_finite() { rate } else { 0.0 };
        self.previous = Some(error);
        let mut integral = self.integral + if integrate { error * dt } else { 0.0 };
        if g.ki != 0.0 {
            let cap = g.integral_limit / g.ki.abs();
            integral = integral.clamp(-cap, cap);
        }
        let unclamped = g.kp * error + g.ki * integral + g.kd * derivative;
        let output = unclamped.clamp(-g.output_limit, g.output_limit);
        let saturated = output != unclamped;
        // Keep the new integral unless saturated and integrating further into the saturation.
        if !saturated || (error * unclamped) < 0.0 {
            self.integral = integral;
        }
        output
    }
}

/// Stick command in [-1, 1] per axis, RC semantics: +roll right, +pitch forward, +yaw clockwise,
/// +throttle climb (0 = hold altitude).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StickCommand {
    /// +1 = bank right.
    pub roll: f64,
    /// +1 = nose down (forward).
    pub pitch: f64,
    /// +1 = yaw clockwise.
    pub yaw: f64,
    /// +1 = climb.
    pub throttle: f64,
}

/// A stick value as a pulse of 1500 ± 400 µs (seed 002 ch. 5).
pub fn stick_to_us(u: f64) -> u16 {
    let u = if u.is_finite() {
        u.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    (1500.0 + 400.0 * u).round() as u16
}

/// Gains of the position controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionGains {
    /// Map x loop (its output is rotated into the body frame).
    pub x: PidGains,
    /// Map y loop (its output is rotated into the body frame).
    pub y: PidGains,
    /// Height loop.
    pub z: PidGains,
    /// Heading loop.
    pub yaw: PidGains,
}

impl Default for PositionGains {
    /// Seed 002, Table 5.1. Not what the mission runtime flies: its gains, fitted to the
    /// simulated drone, are `gcs::runtime::drone::DroneConfig`'s.
    fn default() -> Self {
        Self {
            x: PidGains::pid(0.1, 0.4, 4.0),
            y: PidGains::pid(0.1, 0.15, 4.0),
            z: PidGains::pid(0.4, 1.0, 0.7),
            yaw: PidGains::p(2.5),
        }
    }
}

impl PositionGains {
    /// The thesis's controllers, converted from its reversed-wiring µs gains to stick units
    /// (500 µs = full stick): height PI (500, 15), yaw P (5 µs/° ≈ 0.57/rad), pitch and roll PD
    /// limited to ±20 µs (±0.04 stick).
    pub fn thesis() -> Self {
        let pd = PidGains {
            kp: 0.1,
            ki: 0.0,
            kd: 0.5,
            output_limit: 0.04,
            integral_limit: 0.0,
        };
        Self {
            x: pd,
            y: pd,
            z: PidGains {
                kp: 1.0,
                ki: 0.03,
                kd: 0.0,
                output_limit: 1.0,
                integral_limit: 0.5,
            },
            yaw: PidGains::p(5.0 / 500.0 * 180.0 / std::f64::consts::PI),
        }
    }
}

/// Setpoint or estimate: map-frame position and heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose3 {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// z (height), metres.
    pub z: f64,
    /// Heading, radians, counter-clockwise.
    pub yaw: f64,
}

/// A setpoint that moves this much further than the drone between two updates (metres) has
/// jumped to a new target (a path's new carrot, a turn's hold point): it is not moving along.
pub const SETPOINT_JUMP_M: f64 = 0.15;

/// The derivative terms difference over at least this long, seconds: control ticks that come
/// bunched (10 ms apart after a pause, under load) would turn a centimetre's wobble of the
/// estimate into a metre per second.
pub const DERIVATIVE_WINDOW_S: f64 = 0.05;

/// The horizontal setpoint and estimate the derivative terms difference from.
#[derive(Debug, Clone, Copy)]
struct Reference {
    target: [f64; 2],
    here: [f64; 2],
    /// Seconds since.
    age: f64,
}

/// x/y/z/yaw PID controllers: a pose setpoint and a pose estimate in, sticks out.
#[derive(Debug, Clone)]
pub struct PositionController {
    x: Pid,
    y: Pid,
    z: Pid,
    yaw: Pid,
    /// Where the derivative terms difference from: the latest update at least
    /// [`DERIVATIVE_WINDOW_S`] ago…
    reference: Option<Reference>,
    /// …and the latest update, to be that once it is old enough.
    recent: Option<Reference>,
    /// The next update's setpoint is a new target ([`PositionController::target_jumps`]).
    jumps: bool,
    /// The x and y loops add to their integrals ([`PositionController::integrate_xy`]).
    integrating_xy: bool,
}

impl PositionController {
    /// Controllers at rest.
    pub fn new(gains: PositionGains) -> Self {
        Self {
            x: Pid::new(gains.x),
            y: Pid::new(gains.y),
            z: Pid::new(gains.z),
            yaw: Pid::new(gains.yaw),
            reference: None,
            recent: None,
            jumps: false,
            integrating_xy: true,
        }
    }

    /// Whether the x and y loops add to their integrals (they do unless told otherwise). Off,
    /// they fly on what they have integrated: a drone pursuing a carrot always trails it by the
    /// follower's lead, and integrated that lead winds the loops up in the way it flies, a push
    /// that stays after it stops to hold a spot.
    pub fn integrate_xy(&mut self, on: bool) {
        self.integrating_xy = on;
    }

    /// The next update's setpoint is a new target (a new path's carrot, a new spot to hold),
    /// whatever the distance: the derivative terms take it as having moved along with the
    /// drone, as they take a jump they see ([`SETPOINT_JUMP_M`]). A carrot that moved a few
    /// centimetres sideways with a new path, differenced, read as half a metre a second and
    /// kicked the sticks by 0.3–0.5 for a tick, once a second.
    pub fn target_jumps(&mut self) {
        self.jumps = true;
    }

    /// Resets every loop.
    pub fn reset(&mut self) {
        for p in [&mut self.x, &mut self.y, &mut self.z, &mut self.yaw] {
            p.reset();
        }
        (self.reference, self.recent) = (None, None);
        self.jumps = false;
    }

    /// One update. The x and y loops run on the map-frame errors, and their outputs are rotated
    /// into the body frame by the current heading (so turning does not look like motion to the
    /// derivative terms); the heading error is wrapped, so −179.9° to 179.9° is a 0.2° turn.
    ///
    /// The derivative terms take a setpoint that jumped ([`SETPOINT_JUMP_M`], or announced by
    /// [`PositionController::target_jumps`]: a new target, not one moving along with the
    /// drone) as having moved with the drone, so it neither kicks nor brakes the sticks: from
    /// the next update they follow the new target's own motion (a spot to hold stands still:
    /// they brake the drone). (A setpoint that jumped 0.26 m from a turn's hold point to the
    /// carrot, differenced, had pushed a drone at 0.69 of full stick for 0.2 s away from both,
    /// toward a door's jamb; taken as standing still, a carrot that jumped braked a drone
    /// cruising at 0.9 m/s by half a stick for a tick.) They difference over at least
    /// [`DERIVATIVE_WINDOW_S`], however close together the updates come.
    pub fn update(&mut self, setpoint: &Pose3, estimate: &Pose3, dt: f64) -> StickCommand {
        self.update_steered(setpoint, [setpoint.x, setpoint.y], estimate, dt)
    }

    /// One update as [`PositionController::update`], steering to `steer` (map x/y, metres)
    /// instead of the setpoint's own x/y: where [`crate::avoid::keep_clear`] moved it, off
    /// the walls. The proportional and integral terms fly to `steer`; the derivative terms
    /// still follow the setpoint's motion. `steer` is worked out from the drone's position
    /// each tick (its lead from the drone, shortened near a wall), so it moves with the
    /// drone: differenced, it would show no motion to brake, and a drone near a wall would
    /// coast on unbraked (on true poses, each of the three wall collisions in 40 two-drone
    /// missions came at the end of seconds of coasting at 0.1–0.6 m/s beside a wall, the
    /// sticks near zero).
    pub fn update_steered(
        &mut self,
        setpoint: &Pose3,
        steer: [f64; 2],
        estimate: &Pose3,
        dt: f64,
    ) -> StickCommand {
        let target = [setpoint.x, setpoint.y];
        let here = [estimate.x, estimate.y];
        if dt > 0.0 {
            for r in [&mut self.reference, &mut self.recent]
                .into_iter()
                .flatten()
            {
                r.age += dt;
            }
        }
        if self.recent.is_some_and(|r| r.age >= DERIVATIVE_WINDOW_S) {
            self.reference = self.recent;
        }
        let announced = std::mem::take(&mut self.jumps);
        let rate = match self.reference {
            Some(from) if dt > 0.0 => {
                let span = from.age;
                let led = [target[0] - from.target[0], target[1] - from.target[1]];
                let moved = [here[0] - from.here[0], here[1] - from.here[1]];
                if announced || (led[0] - moved[0]).hypot(led[1] - moved[1]) > SETPOINT_JUMP_M {
                    // As if the new target had always moved with the drone.
                    for r in [&mut self.reference, &mut self.recent]
                        .into_iter()
                        .flatten()
                    {
                        r.target = [
                            target[0] - (here[0] - r.here[0]),
                            target[1] - (here[1] - r.here[1]),
                        ];
                    }
                    [0.0; 2]
                } else {
                    [(led[0] - moved[0]) / span, (led[1] - moved[1]) / span]
                }
            }
            _ => [0.0; 2],
        };
        if target.iter().chain(&here).all(|v| v.is_finite()) {
            let now = Reference {
                target,
                here,
                age: 0.0,
            };
            self.reference.get_or_insert(now);
            self.recent = Some(now);
        }
        let integrate = self.integrating_xy;
        let ax = self.x.step(steer[0] - estimate.x, rate[0], dt, integrate);
        let ay = self.y.step(steer[1] - estimate.y, rate[1], dt, integrate);
        let (s, c) = estimate.yaw.sin_cos();
        let forward = c * ax + s * ay;
        let left = -s * ax + c * ay;
        StickCommand {
            pitch: forward.clamp(-1.0, 1.0),
            roll: (-left).clamp(-1.0, 1.0),
            throttle: self.z.update(setpoint.z - estimate.z, dt),
            // Map yaw is counter-clockwise; a clockwise stick is positive.
            yaw: -self.yaw.update(wrap_angle(setpoint.yaw - estimate.yaw), dt),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A climb-rate plant like ALT_HOLD: the stick commands a climb rate of up to 1 m/s, reached
    /// with a first-order lag of 0.3 s.
    fn simulate(pid: &mut Pid, target: f64, seconds: f64, ceiling: f64) -> (Vec<f64>, f64) {
        let dt = 0.05;
        let (mut z, mut v) = (0.0f64, 0.0f64);
        let mut trace = vec![];
        for _ in 0..(seconds / dt) as usize {
            let u = pid.update(target - z, dt);
            v += ((u * 1.0) - v) / 0.3 * dt;
            z = (z + v * dt).min(ceiling);
            if z >= ceiling {
                v = v.min(0.0);
            }
            trace.push(z);
        }
        (trace, z)
    }

    #[test]
    fn height_loop_settles_on_a_first_order_plant() {
        let mut pid = Pid::new(PidGains::pid(1.2, 0.3, 0.1));
        let (trace, z) = simulate(&mut pid, 1.0, 15.0, f64::INFINITY);
        assert!((z - 1.0).abs() < 0.02, "settled at {z}");
        let peak = trace.iter().copied().fold(0.0, f64::max);
        assert!(peak < 1.2, "overshoot to {peak}");
    }

    #[test]
    fn no_windup_while_saturated() {
        // No integral limit to help: only conditional integration stands between the loop and
        // windup. A ceiling holds the drone at 0.5 m while it is asked for 3 m for 20 s; a plain
        // PID would integrate 2.5 m × 20 s × 0.5 = 25 (twenty-five full sticks) meanwhile.
        let gains = PidGains {
            kp: 1.2,
            ki: 0.5,
            kd: 0.0,
            output_limit: 1.0,
            integral_limit: 1e9,
        };
        let mut pid = Pid::new(gains);
        simulate(&mut pid, 3.0, 20.0, 0.5);
        assert!(
            pid.integral_term().abs() < 0.5,
            "wound up to {}",
            pid.integral_term()
        );
        // Asked for 0.4 m now, it is there within 3 s instead of flying up on a wound integral.
        let (trace, _) = simulate(&mut pid, 0.4, 6.0, f64::INFINITY);
        let after_3s = &trace[60..];
        assert!(
            after_3s.iter().all(|z| (z - 0.4).abs() < 0.1),
            "{:?}",
            &after_3s[..5]
        );
    }

    #[test]
    fn with_the_xy_integrals_frozen_a_lead_winds_nothing_up_and_what_was_integrated_stays() {
        let gains = PositionGains {
            x: PidGains::pid(0.3, 0.02, 0.0),
            y: PidGains::pid(0.3, 0.02, 0.0),
            ..PositionGains::default()
        };
        let mut c = PositionController::new(gains);
        let at = |x: f64| Pose3 {
            x,
            y: 0.0,
            z: 1.0,
            yaw: 0.0,
        };
        // Held 0.5 m short of a spot for 10 s: the x loop integrates 5 m·s.
        for _ in 0..100 {
            c.update(&at(0.5), &at(0.0), 0.1);
        }
        let held = c.x.integral_term();
        assert!((held - 0.1).abs() < 1e-9, "{held}");
        // Then 40 s behind a carrot 0.4 m ahead, frozen: nothing added, and the sticks are the
        // proportional part and what was integrated before.
        c.integrate_xy(false);
        let mut pitch = 0.0;
        for k in 0..400 {
            let x = 0.05 * f64::from(k);
            pitch = c.update(&at(x + 0.4), &at(x), 0.1).pitch;
        }
        assert_eq!(c.x.integral_term(), held);
        assert!((pitch - (0.3 * 0.4 + held)).abs() < 1e-9, "{pitch}");
        // Integrating again, the same lead winds it up.
        c.integrate_xy(true);
        for k in 0..100 {
            let x = 0.05 * f64::from(k);
            c.update(&at(x + 0.4), &at(x), 0.1);
        }
        assert!(c.x.integral_term() > held + 0.07, "{}", c.x.integral_term());
    }

    #[test]
    fn outputs_are_limited_and_mapped_to_pulses() {
        let mut pid = Pid::new(PidGains::pid(10.0, 0.0, 0.0));
        assert_eq!(pid.update(5.0, 0.1), 1.0);
        assert_eq!(pid.update(f64::NAN, 0.1), 0.0);
        assert_eq!(pid.update(1.0, 0.0), 0.0);
        assert_eq!(
            (
                stick_to_us(1.0),
                stick_to_us(-1.0),
                stick_to_us(0.0),
                stick_to_us(f64::NAN)
            ),
            (1900, 1100, 1500, 1500)
        );
    }

    #[test]
    fn position_errors_are_rotated_into_the_body_frame() {
        let mut pc = PositionController::new(PositionGains::default());
        // Facing +y (yaw 90°), the target 1 m along +y is straight ahead: pitch forward, no roll.
        let sp = Pose3 {
            x: 0.0,
            y: 1.0,
            z: 1.0,
            yaw: std::f64::consts::FRAC_PI_2,
        };
        let est = Pose3 {
            x: 0.0,
            y: 0.0,
            z: 1.0,
            yaw: std::f64::consts::FRAC_PI_2,
        };
        let s = pc.update(&sp, &est, 0.1);
        assert!(
            s.pitch > 0.0 && s.roll.abs() < 1e-9 && s.throttle.abs() < 1e-9 && s.yaw.abs() < 1e-9,
            "{s:?}"
        );
        // A target to the left (+x while facing +y is to the right): roll right.
        let mut pc = PositionController::new(PositionGains::default());
        let s = pc.update(&Pose3 { x: 1.0, ..est }, &est, 0.1);
        assert!(s.roll > 0.0 && s.pitch.abs() < 1e-9, "{s:?}");
        // Heading across the ±180° jump turns the short way: 179.9° → −179.9° is 0.2° counter-clockwise.
        let mut pc = PositionController::new(PositionGains::default());
        let a = Pose3 {
            yaw: 179.9f64.to_radians(),
            ..est
        };
        let b = Pose3 {
            yaw: (-179.9f64).to_radians(),
            ..est
        };
        let s = pc.update(&b, &a, 0.1);
        assert!(s.yaw < 0.0 && s.yaw > -0.02, "{s:?}");
    }

    #[test]
    fn turning_on_the_spot_is_not_seen_as_motion() {
        // A fixed map-frame error while the drone turns: the body-frame command turns with it and
        // keeps its size (a body-frame derivative would kick at every heading change).
        let gains = PositionGains {
            x: PidGains::pid(0.3, 0.0, 0.6),
            y: PidGains::pid(0.3, 0.0, 0.6),
            ..PositionGains::default()
        };
        let mut pc = PositionController::new(gains);
        let sp = Pose3 {
            x: 1.0,
            y: 0.0,
            z: 1.0,
            yaw: 0.0,
        };
        let mut sizes = vec![];
        for i in 0..10 {
            let est = Pose3 {
                x: 0.0,
                y: 0.0,
                z: 1.0,
                yaw: 0.3 * f64::from(i),
            };
            let s = pc.update(&sp, &est, 0.1);
            sizes.push(s.pitch.hypot(s.roll));
        }
        assert!(
            sizes[1..].iter().all(|m| (m - sizes[1]).abs() < 1e-9),
            "{sizes:?}"
        );
    }

    #[test]
    fn a_setpoint_that_jumps_does_not_kick_the_sticks() {
        // At rest 1 m behind a target straight ahead; the target jumps 0.3 m nearer (a turn's
        // hold point after a carrot). It is still ahead: the sticks must still lead toward it,
        // not away from it as the jump differenced would.
        let mut pc = PositionController::new(PositionGains::default());
        let est = Pose3 {
            x: 0.0,
            y: 0.0,
            z: 1.0,
            yaw: 0.0,
        };
        let far = Pose3 { x: 1.0, ..est };
        for _ in 0..3 {
            assert!(pc.update(&far, &est, 0.1).pitch > 0.0);
        }
        let near = Pose3 { x: 0.7, ..est };
        let s = pc.update(&near, &est, 0.1);
        assert!(s.pitch > 0.0 && s.roll.abs() < 1e-9, "{s:?}");
        // Moving on at 0.5 m/s toward a target that jumps 0.5 m further: the derivative
        // neither kicks (the jump's 4.5 m/s) nor brakes (0.5 m/s) for it: PD 0.3, 0.6 gives
        // only the proportional 0.3 × 1.45.
        let pd = PidGains::pid(0.3, 0.0, 0.6);
        let mut pc = PositionController::new(PositionGains {
            x: pd,
            y: pd,
            ..PositionGains::default()
        });
        pc.update(&far, &est, 0.1);
        let moved = Pose3 { x: 0.05, ..est };
        let s = pc.update(&Pose3 { x: 1.5, ..est }, &moved, 0.1);
        assert!((s.pitch - 0.3 * 1.45).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn a_new_target_a_few_centimetres_off_kicks_nothing_then_its_motion_is_followed() {
        // Cruising +x at 0.5 m/s behind a carrot 0.4 m ahead that moves with it (ticks of
        // 0.1 s); a new path puts the carrot 8 cm to the left, too little to be seen as a jump.
        let pd = PidGains::pid(0.3, 0.0, 0.6);
        let gains = PositionGains {
            x: pd,
            y: pd,
            ..PositionGains::default()
        };
        let at = |x: f64, y: f64| Pose3 {
            x,
            y,
            z: 1.0,
            yaw: 0.0,
        };
        let roll_after_the_new_path = |announced: bool| {
            let mut pc = PositionController::new(gains);
            for i in 0..5 {
                let x = 0.05 * f64::from(i);
                let s = pc.update(&at(x + 0.4, 0.0), &at(x, 0.0), 0.1);
                assert!(s.roll.abs() < 1e-9, "{s:?}");
            }
            if announced {
                pc.target_jumps();
            }
            let jump = pc.update(&at(0.25 + 0.4, 0.08), &at(0.25, 0.0), 0.1).roll;
            // The next tick: the carrot moves with the drone again; the drone drifts 1 cm left.
            let next = pc.update(&at(0.3 + 0.4, 0.08), &at(0.3, 0.01), 0.1).roll;
            (jump, next)
        };
        // Differenced, 0.8 m/s to the left: a kick of 0.6 × 0.8 on top of the 0.3 × 0.08.
        let (kicked, _) = roll_after_the_new_path(false);
        assert!((kicked + (0.3 * 0.08 + 0.6 * 0.8)).abs() < 1e-9, "{kicked}");
        // Announced: only the proportional term; then the drift is damped as ever.
        let (jump, next) = roll_after_the_new_path(true);
        assert!((jump + 0.3 * 0.08).abs() < 1e-9, "{jump}");
        assert!((next + (0.3 * 0.07 - 0.6 * 0.1)).abs() < 1e-9, "{next}");
    }

    #[test]
    fn ticks_that_come_bunched_do_not_kick_the_sticks() {
        // Flying at 0.5 m/s toward a target ahead, 0.1 s between ticks; then one tick 10 ms
        // after the last, the estimate 1 cm off (a wobble). Differenced over the 10 ms it would
        // read 1.5 m/s and brake at 0.9 of full stick; over the window it is a small change.
        let pd = PidGains::pid(0.3, 0.0, 0.6);
        let mut pc = PositionController::new(PositionGains {
            x: pd,
            y: pd,
            ..PositionGains::default()
        });
        let at = |x: f64| Pose3 {
            x,
            y: 0.0,
            z: 1.0,
            yaw: 0.0,
        };
        let target = at(2.0);
        let mut steady = 0.0;
        for i in 0..5 {
            steady = pc.update(&target, &at(0.05 * f64::from(i)), 0.1).pitch;
        }
        assert!((steady - (0.3 * 1.8 - 0.6 * 0.5)).abs() < 1e-9, "{steady}");
        let bunched = pc.update(&target, &at(0.2 + 0.005 + 0.01), 0.01).pitch;
        assert!((bunched - steady).abs() < 0.1, "{bunched} against {steady}");
        // The next tick, 0.1 s on, differences from the bunched one, over 0.1 s as ever.
        let next = pc.update(&target, &at(0.255), 0.1).pitch;
        assert!((next - (0.3 * 1.745 - 0.6 * 0.4)).abs() < 1e-9, "{next}");
    }

    #[test]
    fn a_steer_point_that_moves_with_the_drone_still_brakes_it() {
        // A drone coasting at 0.4 m/s (−x) away from its hold point at x = 0, beside a wall:
        // the steer point is 0.2 m from the drone toward the hold point, so it moves with the
        // drone. The derivative follows the hold point, which stands still: full brake.
        let hold = Pose3 {
            x: 0.0,
            y: 0.0,
            z: 1.0,
            yaw: 0.0,
        };
        let coast = |steered: bool| {
            let mut pc = PositionController::new(PositionGains::default());
            let mut pitch = 0.0;
            for i in 0..5 {
                let here = Pose3 {
                    x: -0.3 - 0.04 * f64::from(i),
                    ..hold
                };
                let steer = [here.x + 0.2, 0.0];
                pitch = if steered {
                    pc.update_steered(&hold, steer, &here, 0.1).pitch
                } else {
                    let at_steer = Pose3 {
                        x: steer[0],
                        ..hold
                    };
                    pc.update(&at_steer, &here, 0.1).pitch
                };
            }
            pitch
        };
        assert_eq!(coast(true), 1.0);
        // Flown as the setpoint itself, the steer point shows no motion: barely a touch.
        let unbraked = coast(false);
        assert!(unbraked > 0.0 && unbraked < 0.2, "{unbraked}");
    }

    #[test]
    fn a_setpoint_moving_along_is_differenced_as_a_whole() {
        // A carrot running ahead of a drone (1 cm further than it each tick): the same sticks
        // as plain PID loops on the map errors.
        let gains = PositionGains {
            x: PidGains::pid(0.3, 0.02, 0.6),
            y: PidGains::pid(0.3, 0.02, 0.6),
            ..PositionGains::default()
        };
        let mut pc = PositionController::new(gains);
        let (mut px, mut py) = (Pid::new(gains.x), Pid::new(gains.y));
        for i in 0..20 {
            let t = f64::from(i);
            let est = Pose3 {
                x: 0.05 * t,
                y: 0.02 * t,
                z: 1.0,
                yaw: 0.0,
            };
            let sp = Pose3 {
                x: 0.4 + 0.06 * t,
                y: 0.1 + 0.02 * t,
                ..est
            };
            let s = pc.update(&sp, &est, 0.1);
            let (ax, ay) = (px.update(sp.x - est.x, 0.1), py.update(sp.y - est.y, 0.1));
            assert!(
                (s.pitch - ax).abs() < 1e-12 && (s.roll + ay).abs() < 1e-12,
                "{i}: {s:?}"
            );
        }
    }
}
