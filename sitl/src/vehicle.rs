//! A multirotor behind a stabilising flight controller, as the thesis flew it (seed 002 §4.2.1).
//!
//! Sticks command lean angles, yaw rate and — with altitude hold, around mid throttle — climb
//! rate; attitude, yaw rate and climb rate follow their commands with first-order lags; the body
//! accelerates with its lean and slows with linear drag relative to the air, so a gust makes it
//! drift: nothing holds position except the LOITER, GUIDED and LAND modes of the MAVLink
//! autopilot. Motors turn only when armed. The drone never passes through a wall: the part of a
//! move that would overlap one is refused (the drone stops against the wall and can only slide
//! along it), and the collision is reported.
//!
//! Frames: map x, y horizontal and z up from the floor; attitude as roll (+ banks right),
//! pitch (+ nose down) and yaw (+ anticlockwise from x), the FLU convention of `link`.

use link::{FlightMode, Sticks};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::battery::{Load, Pack};
use crate::world::World;

/// Gravity, m/s².
pub const G: f64 = 9.81;

/// Physical and flight-controller constants of one vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleParams {
    /// Radius of the disc that must stay clear of walls, metres.
    pub radius: f64,
    /// Lean angle at full roll or pitch stick, radians.
    pub max_lean: f64,
    /// Time constant of the attitude response, seconds.
    pub attitude_tau: f64,
    /// Yaw rate at full yaw stick, rad/s.
    pub max_yaw_rate: f64,
    /// Time constant of the yaw-rate response, seconds.
    pub yaw_tau: f64,
    /// Climb rate at full throttle in altitude hold, m/s.
    pub max_climb: f64,
    /// Time constant of the climb-rate response, seconds.
    pub climb_tau: f64,
    /// Linear drag, 1/s (acceleration per m/s of airspeed).
    pub drag: f64,
    /// Horizontal speed at full stick in LOITER, m/s.
    pub loiter_speed: f64,
    /// Descent rate in LAND, m/s.
    pub land_speed: f64,
    /// The battery: its cells and its sag under load.
    pub battery: Pack,
    /// Flight time on one battery at hover, seconds.
    pub endurance_s: f64,
    /// A simulated operator puts a charged battery in a vehicle that has rested disarmed on
    /// the floor this long with less than half its charge left, seconds (a hot swap: the flight
    /// controller stays on); `None`: batteries are never changed.
    pub battery_swap_s: Option<f64>,
    /// The camera's position on the body (x forward, y left, z up), metres.
    pub camera_offset: [f64; 3],
}

impl Default for VehicleParams {
    fn default() -> Self {
        Self {
            radius: 0.2,
            max_lean: 20f64.to_radians(),
            attitude_tau: 0.15,
            max_yaw_rate: 90f64.to_radians(),
            yaw_tau: 0.1,
            max_climb: 1.0,
            climb_tau: 0.3,
            drag: 0.6,
            loiter_speed: 1.5,
            land_speed: 0.5,
            battery: Pack::default(),
            endurance_s: 12.0 * 60.0,
            battery_swap_s: None,
            camera_offset: [0.1, 0.0, 0.05],
        }
    }
}

/// The true state of a vehicle (the simulator's ground truth).
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleState {
    /// Position in the map, metres (z above the floor).
    pub position: [f64; 3],
    /// Velocity in the map, m/s.
    pub velocity: [f64; 3],
    /// Roll, radians (+ banks right).
    pub roll: f64,
    /// Pitch, radians (+ nose down).
    pub pitch: f64,
    /// Yaw, radians (+ anticlockwise from the map's x axis).
    pub yaw: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate: f64,
    /// Motors armed.
    pub armed: bool,
    /// Resting on the floor.
    pub landed: bool,
    /// Fraction of the battery used, 0–1.
    pub consumed: f64,
    /// Collisions with walls or the ceiling so far.
    pub collisions: u32,
}

/// Something that happened to a vehicle, for its endpoint to report.
#[derive(Debug, Clone, PartialEq)]
pub enum VehicleEvent {
    /// It touched a wall (or the ceiling) at this position and stopped.
    Collision([f64; 3]),
    /// It touched down.
    Landed,
    /// It left the floor.
    TookOff,
    /// A charged battery was put in ([`VehicleParams::battery_swap_s`]).
    BatterySwapped,
}

