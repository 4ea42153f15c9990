//! Vehicles in a world, stepped in simulated time: physics, sensors, gusts and cameras.
//!
//! Deterministic: the same world, seed and inputs at the same simulated times give the same run,
//! bit for bit (every noise source draws from its own seeded stream).

use std::sync::Arc;
use std::time::Duration;

use link::camera::RgbdFrame;
use nalgebra::Isometry3;

use crate::render::{Camera, render_frame};
use crate::rng::Rng;
use crate::sensors::{Readings, SensorParams, Sensors};
use crate::vehicle::{Vehicle, VehicleParams};
use crate::world::World;

/// Simulation settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Seed of every noise source.
    pub seed: u64,
    /// The camera every vehicle carries (`None`: no cameras).
    pub camera: Option<Camera>,
    /// Camera frames per second of simulated time.
    pub camera_hz: f64,
    /// Turbulence: standard deviation of the wind, m/s (0 = still air).
    pub gust_mps: f64,
    /// Turbulence correlation time, seconds.
    pub gust_tau_s: f64,
    /// Vehicle constants.
    pub vehicle: VehicleParams,
    /// Sensor characteristics.
    pub sensors: SensorParams,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            camera: Some(Camera::kinect(320, 240)),
            camera_hz: 10.0,
            gust_mps: 0.1,
            gust_tau_s: 3.0,
            vehicle: VehicleParams::default(),
            sensors: SensorParams::default(),
        }
    }
}

/// A simulation that cannot be set up.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// More vehicles than the world has start positions.
    #[error("world '{world}' has room for {starts} drones, {asked} were asked for")]
    TooManyVehicles {
        /// The world.
        world: String,
        /// Start positions it has.
        starts: usize,
        /// Vehicles asked for.
        asked: usize,
    },
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
}

/// A camera frame with the camera's true pose (for evaluation; never sent to the station).
#[derive(Debug, Clone)]
pub struct CameraFrame {
    /// The frame as the camera delivers it.
    pub frame: RgbdFrame,
    /// Ground truth: the camera's optical frame in the map when the frame was taken.
    pub map_from_camera: Isometry3<f64>,
}

struct SimVehicle {
    vehicle: Vehicle,
    sensors: Sensors,
    gust_rng: Rng,
    gust: [f64; 2],
    /// Wind set from outside, added to the turbulence.
    wind: [f64; 2],
    next_frame_us: u64,
    frames: u64,
}

/// The simulated fleet in its world.
pub struct Sim {
    world: Arc<World>,
    config: SimConfig,
    vehicles: Vec<SimVehicle>,
    time_us: u64,
}

impl Sim {
    /// `n` vehicles at the world's first `n` start positions, each facing its most open
    /// direction.
    pub fn new(world: Arc<World>, n: usize, config: SimConfig) -> Result<Self, SimError> {
        if n > world.starts().len() {
            return Err(SimError::TooManyVehicles {
                world: world.name().into(),
                starts: world.starts().len(),
                asked: n,
            });
        }
        if !(config.camera_hz.is_finite() && config.camera_hz > 0.0 && config.camera_hz <= 100.0) {
            return Err(SimError::Config(format!(
                "camera rate {} Hz must be in (0, 100]",
                config.camera_hz
            )));
        }
        if !(config.gust_mps.is_finite() && config.gust_mps >= 0.0 && config.gust_tau_s > 0.0) {
            return Err(SimError::Config("gusts need σ ≥ 0 m/s and τ > 0 s".into()));
        }
        let endurance = config.vehicle.endurance_s;
        if !(endurance.is_finite() && endurance >= 60.0) {
            return Err(SimError::Config(format!(
                "flight time {endurance} s must be at least a minute"
            )));
        }
        if let Some(swap) = config.vehicle.battery_swap_s
            && !(swap.is_finite() && (0.0..=3600.0).contains(&swap))
        {
            return Err(SimError::Config(format!(
                "battery swap after {swap} s must be between 0 s and an hour"
            )));
        }
        let vehicles = (0..n)
            .map(|k| {
                let [x, y] = world.starts()[k];
                let yaw = open_heading(&world, [x, y]);
                SimVehicle {
                    vehicle: Vehicle::new(config.vehicle.clone(), x, y, yaw),
                    sensors: Sensors::new(
                        config.sensors.clone(),
                        Rng::new(config.seed, 100 + k as u64),
                    ),
                    gust_rng: Rng::new(config.seed, 200 + k as u64),
                    gust: [0.0; 2],
                    wind: [0.0; 2],
                    next_frame_us: (1e6 / config.camera_hz) as u64,
                    frames: 0,
                }
            })
            .collect();
        Ok(Self {
            world,
            config,
            vehicles,
            time_us: 0,
        })
    }

    /// The world.
    pub fn world(&self) -> &Arc<World> {
        &self.world
    }

    /// The settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Simulated time since the start.
    pub fn time(&self) -> Duration {
        Duration::from_micros(self.time_us)
    }

    /// Number of vehicles.
    pub fn len(&self) -> usize {
        self.vehicles.len()
    }

