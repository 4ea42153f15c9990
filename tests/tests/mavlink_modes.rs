//! The station's MAVLink link against the simulated ArduCopter on a loopback socket: the flight
//! mode it reports.

mod common;

use std::time::Duration;

use common::copter;
use link::mavlink::{MavlinkConfig, MavlinkLink};
use link::{Command, FlightMode, VehicleLink};
use tests::eventually;

const S: Duration = Duration::from_secs(1);

#[test]
fn a_mode_change_the_vehicle_accepted_is_its_mode_at_once() {
    // Heartbeats (1 Hz) carry the mode. Before, the link kept the old one until the next: a
    // drone taken off again after a landing read LAND for up to a second in the air, and the
    // station took that for the vehicle landing on its own.
    let sitl = copter("tcpin:127.0.0.1:0");
    let port = sitl.endpoint_addrs()[0].expect("a TCP port").port();
    let link = MavlinkLink::connect(
        &format!("tcpout:127.0.0.1:{port}").parse().expect("address"),
        MavlinkConfig::default(),
    )
    .expect("open the link");
    let v = link.wait_for_vehicle(5 * S).expect("no vehicle heard");
    assert!(eventually(3 * S, || v.telemetry().mode.is_some()));
    for mode in [
        FlightMode::Land,
        FlightMode::AltHold,
        FlightMode::Loiter,
        FlightMode::AltHold,
    ] {
        v.command(Command::SetMode(mode)).expect("set mode");
        assert_eq!(v.telemetry().mode.as_deref(), Some(mode.name()));
        assert_eq!(sitl.with_sim(|s| s.vehicle(0).mode()), mode);
    }
}