/// One simulated multirotor and its stabilising flight controller.
#[derive(Debug, Clone)]
pub struct Vehicle {
    params: VehicleParams,
    state: VehicleState,
    mode: FlightMode,
    sticks: Sticks,
    /// Position held in LOITER, GUIDED and LAND.
    hold: Option<[f64; 2]>,
    /// Altitude a GUIDED takeoff climbs to.
    guided_altitude: Option<f64>,
    wind: [f64; 2],
    in_contact: bool,
    /// How long it has rested disarmed on the floor, seconds.
    resting_s: f64,
    events: Vec<VehicleEvent>,
}

/// Largest integration step, seconds.
pub const MAX_STEP: f64 = 0.005;

impl Vehicle {
    /// A disarmed vehicle resting at `(x, y)` on the floor, facing `yaw`.
    pub fn new(params: VehicleParams, x: f64, y: f64, yaw: f64) -> Self {
        Self {
            params,
            state: VehicleState {
                position: [x, y, 0.0],
                velocity: [0.0; 3],
                roll: 0.0,
                pitch: 0.0,
                yaw,
                yaw_rate: 0.0,
                armed: false,
                landed: true,
                consumed: 0.0,
                collisions: 0,
            },
            mode: FlightMode::AltHold,
            sticks: Sticks::CENTRED,
            hold: None,
            guided_altitude: None,
            wind: [0.0; 2],
            in_contact: false,
            resting_s: 0.0,
            events: vec![],
        }
    }

    /// The ground-truth state.
    pub fn state(&self) -> &VehicleState {
        &self.state
    }

    /// The vehicle's constants.
    pub fn params(&self) -> &VehicleParams {
        &self.params
    }

    /// The flight controller's mode.
    pub fn mode(&self) -> FlightMode {
        self.mode
    }

    /// Changes the flight controller's mode (the caller decides whether it is allowed).
    pub fn set_mode(&mut self, mode: FlightMode) {
        if mode != self.mode {
            self.hold = None;
            if mode != FlightMode::Guided {
                self.guided_altitude = None;
            }
        }
        self.mode = mode;
    }

    /// The stick inputs the flight controller acts on.
    pub fn set_sticks(&mut self, sticks: Sticks) {
        self.sticks = sticks;
    }

    /// The current stick inputs.
    pub fn sticks(&self) -> Sticks {
        self.sticks
    }

    /// Starts or stops the motors. Disarming in the air stops the motors: it falls.
    pub fn set_armed(&mut self, armed: bool) {
        self.state.armed = armed;
        if !armed {
            self.guided_altitude = None;
        }
    }

    /// In GUIDED, climbs to `altitude` metres and holds there.
    pub fn takeoff(&mut self, altitude: f64) {
        self.guided_altitude = Some(altitude.clamp(0.0, 100.0));
    }

    /// Sets the wind the vehicle flies in, m/s in the map frame.
    pub fn set_wind(&mut self, wind: [f64; 2]) {
        self.wind = wind;
    }

    /// Battery voltage now, V: a LiPo pack's at the charge left, sagging under the load of the
    /// motors ([`crate::battery`]).
    pub fn battery_voltage(&self) -> f64 {
        let s = &self.state;
        let load = match (s.armed, s.landed) {
            (false, _) => Load::None,
            (true, true) => Load::Idle,
            (true, false) => Load::Flying,
        };
        self.params
            .battery
            .voltage((1.0 - s.consumed).clamp(0.0, 1.0), load)
    }

    /// Battery left, percent.
    pub fn battery_remaining(&self) -> u8 {
        ((1.0 - self.state.consumed).clamp(0.0, 1.0) * 100.0).round() as u8
    }

    /// Drains the battery to `remaining` (0–1) at once, if it holds more (a fault for tests: a
    /// cell failing, a battery that was not charged).
    pub fn drain_battery(&mut self, remaining: f64) {
        let consumed = 1.0 - remaining.clamp(0.0, 1.0);
        self.state.consumed = self.state.consumed.max(consumed);
    }

    /// Takes the events since the last call.
    pub fn take_events(&mut self) -> Vec<VehicleEvent> {
        std::mem::take(&mut self.events)
    }