    /// True without vehicles.
    pub fn is_empty(&self) -> bool {
        self.vehicles.is_empty()
    }

    /// Vehicle `k`.
    ///
    /// # Panics
    /// If `k` is out of range.
    pub fn vehicle(&self, k: usize) -> &Vehicle {
        &self.vehicles[k].vehicle
    }

    /// Vehicle `k`, to command it.
    ///
    /// # Panics
    /// If `k` is out of range.
    pub fn vehicle_mut(&mut self, k: usize) -> &mut Vehicle {
        &mut self.vehicles[k].vehicle
    }

    /// Sets a steady wind on vehicle `k` (on top of the turbulence), m/s in the map frame.
    pub fn set_wind(&mut self, k: usize, wind: [f64; 2]) {
        if let Some(v) = self.vehicles.get_mut(k) {
            v.wind = wind;
        }
    }

    /// Samples vehicle `k`'s sensors.
    pub fn sense(&mut self, k: usize) -> Option<Readings> {
        let v = self.vehicles.get_mut(k)?;
        Some(v.sensors.sample(&v.vehicle))
    }

    /// Advances every vehicle by `dt`.
    pub fn step(&mut self, dt: Duration) {
        let h = dt.as_secs_f64();
        let (sigma, tau) = (self.config.gust_mps, self.config.gust_tau_s);
        for v in &mut self.vehicles {
            // Ornstein–Uhlenbeck turbulence with standard deviation σ and correlation time τ.
            let a = (-h / tau).exp();
            let b = sigma * (1.0 - a * a).sqrt();
            for k in 0..2 {
                v.gust[k] = a * v.gust[k] + b * v.gust_rng.normal();
            }
            v.vehicle
                .set_wind([v.wind[0] + v.gust[0], v.wind[1] + v.gust[1]]);
            v.vehicle.step(&self.world, h);
        }
        self.time_us += dt.as_micros() as u64;
    }

    /// The vehicles whose camera frame is due now (each at most once per period).
    pub fn due_cameras(&mut self) -> Vec<usize> {
        if self.config.camera.is_none() {
            return vec![];
        }
        let period = (1e6 / self.config.camera_hz) as u64;
        let now = self.time_us;
        self.vehicles
            .iter_mut()
            .enumerate()
            .filter_map(|(k, v)| {
                (now >= v.next_frame_us).then(|| {
                    v.next_frame_us = (now / period + 1) * period;
                    k
                })
            })
            .collect()
    }

    /// Renders the cameras of `vehicles` now, in parallel over the machine's cores.
    pub fn render(&mut self, vehicles: &[usize]) -> Vec<CameraFrame> {
        self.camera_shots(vehicles).render()
    }

    /// What the cameras of `vehicles` see now, to be rendered later — e.g. by a thread that does
    /// not hold the simulation (see [`Shots::render`]).
    pub fn camera_shots(&mut self, vehicles: &[usize]) -> Shots {
        let poses = vehicles
            .iter()
            .filter_map(|&k| {
                let v = self.vehicles.get_mut(k)?;
                v.frames += 1;
                Some((k, v.vehicle.map_from_camera(), v.frames))
            })
            .collect();
        Shots {
            world: self.world.clone(),
            camera: self.config.camera,
            seed: self.config.seed,
            stamp: self.time(),
            poses,
        }
    }
}

/// Camera frames taken at one instant, not yet rendered.
pub struct Shots {
    world: Arc<World>,
    camera: Option<Camera>,
    seed: u64,
    stamp: Duration,
    poses: Vec<(usize, Isometry3<f64>, u64)>,
}

impl Shots {
    /// True when there is nothing to render.
    pub fn is_empty(&self) -> bool {
        self.camera.is_none() || self.poses.is_empty()
    }

    /// Renders every frame, in parallel over the machine's cores.
    pub fn render(self) -> Vec<CameraFrame> {
        let Some(camera) = self.camera else {
            return vec![];
        };
        let (world, seed, stamp) = (&self.world, self.seed, self.stamp);
        let one = |&(k, pose, n): &(usize, Isometry3<f64>, u64)| CameraFrame {
            frame: render_frame(
                world,
                &pose,
                &camera,
                Some((crate::rng::hash2(seed, k as u64), n)),
                k as u8,
                stamp,
            ),
            map_from_camera: pose,
        };
        let jobs = &self.poses;
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(jobs.len());
        if threads <= 1 {
            return jobs.iter().map(one).collect();
        }
        let chunk = jobs.len().div_ceil(threads);
        std::thread::scope(|scope| {
            let handles: Vec<_> = jobs
                .chunks(chunk)
                .map(|part| scope.spawn(move || part.iter().map(one).collect::<Vec<_>>()))
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_default())
                .collect()
        })
    }
}

