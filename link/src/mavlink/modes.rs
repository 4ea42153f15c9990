//! ArduPilot Copter flight modes (the `custom_mode` numbers of its HEARTBEAT).

use crate::vehicle::FlightMode;

/// ArduCopter's mode numbers and names.
const COPTER_MODES: [(u32, &str); 18] = [
    (0, "STABILIZE"),
    (1, "ACRO"),
    (2, "ALT_HOLD"),
    (3, "AUTO"),
    (4, "GUIDED"),
    (5, "LOITER"),
    (6, "RTL"),
    (7, "CIRCLE"),
    (9, "LAND"),
    (11, "DRIFT"),
    (13, "SPORT"),
    (14, "FLIP"),
    (15, "AUTOTUNE"),
    (16, "POSHOLD"),
    (17, "BRAKE"),
    (18, "THROW"),
    (20, "GUIDED_NOGPS"),
    (21, "SMART_RTL"),
];

/// The ArduCopter `custom_mode` for a flight mode.
pub fn copter_custom_mode(mode: FlightMode) -> u32 {
    match mode {
        FlightMode::Stabilize => 0,
        FlightMode::AltHold => 2,
        FlightMode::Guided => 4,
        FlightMode::Loiter => 5,
        FlightMode::Land => 9,
    }
}

/// The name of an ArduCopter `custom_mode`, or `MODE(n)` for one it does not have.
pub fn copter_mode_name(custom_mode: u32) -> String {
    COPTER_MODES
        .iter()
        .find(|(n, _)| *n == custom_mode)
        .map_or_else(
            || format!("MODE({custom_mode})"),
            |(_, name)| (*name).to_owned(),
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_flight_mode_has_its_ardupilot_name() {
        for m in FlightMode::ALL {
            assert_eq!(copter_mode_name(copter_custom_mode(m)), m.name());
        }
        assert_eq!(copter_mode_name(99), "MODE(99)");
    }
}