    /// The body pose in the map (x forward, y left, z up).
    pub fn map_from_body(&self) -> Isometry3<f64> {
        let s = &self.state;
        Isometry3::from_parts(
            Translation3::new(s.position[0], s.position[1], s.position[2]),
            UnitQuaternion::from_euler_angles(s.roll, s.pitch, s.yaw),
        )
    }

    /// The camera's optical frame (x right, y down, z forward) in the map.
    pub fn map_from_camera(&self) -> Isometry3<f64> {
        self.map_from_body() * body_from_camera(self.params.camera_offset)
    }

    /// Advances `dt` seconds in `world` (in steps of at most [`MAX_STEP`]).
    pub fn step(&mut self, world: &World, dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let n = (dt / MAX_STEP).ceil().max(1.0);
        let h = dt / n;
        for _ in 0..n as u32 {
            self.substep(world, h);
        }
    }

    /// What the flight controller asks for: lean (roll, pitch), yaw rate and the vertical command.
    fn targets(&mut self) -> (f64, f64, f64, Vertical) {
        let p = &self.params;
        let s = &self.state;
        let sticks = self.sticks;
        let (roll_in, pitch_in) = (
            f64::from(sticks.get(link::Axis::Roll)),
            f64::from(sticks.get(link::Axis::Pitch)),
        );
        let yaw_rate = -f64::from(sticks.get(link::Axis::Yaw)) * p.max_yaw_rate; // + stick = clockwise
        let throttle = f64::from(sticks.get(link::Axis::Throttle));
        let climb = Vertical::Rate(throttle * p.max_climb);
        match self.mode {
            FlightMode::Stabilize => (
                roll_in * p.max_lean,
                pitch_in * p.max_lean,
                yaw_rate,
                Vertical::Thrust(f64::from(sticks.get(link::Axis::Throttle))),
            ),
            FlightMode::AltHold => (roll_in * p.max_lean, pitch_in * p.max_lean, yaw_rate, climb),
            FlightMode::Loiter | FlightMode::Guided | FlightMode::Land => {
                let (fwd, right) = if self.mode == FlightMode::Loiter {
                    (pitch_in * p.loiter_speed, roll_in * p.loiter_speed)
                } else {
                    (0.0, 0.0)
                };
                // Velocity target in the map from the sticks (body frame) and the held position.
                let (c, sn) = (s.yaw.cos(), s.yaw.sin());
                let mut v_target = [fwd * c + right * sn, fwd * sn - right * c];
                if fwd == 0.0 && right == 0.0 {
                    let hold = *self.hold.get_or_insert([s.position[0], s.position[1]]);
                    for k in 0..2 {
                        v_target[k] = (1.0 * (hold[k] - s.position[k]))
                            .clamp(-p.loiter_speed, p.loiter_speed);
                    }
                } else {
                    self.hold = None;
                }
                // Lean to correct the velocity error (a P controller on velocity), then rotate the
                // map-frame acceleration into the body's forward / right lean.
                let a = [
                    2.0 * (v_target[0] - s.velocity[0]) + p.drag * s.velocity[0],
                    2.0 * (v_target[1] - s.velocity[1]) + p.drag * s.velocity[1],
                ];
                let a_fwd = a[0] * c + a[1] * sn;
                let a_right = a[0] * sn - a[1] * c;
                let pitch = (a_fwd / G).atan().clamp(-p.max_lean, p.max_lean);
                let roll = (a_right / G).atan().clamp(-p.max_lean, p.max_lean);
                let vertical = match (self.mode, self.guided_altitude) {
                    (FlightMode::Land, _) => Vertical::Rate(-p.land_speed),
                    (FlightMode::Guided, Some(alt)) => Vertical::Rate(
                        (1.0 * (alt - s.position[2])).clamp(-p.max_climb, p.max_climb),
                    ),
                    (FlightMode::Guided, None) => Vertical::Rate(0.0),
                    _ => climb,
                };
                let yaw_rate = if self.mode == FlightMode::Loiter {
                    yaw_rate
                } else {
                    0.0
                };
                (roll, pitch, yaw_rate, vertical)
            }
        }
    }