/// The heading (of 16) along which the most open space lies from `point_in_map`.
fn open_heading(world: &World, point_in_map: [f64; 2]) -> f64 {
    let step = world.resolution() / 2.0;
    (0..16)
        .map(|i| f64::from(i) * std::f64::consts::TAU / 16.0)
        .map(|a| {
            let (c, s) = (a.cos(), a.sin());
            let mut d = 0.0;
            while d < 20.0 {
                let (x, y) = world.cell_of([point_in_map[0] + d * c, point_in_map[1] + d * s]);
                if world.material(x, y).is_solid() {
                    break;
                }
                d += step;
            }
            (a, d)
        })
        .fold(
            (0.0, -1.0),
            |best, (a, d)| if d > best.1 { (a, d) } else { best },
        )
        .0
}

#[cfg(test)]
mod tests {
    use super::*;
    use link::Sticks;

    fn run(seed: u64) -> (Vec<[f64; 3]>, Vec<u16>) {
        let world = Arc::new(World::load(crate::world::DEFAULT_WORLD).unwrap());
        let mut config = SimConfig {
            seed,
            camera: Some(Camera::kinect(80, 60)),
            ..SimConfig::default()
        };
        config.gust_mps = 0.3;
        let mut sim = Sim::new(world, 2, config).unwrap();
        for k in 0..2 {
            sim.vehicle_mut(k).set_armed(true);
            sim.vehicle_mut(k).set_sticks(Sticks {
                throttle: 0.6,
                ..Sticks::CENTRED
            });
        }
        let mut depth = vec![];
        for i in 0..300 {
            if i == 150 {
                sim.vehicle_mut(0).set_sticks(Sticks::CENTRED);
            }
            sim.step(Duration::from_millis(10));
            let due = sim.due_cameras();
            for f in sim.render(&due) {
                depth.extend(f.frame.depth_mm);
            }
        }
        (
            (0..2).map(|k| sim.vehicle(k).state().position).collect(),
            depth,
        )
    }

    #[test]
    fn the_same_seed_gives_the_same_run_and_another_seed_another() {
        let (a, da) = run(5);
        let (b, db) = run(5);
        let (c, dc) = run(6);
        assert_eq!(a, b);
        assert_eq!(da, db);
        assert_ne!(a, c);
        assert_ne!(da, dc);
        // Frames every 0.1 s up to 3 s: 30 per vehicle.
        assert_eq!(da.len(), 2 * 30 * 80 * 60);
    }

    #[test]
    fn too_many_vehicles_is_a_clear_error() {
        let world = Arc::new(World::load(crate::world::DEFAULT_WORLD).unwrap());
        let e = Sim::new(world, 9, SimConfig::default()).err().unwrap();
        assert_eq!(
            e.to_string(),
            "world 'apartment' has room for 8 drones, 9 were asked for"
        );
    }

    #[test]
    fn the_flight_time_sets_how_long_a_battery_lasts_and_is_checked() {
        let world = Arc::new(World::load(crate::world::DEFAULT_WORLD).unwrap());
        let left_after_a_minute = |endurance_s: f64| {
            let config = SimConfig {
                camera: None,
                gust_mps: 0.0,
                vehicle: VehicleParams {
                    endurance_s,
                    ..VehicleParams::default()
                },
                ..SimConfig::default()
            };
            let mut sim = Sim::new(world.clone(), 1, config).unwrap();
            sim.vehicle_mut(0).set_armed(true);
            sim.vehicle_mut(0).set_sticks(Sticks {
                throttle: 0.3,
                ..Sticks::CENTRED
            });
            for _ in 0..6000 {
                sim.step(Duration::from_millis(10));
            }
            assert!(!sim.vehicle(0).state().landed);
            sim.vehicle(0).battery_remaining()
        };
        // A minute of a 12-minute pack (a little of it on the floor) and of an hour's pack.
        assert!((91..=92).contains(&left_after_a_minute(720.0)));
        assert!((98..=99).contains(&left_after_a_minute(3600.0)));
        for endurance_s in [30.0, f64::NAN, f64::INFINITY] {
            let config = SimConfig {
                vehicle: VehicleParams {
                    endurance_s,
                    ..VehicleParams::default()
                },
                ..SimConfig::default()
            };
            let e = Sim::new(world.clone(), 1, config).err().unwrap();
            assert!(e.to_string().contains("at least a minute"), "{e}");
        }
        for swap in [-1.0, f64::NAN, 1e9] {
            let config = SimConfig {
                vehicle: VehicleParams {
                    battery_swap_s: Some(swap),
                    ..VehicleParams::default()
                },
                ..SimConfig::default()
            };
            let e = Sim::new(world.clone(), 1, config).err().unwrap();
            assert!(e.to_string().contains("battery swap"), "{e}");
        }
    }

    #[test]
    fn drones_start_facing_open_space() {
        let world = Arc::new(World::load(crate::world::DEFAULT_WORLD).unwrap());
        let sim = Sim::new(world.clone(), 8, SimConfig::default()).unwrap();
        for k in 0..8 {
            let s = sim.vehicle(k).state();
            let ahead = [
                s.position[0] + 1.0 * s.yaw.cos(),
                s.position[1] + 1.0 * s.yaw.sin(),
            ];
            assert!(!world.disc_hits_wall(ahead, 0.2), "drone {k} faces a wall");
        }
    }
}
