//! What the mission runtime sees of any vehicle, whatever protocol is behind it.

use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

use crate::heartbeat::LinkState;
use crate::rc::Sticks;

/// A flight mode the station may ask for (ArduPilot Copter names; the shield has none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FlightMode {
    /// Sticks command lean angles; throttle is raw.
    Stabilize,
    /// Sticks command lean angles; mid throttle holds altitude (what the thesis's Naza did).
    AltHold,
    /// Holds position with a position estimate.
    Loiter,
    /// Follows guided setpoints.
    Guided,
    /// Lands where it is.
    Land,
}

impl FlightMode {
    /// All modes, for parsing and help text.
    pub const ALL: [FlightMode; 5] = [
        FlightMode::Stabilize,
        FlightMode::AltHold,
        FlightMode::Loiter,
        FlightMode::Guided,
        FlightMode::Land,
    ];

    /// Upper-case name as ArduPilot prints it.
    pub fn name(self) -> &'static str {
        match self {
            FlightMode::Stabilize => "STABILIZE",
            FlightMode::AltHold => "ALT_HOLD",
            FlightMode::Loiter => "LOITER",
            FlightMode::Guided => "GUIDED",
            FlightMode::Land => "LAND",
        }
    }
}

impl std::str::FromStr for FlightMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let up = s.to_ascii_uppercase().replace('-', "_");
        FlightMode::ALL
            .into_iter()
            .find(|m| m.name() == up || (up == "ALTHOLD" && *m == FlightMode::AltHold))
            .ok_or_else(|| {
                let names: Vec<_> = FlightMode::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "unknown flight mode {s:?}; expected one of {}",
                    names.join(", ")
                )
            })
    }
}

impl fmt::Display for FlightMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A discrete command to a vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// Arm the motors (MAVLink) or the shield's outputs.
    Arm,
    /// Disarm.
    Disarm,
    /// Start the motors (the Naza's stick combination; on MAVLink the same as arming).
    StartMotors,
    /// Land where the vehicle is.
    Land,
    /// Change flight mode.
    SetMode(FlightMode),
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Command::Arm => f.write_str("arm"),
            Command::Disarm => f.write_str("disarm"),
            Command::StartMotors => f.write_str("start motors"),
            Command::Land => f.write_str("land"),
            Command::SetMode(m) => write!(f, "set mode {m}"),
        }
    }
}

/// Why a command did not take effect.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// The vehicle answered and refused.
    #[error("vehicle refused {command}: {reason}")]
    Rejected {
        /// The command.
        command: Command,
        /// The vehicle's answer.
        reason: String,
    },
    /// No answer after every retry.
    #[error(
        "no answer to {command} after {attempts} attempts; check the link and that the vehicle is powered"
    )]
    Timeout {
        /// The command.
        command: Command,
        /// How many times it was sent.
        attempts: u32,
    },
    /// This back end cannot do it.
    #[error("{command} is not supported over {backend}")]
    Unsupported {
        /// The command.
        command: Command,
        /// The link kind.
        backend: &'static str,
    },
    /// The vehicle has not been heard on this link yet.
    #[error("cannot {command}: the vehicle has not been heard on this link yet")]
    NotConnected {
        /// The command.
        command: Command,
    },
    /// The link was closed while the command was pending.
    #[error("link closed before {command} was answered")]
    Closed {
        /// The command.
        command: Command,
    },
}

/// Attitude in the map frame convention (FLU body, ENU-style world): radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Attitude {
    /// Rotation about body x (forward); + = right side down.
    pub roll: f32,
    /// Rotation about body y (left); + = nose down in FLU.
    pub pitch: f32,
    /// Heading about z (up); + = counter-clockwise seen from above.
    pub yaw: f32,
}

/// Battery state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Battery {
    /// Pack voltage, volts.
    pub voltage_v: f32,
    /// Remaining charge in percent, when the vehicle estimates it.
    pub remaining_pct: Option<u8>,
}

/// The latest telemetry of one vehicle; `None` means "not reported by this vehicle".
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Telemetry {
    /// Height above ground (sonar / rangefinder, else relative altitude), metres.
    pub height_m: Option<f32>,
    /// Attitude (roll, pitch, yaw), where the vehicle reports all three.
    pub attitude: Option<Attitude>,
    /// Heading in radians, + = counter-clockwise (IMU yaw on the shield, attitude yaw on MAVLink).
    pub yaw_rad: Option<f32>,
    /// When the message that carried `yaw_rad` (and `attitude`) arrived, on the link's
    /// [`VehicleClock`](crate::VehicleClock): a reader polling at its own rate sees how old the
    /// heading is (and whether it is new), so a turning vehicle's heading is not taken as now.
    pub heading_at: Option<Duration>,
    /// Battery.
    pub battery: Option<Battery>,
    /// Position in the map frame (x forward/north, y left/west, z up), metres, where the
    /// autopilot has one.
    pub position_m: Option<[f32; 3]>,
    /// Velocity in the map frame, m/s.
    pub velocity_mps: Option<[f32; 3]>,
    /// Armed state as the vehicle reports it.
    pub armed: Option<bool>,
    /// Flight mode name as the vehicle reports it.
    pub mode: Option<String>,
}

