//! Link health from the time of the last message heard: connecting, connected, degraded, lost.

use std::time::{Duration, Instant};

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

/// Tracks when a vehicle was last heard and turns that into a [`LinkState`].
#[derive(Debug, Clone)]
pub struct HeartbeatMonitor {
    period: Duration,
    last_heard: Option<Instant>,
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
    pub fn heard(&mut self, now: Instant) {
        self.last_heard = Some(now);
    }

    /// Age of the last heartbeat at `now`, `None` if never heard.
    pub fn age(&self, now: Instant) -> Option<Duration> {
        self.last_heard.map(|t| now.saturating_duration_since(t))
    }

    /// The link state at `now`.
    pub fn state(&self, now: Instant) -> LinkState {
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
        let t0 = Instant::now();
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
}
