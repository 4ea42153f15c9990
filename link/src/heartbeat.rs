//! Link health from the time of the last message heard: connecting, connected, degraded, lost,
//! counted on the clock the vehicle lives by.

use std::fmt;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// The time a vehicle lives in, as its link reads it: wall time for a real vehicle, the
/// simulator's time for a simulated one. Heartbeat timeouts count this time, so a simulation
/// held up (by a loaded machine, or a station that it waits for) is not taken for a silent
/// vehicle, and a simulation run faster than real time keeps the vehicle's own timings.
#[derive(Clone)]
pub struct VehicleClock {
    now: Arc<dyn Fn() -> Duration + Send + Sync>,
    speed: f64,
}

impl VehicleClock {
    /// Wall time (seconds since the first wall clock was made in this process).
    pub fn wall() -> Self {
        static EPOCH: OnceLock<Instant> = OnceLock::new();
        let epoch = *EPOCH.get_or_init(Instant::now);
        Self {
            now: Arc::new(move || epoch.elapsed()),
            speed: 1.0,
        }
    }

    /// A clock read by `now`, expected to run `speed` times as fast as wall time (used to pace
    /// what the station sends: a heartbeat every period of this clock).
    pub fn new(speed: f64, now: impl Fn() -> Duration + Send + Sync + 'static) -> Self {
        Self {
            now: Arc::new(now),
            speed: if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            },
        }
    }

    /// The time now.
    pub fn now(&self) -> Duration {
        (self.now)()
    }

    /// Nominal seconds of this clock per wall second.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The wall time in which `period` of this clock nominally passes.
    pub fn wall_period(&self, period: Duration) -> Duration {
        period.div_f64(self.speed)
    }
}

impl Default for VehicleClock {
    fn default() -> Self {
        Self::wall()
    }
}

impl fmt::Debug for VehicleClock {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("VehicleClock")
            .field("speed", &self.speed)
            .finish_non_exhaustive()
    }
}

/// The state of a vehicle link as the operator sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LinkState {
    /// Nothing heard from the vehicle yet.
    Connecting,
    /// Heartbeats arrive on time.
    Connected,
    /// At least one heartbeat is late.
    Degraded,
    /// No heartbeat for [`HeartbeatMonitor::LOST_AFTER`] periods: the vehicle is gone.
    Lost,
}

impl LinkState {
    /// Lower-case name for displays and JSON.
    pub fn name(self) -> &'static str {
        match self {
            LinkState::Connecting => "connecting",
            LinkState::Connected => "connected",
            LinkState::Degraded => "degraded",
            LinkState::Lost => "lost",
        }
    }
}

/// Tracks when a vehicle was last heard and turns that into a [`LinkState`]. Times are read from
/// the vehicle's [`VehicleClock`].
#[derive(Debug, Clone)]
pub struct HeartbeatMonitor {
    period: Duration,
    last_heard: Option<Duration>,
}

impl HeartbeatMonitor {
    /// Late by this many periods: degraded.
    pub const DEGRADED_AFTER: f64 = 1.5;
    /// Missing this many periods: lost.
    pub const LOST_AFTER: f64 = 5.0;

    /// A monitor for a vehicle that sends a heartbeat every `period`.
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            last_heard: None,
        }
    }

    /// Records a heartbeat (or any message that proves the vehicle is there) at `now`.
    pub fn heard(&mut self, now: Duration) {
        self.last_heard = Some(now);
    }

    /// Age of the last heartbeat at `now`, `None` if never heard.
    pub fn age(&self, now: Duration) -> Option<Duration> {
        self.last_heard.map(|t| now.saturating_sub(t))
    }

    /// The link state at `now`.
    pub fn state(&self, now: Duration) -> LinkState {
        match self.age(now) {
            None => LinkState::Connecting,
            Some(age) => {
                let periods = age.as_secs_f64() / self.period.as_secs_f64();
                if periods >= Self::LOST_AFTER {
                    LinkState::Lost
                } else if periods >= Self::DEGRADED_AFTER {
                    LinkState::Degraded
                } else {
                    LinkState::Connected
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_follow_the_age_of_the_last_heartbeat() {
        let t0 = Duration::from_secs(100);
        let s = Duration::from_secs(1);
        let mut m = HeartbeatMonitor::new(s);
        assert_eq!(m.state(t0), LinkState::Connecting);
        m.heard(t0);
        assert_eq!(
            m.state(t0 + Duration::from_millis(1400)),
            LinkState::Connected
        );
        assert_eq!(
            m.state(t0 + Duration::from_millis(1600)),
            LinkState::Degraded
        );
        assert_eq!(
            m.state(t0 + Duration::from_millis(4900)),
            LinkState::Degraded
        );
        assert_eq!(m.state(t0 + 5 * s), LinkState::Lost);
        m.heard(t0 + 6 * s);
        assert_eq!(m.state(t0 + 6 * s), LinkState::Connected);
        assert_eq!(m.age(t0 + 7 * s), Some(s));
    }

    #[test]
    fn a_clock_reads_its_source_and_paces_by_its_speed() {
        let t = Arc::new(std::sync::Mutex::new(Duration::from_secs(7)));
        let source = t.clone();
        let clock = VehicleClock::new(4.0, move || *source.lock().expect("lock"));
        assert_eq!(clock.now(), Duration::from_secs(7));
        *t.lock().expect("lock") = Duration::from_secs(9);
        assert_eq!(clock.now(), Duration::from_secs(9));
        assert_eq!(
            clock.wall_period(Duration::from_secs(1)),
            Duration::from_millis(250)
        );
        // A nonsense speed paces as wall time rather than never or at once.
        let odd = VehicleClock::new(f64::NAN, Duration::default);
        assert_eq!(
            odd.wall_period(Duration::from_secs(1)),
            Duration::from_secs(1)
        );
        let wall = VehicleClock::wall();
        let a = wall.now();
        std::thread::sleep(Duration::from_millis(5));
        assert!(wall.now() >= a + Duration::from_millis(5));
    }
}