impl Telemetry {
    /// When the heading (and attitude) arrived, in seconds on the link's clock, read at `now`
    /// on that clock: the stamp, never later than `now`; `now` for a link that does not stamp
    /// them.
    pub fn heading_time(&self, now: f64) -> f64 {
        self.heading_at.map_or(now, |at| at.as_secs_f64().min(now))
    }
}

/// A text message from the vehicle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StatusText {
    /// Syslog severity, 0 = emergency … 7 = debug.
    pub severity: u8,
    /// The text.
    pub text: String,
}

impl StatusText {
    /// The severity of a warning (MAVLink's `MAV_SEVERITY_WARNING`); lower is worse.
    pub const WARNING: u8 = 4;

    /// True for a warning or worse: what the operator must not miss.
    pub fn is_warning(&self) -> bool {
        self.severity <= Self::WARNING
    }
}

/// Link health for displays and failsafes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkStatus {
    /// The state.
    pub state: LinkState,
    /// Age of the last message from the vehicle.
    pub last_message_age: Option<Duration>,
    /// Whether the transport is connected right now.
    pub transport_up: bool,
    /// How many times the transport has been (re)connected.
    pub connections: u32,
    /// Frames received intact.
    pub frames_ok: u64,
    /// Input dropped: bad frames, runs of garbage bytes, rejected signatures.
    pub frames_bad: u64,
}

/// One vehicle, reached over any link. Every method returns at once except [`Self::command`],
/// which waits for the vehicle's answer.
pub trait VehicleLink: Send + Sync {
    /// A short name for logs ("mavlink udpin:0.0.0.0:14550 #1").
    fn name(&self) -> String;
    /// Sets the sticks re-sent at the RC rate; `None` releases control back to the vehicle's own
    /// radio (MAVLink) or centres the sticks (shield, which has no radio of its own).
    fn set_sticks(&self, sticks: Option<Sticks>);
    /// Sends a command and waits for its acknowledgement, retrying on silence.
    fn command(&self, command: Command) -> Result<(), CommandError>;
    /// The latest telemetry.
    fn telemetry(&self) -> Telemetry;
    /// The link's health now.
    fn status(&self) -> LinkStatus;
    /// Takes the status texts received since the last call.
    fn take_status_texts(&self) -> Vec<StatusText>;
}

/// Keeps the most recent status texts (at most `cap`), oldest dropped first.
#[derive(Debug, Default)]
pub(crate) struct TextQueue(VecDeque<StatusText>);

impl TextQueue {
    const CAP: usize = 64;

    pub(crate) fn push(&mut self, t: StatusText) {
        if self.0.len() == Self::CAP {
            self.0.pop_front();
        }
        self.0.push_back(t);
    }

    pub(crate) fn take(&mut self) -> Vec<StatusText> {
        self.0.drain(..).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_heading_is_timed_by_its_stamp_never_later_than_now() {
        let unstamped = Telemetry::default();
        assert_eq!(unstamped.heading_time(2.5), 2.5);
        let stamped = Telemetry {
            heading_at: Some(Duration::from_millis(2250)),
            ..Telemetry::default()
        };
        assert_eq!(stamped.heading_time(2.5), 2.25);
        // A stamp ahead of the reader's clock (another thread read the clock later) is now.
        assert_eq!(stamped.heading_time(2.0), 2.0);
    }

    #[test]
    fn modes_parse_by_name_and_say_what_is_known() {
        assert_eq!(
            "alt_hold".parse::<FlightMode>().unwrap(),
            FlightMode::AltHold
        );
        assert_eq!("LAND".parse::<FlightMode>().unwrap(), FlightMode::Land);
        let e = "hover".parse::<FlightMode>().unwrap_err();
        assert!(
            e.contains("STABILIZE, ALT_HOLD, LOITER, GUIDED, LAND"),
            "{e}"
        );
    }

    #[test]
    fn text_queue_keeps_the_newest() {
        let mut q = TextQueue::default();
        for i in 0..100 {
            q.push(StatusText {
                severity: 6,
                text: i.to_string(),
            });
        }
        let t = q.take();
        assert_eq!(t.len(), TextQueue::CAP);
        assert_eq!(t.last().unwrap().text, "99");
        assert!(q.take().is_empty());
    }
}