    fn substep(&mut self, world: &World, h: f64) {
        let p = self.params.clone();
        let (roll_t, pitch_t, yaw_rate_t, vertical) = if self.state.armed {
            self.targets()
        } else {
            (0.0, 0.0, 0.0, Vertical::Off)
        };
        let s = &mut self.state;
        let flying = !s.landed;
        // Attitude and yaw rate follow their commands (level on the floor).
        let (roll_t, pitch_t) = if flying {
            (roll_t, pitch_t)
        } else {
            (0.0, 0.0)
        };
        s.roll += (roll_t - s.roll) * (h / p.attitude_tau).min(1.0);
        s.pitch += (pitch_t - s.pitch) * (h / p.attitude_tau).min(1.0);
        let yaw_rate_t = if flying { yaw_rate_t } else { 0.0 };
        s.yaw_rate += (yaw_rate_t - s.yaw_rate) * (h / p.yaw_tau).min(1.0);
        s.yaw = wrap(s.yaw + s.yaw_rate * h);
        // Horizontal: lean accelerates, drag slows relative to the air.
        let (c, sn) = (s.yaw.cos(), s.yaw.sin());
        let a_fwd = G * s.pitch.tan();
        let a_left = -G * s.roll.tan();
        let mut a = [
            a_fwd * c - a_left * sn + p.drag * (self.wind[0] - s.velocity[0]),
            a_fwd * sn + a_left * c + p.drag * (self.wind[1] - s.velocity[1]),
            0.0,
        ];
        // Vertical.
        match vertical {
            Vertical::Rate(rate) => {
                a[2] = (rate - s.velocity[2]) / p.climb_tau;
            }
            Vertical::Thrust(t) => {
                a[2] = 0.5 * G * t - p.drag * s.velocity[2];
            }
            Vertical::Off => {
                a[2] = -G - p.drag * s.velocity[2];
            }
        }
        if s.landed {
            // On the floor: no sliding; it lifts off only when asked to climb.
            a[0] = 0.0;
            a[1] = 0.0;
            s.velocity[0] = 0.0;
            s.velocity[1] = 0.0;
            a[2] = a[2].max(0.0);
        }
        for (v, a) in s.velocity.iter_mut().zip(a) {
            *v += a * h;
        }
        let mut next = [
            s.position[0] + s.velocity[0] * h,
            s.position[1] + s.velocity[1] * h,
            s.position[2] + s.velocity[2] * h,
        ];
        // Walls: a move into a wall is refused along the blocked axis (the drone stops there and
        // may slide along the wall), and the first touch is reported.
        let mut contact = false;
        if world.disc_hits_wall([next[0], next[1]], p.radius) {
            contact = true;
            if !world.disc_hits_wall([next[0], s.position[1]], p.radius) {
                next[1] = s.position[1];
                s.velocity[1] = 0.0;
            } else if !world.disc_hits_wall([s.position[0], next[1]], p.radius) {
                next[0] = s.position[0];
                s.velocity[0] = 0.0;
            } else {
                next[0] = s.position[0];
                next[1] = s.position[1];
                s.velocity[0] = 0.0;
                s.velocity[1] = 0.0;
            }
        }
        let top = world.ceiling() - 0.1;
        if next[2] > top {
            contact = true;
            next[2] = top;
            s.velocity[2] = 0.0;
        }
        if contact && !self.in_contact {
            s.collisions += 1;
            self.events.push(VehicleEvent::Collision(s.position));
            self.in_contact = true;
        }
        // The contact ends once the drone has moved 5 cm clear (so pressing on counts once).
        if self.in_contact
            && !contact
            && next[2] < top - 0.05
            && !world.disc_hits_wall([next[0], next[1]], p.radius + 0.05)
        {
            self.in_contact = false;
        }
        // Floor.
        if next[2] <= 0.0 {
            next[2] = 0.0;
            s.velocity[2] = s.velocity[2].max(0.0);
            if !s.landed && s.velocity[2] <= 0.0 {
                s.landed = true;
                s.roll = 0.0;
                s.pitch = 0.0;
                self.events.push(VehicleEvent::Landed);
            }
        } else if s.landed && next[2] > 0.02 {
            s.landed = false;
            self.events.push(VehicleEvent::TookOff);
        }
        s.position = next;
        // Battery: full drain in the air, a tenth of it armed on the floor.
        if s.armed {
            let rate = if s.landed { 0.1 } else { 1.0 } / p.endurance_s;
            s.consumed = (s.consumed + rate * h).min(1.0);
        }
        // A battery swap, once it has rested long enough for the operator to reach it.
        self.resting_s = if !s.armed && s.landed {
            self.resting_s + h
        } else {
            0.0
        };
        if let Some(swap_s) = p.battery_swap_s
            && self.resting_s >= swap_s
            && s.consumed > 0.5
        {
            s.consumed = 0.0;
            self.events.push(VehicleEvent::BatterySwapped);
        }
    }
}

