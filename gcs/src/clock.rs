//! The mission's clock: wall time for real vehicles, the simulator's time for simulated ones
//! (whose timeouts and rates count simulated seconds, however fast the simulation runs).

use std::sync::Arc;
use std::time::{Duration, Instant};

use link::VehicleClock;

/// Seconds since the mission's epoch, from any thread.
pub trait Clock: Send + Sync {
    /// Seconds now.
    fn now(&self) -> f64;
    /// Simulated seconds per real second (1 for wall time): rates sent to vehicles scale with it.
    fn speed(&self) -> f64 {
        1.0
    }
}

/// Wall time from the moment it was made.
#[derive(Debug, Clone, Copy)]
pub struct WallClock(Instant);

impl WallClock {
    /// A clock at zero now.
    pub fn start() -> Self {
        Self(Instant::now())
    }
}

impl Clock for WallClock {
    fn now(&self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
}

/// The simulator's time.
#[derive(Debug, Clone)]
pub struct SimulatedClock {
    /// The running simulator's time.
    pub clock: sitl::SimClock,
    /// Its speed relative to real time.
    pub speed: f64,
}

impl Clock for SimulatedClock {
    fn now(&self) -> f64 {
        self.clock.now().as_secs_f64()
    }
    fn speed(&self) -> f64 {
        self.speed
    }
}

/// The mission's `clock` as a link's clock: the link's heartbeat timeouts and rates count it,
/// and the times it stamps on telemetry ([`link::Telemetry::heading_at`]) are mission times.
pub fn link_clock(clock: &Arc<dyn Clock>) -> VehicleClock {
    let mission = clock.clone();
    VehicleClock::new(clock.speed(), move || {
        Duration::try_from_secs_f64(mission.now()).unwrap_or_default()
    })
}