/// The vertical command of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Vertical {
    /// Altitude hold: climb at this rate, m/s.
    Rate(f64),
    /// Manual throttle in [-1, 1] around hover.
    Thrust(f64),
    /// Motors stopped.
    Off,
}

/// An angle wrapped to (-π, π].
pub fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w == -std::f64::consts::PI {
        std::f64::consts::PI
    } else {
        w
    }
}

/// The camera's optical frame (x right, y down, z forward) in the body (FLU), for a camera
/// looking forward from `offset` (metres, FLU).
pub fn body_from_camera(offset: [f64; 3]) -> Isometry3<f64> {
    let [x, y, z] = offset;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_matrix(&nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, //
            -1.0, 0.0, 0.0, //
            0.0, -1.0, 0.0,
        )),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn open_hall() -> World {
        // 20 m × 10 m, walls all round, 0.1 m cells.
        let mut text = String::from("resolution 0.1\nceiling 3.0\n---\n");
        for y in 0..100 {
            for x in 0..200 {
                text.push(if x == 0 || y == 0 || x == 199 || y == 99 {
                    '#'
                } else {
                    '.'
                });
            }
            text.push('\n');
        }
        World::parse_text("hall", &text).unwrap()
    }

    fn fly(v: &mut Vehicle, w: &World, sticks: Sticks, seconds: f64) {
        v.set_sticks(sticks);
        for _ in 0..(seconds / 0.01).round() as usize {
            v.step(w, 0.01);
        }
    }

    fn climb_to_1m(v: &mut Vehicle, w: &World) {
        v.set_armed(true);
        fly(
            v,
            w,
            Sticks {
                throttle: 1.0,
                ..Sticks::CENTRED
            },
            1.2,
        );
        fly(v, w, Sticks::CENTRED, 1.0);
    }

    #[test]
    fn motors_start_only_when_armed() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        fly(
            &mut v,
            &w,
            Sticks {
                throttle: 1.0,
                ..Sticks::CENTRED
            },
            2.0,
        );
        assert_eq!(v.state().position[2], 0.0);
        assert!(v.state().landed);
        assert_eq!(v.state().consumed, 0.0);
        v.set_armed(true);
        fly(
            &mut v,
            &w,
            Sticks {
                throttle: 1.0,
                ..Sticks::CENTRED
            },
            2.0,
        );
        assert!(v.state().position[2] > 1.0, "{:?}", v.state());
        assert!(v.take_events().contains(&VehicleEvent::TookOff));
        assert!(v.battery_voltage() < 12.6);
    }

    #[test]
    fn hover_holds_altitude_at_mid_throttle() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        climb_to_1m(&mut v, &w);
        let z0 = v.state().position[2];
        let mut worst: f64 = 0.0;
        for _ in 0..30 {
            fly(&mut v, &w, Sticks::CENTRED, 1.0);
            worst = worst.max((v.state().position[2] - z0).abs());
        }
        assert!(worst < 0.02, "altitude wandered {worst} m in 30 s");
        let d = (v.state().position[0] - 5.0).hypot(v.state().position[1] - 5.0);
        assert!(d < 0.01, "drifted {d} m with no wind");
    }

    #[test]
    fn a_gust_makes_it_drift_without_position_hold_but_loiter_holds() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        climb_to_1m(&mut v, &w);
        v.set_wind([0.0, 1.0]);
        fly(&mut v, &w, Sticks::CENTRED, 3.0);
        let drift = v.state().position[1] - 5.0;
        assert!(
            drift > 1.0,
            "drifted only {drift} m in a 1 m/s gust over 3 s"
        );
        // LOITER holds the position against the same wind.
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        climb_to_1m(&mut v, &w);
        v.set_mode(FlightMode::Loiter);
        v.set_wind([0.0, 1.0]);
        fly(&mut v, &w, Sticks::CENTRED, 10.0);
        let drift = (v.state().position[1] - 5.0).abs();
        assert!(drift < 0.5, "LOITER drifted {drift} m");
    }

    #[test]
    fn sticks_lean_it_the_way_the_stick_semantics_say() {
        let w = open_hall();
        // Facing +y: pitch forward moves +y, roll right moves +x, yaw right turns clockwise.
        let mut v = Vehicle::new(
            VehicleParams::default(),
            5.0,
            5.0,
            std::f64::consts::FRAC_PI_2,
        );
        climb_to_1m(&mut v, &w);
        fly(
            &mut v,
            &w,
            Sticks {
                pitch: 0.5,
                ..Sticks::CENTRED
            },
            1.0,
        );
        assert!(
            v.state().velocity[1] > 0.5 && v.state().velocity[0].abs() < 0.05,
            "{:?}",
            v.state()
        );
        assert!(v.state().pitch > 0.1);
        fly(
            &mut v,
            &w,
            Sticks {
                roll: 0.5,
                ..Sticks::CENTRED
            },
            1.0,
        );
        assert!(v.state().velocity[0] > 0.3, "{:?}", v.state());
        let yaw0 = v.state().yaw;
        fly(
            &mut v,
            &w,
            Sticks {
                yaw: 0.5,
                ..Sticks::CENTRED
            },
            0.5,
        );
        assert!(v.state().yaw < yaw0 - 0.2, "clockwise is a decreasing yaw");
    }

    #[test]
    fn flown_into_a_wall_it_stops_at_the_wall_and_reports_once() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 17.0, 5.0, 0.0);
        climb_to_1m(&mut v, &w);
        fly(
            &mut v,
            &w,
            Sticks {
                pitch: 1.0,
                ..Sticks::CENTRED
            },
            6.0,
        );
        let x = v.state().position[0];
        // The wall's face is at x = 19.9; the disc of radius 0.2 stops before it.
        assert!(x <= 19.9 - 0.2 + 1e-9 && x > 19.5, "x = {x}");
        assert_eq!(v.state().collisions, 1);
        let hits = v
            .take_events()
            .iter()
            .filter(|e| matches!(e, VehicleEvent::Collision(_)))
            .count();
        assert_eq!(hits, 1);
        // Backing off and hitting again counts again.
        fly(
            &mut v,
            &w,
            Sticks {
                pitch: -1.0,
                ..Sticks::CENTRED
            },
            1.0,
        );
        fly(
            &mut v,
            &w,
            Sticks {
                pitch: 1.0,
                ..Sticks::CENTRED
            },
            3.0,
        );
        assert_eq!(v.state().collisions, 2);
    }

    #[test]
    fn against_a_wall_it_can_slide_along_it_but_never_into_it() {
        let w = open_hall();
        // Facing the east wall at 45°: forward pushes it into the wall and along it (+y).
        let mut v = Vehicle::new(
            VehicleParams::default(),
            18.5,
            3.0,
            std::f64::consts::FRAC_PI_4,
        );
        climb_to_1m(&mut v, &w);
        fly(
            &mut v,
            &w,
            Sticks {
                pitch: 0.6,
                ..Sticks::CENTRED
            },
            4.0,
        );
        let s = v.state();
        assert!(s.position[0] <= 19.9 - 0.2 + 1e-9, "{:?}", s.position);
        assert!(s.position[1] > 4.0, "slid along the wall: {:?}", s.position);
        assert_eq!(s.collisions, 1);
    }

    #[test]
    fn the_ceiling_stops_a_climb() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        v.set_armed(true);
        fly(
            &mut v,
            &w,
            Sticks {
                throttle: 1.0,
                ..Sticks::CENTRED
            },
            6.0,
        );
        assert!(
            (v.state().position[2] - 2.9).abs() < 1e-9,
            "{}",
            v.state().position[2]
        );
        fly(
            &mut v,
            &w,
            Sticks {
                throttle: 1.0,
                ..Sticks::CENTRED
            },
            2.0,
        );
        assert_eq!(v.state().collisions, 1);
    }

    #[test]
    fn land_mode_descends_and_disarming_in_the_air_drops_it() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        climb_to_1m(&mut v, &w);
        v.set_mode(FlightMode::Land);
        fly(&mut v, &w, Sticks::CENTRED, 1.0);
        let vz = v.state().velocity[2];
        assert!((vz + 0.5).abs() < 0.05, "{vz}");
        fly(&mut v, &w, Sticks::CENTRED, 3.0);
        assert!(v.state().landed);
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        climb_to_1m(&mut v, &w);
        v.set_armed(false);
        fly(&mut v, &w, Sticks::CENTRED, 1.0);
        assert!(v.state().landed && v.state().position[2] == 0.0);
    }

    #[test]
    fn guided_takeoff_climbs_to_the_altitude() {
        let w = open_hall();
        let mut v = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        v.set_mode(FlightMode::Guided);
        v.set_armed(true);
        v.takeoff(1.5);
        fly(&mut v, &w, Sticks::CENTRED, 8.0);
        assert!(
            (v.state().position[2] - 1.5).abs() < 0.05,
            "{}",
            v.state().position[2]
        );
    }

    #[test]
    fn camera_looks_forward() {
        let v = Vehicle::new(
            VehicleParams::default(),
            1.0,
            2.0,
            std::f64::consts::FRAC_PI_2,
        );
        let cam = v.map_from_camera();
        let forward = cam.rotation * nalgebra::Vector3::z();
        assert!((forward - nalgebra::Vector3::y()).norm() < 1e-9);
        let down = cam.rotation * nalgebra::Vector3::y();
        assert!((down + nalgebra::Vector3::z()).norm() < 1e-9);
        assert!((cam.translation.vector - nalgebra::Vector3::new(1.0, 2.1, 0.05)).norm() < 1e-9);
    }

    #[test]
    fn a_spent_battery_is_swapped_only_once_the_vehicle_has_rested_disarmed() {
        let w = open_hall();
        let params = VehicleParams {
            battery_swap_s: Some(30.0),
            ..VehicleParams::default()
        };
        let mut v = Vehicle::new(params.clone(), 5.0, 5.0, 0.0);
        v.drain_battery(0.3);
        // Armed on the floor: no one reaches for it.
        v.set_armed(true);
        let low = Sticks {
            throttle: -1.0,
            ..Sticks::CENTRED
        };
        fly(&mut v, &w, low, 40.0);
        assert!(v.state().landed);
        assert!(v.battery_remaining() <= 30);
        // Disarmed: not before 30 s.
        v.set_armed(false);
        fly(&mut v, &w, Sticks::CENTRED, 29.0);
        assert!(v.battery_remaining() <= 30);
        assert!(!v.take_events().contains(&VehicleEvent::BatterySwapped));
        fly(&mut v, &w, Sticks::CENTRED, 2.0);
        assert_eq!(v.battery_remaining(), 100);
        assert!((v.battery_voltage() - 12.6).abs() < 1e-6);
        assert_eq!(v.take_events(), vec![VehicleEvent::BatterySwapped]);
        // Half a battery or more left: kept. Off by default.
        let mut half = Vehicle::new(params, 5.0, 5.0, 0.0);
        half.drain_battery(0.6);
        let mut never = Vehicle::new(VehicleParams::default(), 5.0, 5.0, 0.0);
        never.drain_battery(0.1);
        for v in [&mut half, &mut never] {
            fly(v, &w, Sticks::CENTRED, 60.0);
        }
        assert_eq!(
            (half.battery_remaining(), never.battery_remaining()),
            (60, 10)
        );
    }

    #[test]
    fn wrap_stays_in_range() {
        for a in [
            -10.0,
            -3.2,
            0.0,
            3.2,
            7.0,
            std::f64::consts::PI,
            -std::f64::consts::PI,
        ] {
            let w = wrap(a);
            assert!(w > -std::f64::consts::PI && w <= std::f64::consts::PI);
            assert!(
                ((w - a) / std::f64::consts::TAU).fract().abs() < 1e-9
                    || ((w - a) / std::f64::consts::TAU).fract().abs() > 1.0 - 1e-9
            );
        }
    }
}
