//! The link layer's shield adapter flies a `sitl run` shield vehicle over pseudo-terminals (a
//! null-modem pair of serial devices): arm, climb, hold; then the link drops and the shield's
//! failsafe lands and disarms the drone on its own.

mod common;

use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use common::SitlProcess;
use link::shield::{ShieldConfig, ShieldLink};
use link::{Command, LinkState, Sticks, VehicleLink};
use tests::{eventually, pty_pair};

const S: Duration = Duration::from_secs(1);

/// Copies bytes between two pseudo-terminal masters while `up`; drops them otherwise (a radio
/// link fading out).
fn relay(mut from: Box<dyn Read + Send>, mut to: Box<dyn Write + Send>, up: Arc<AtomicBool>) {
    std::thread::spawn(move || {
        let mut buf = [0u8; 512];
        loop {
            match from.read(&mut buf) {
                Ok(0) => {}
                Ok(n) if up.load(Ordering::Relaxed) => {
                    if to.write_all(&buf[..n]).is_err() {
                        return;
                    }
                }
                Ok(_) => {}
                Err(e) if link::transport::is_timeout(&e) => {}
                Err(_) => std::thread::sleep(Duration::from_millis(20)),
            }
        }
    });
}

#[test]
fn the_shield_adapter_flies_a_sitl_shield_vehicle_and_the_failsafe_lands_it() {
    let (drone_path, drone_side, _drone_port) = pty_pair();
    let (station_path, station_side, _station_port) = pty_pair();
    let up = Arc::new(AtomicBool::new(true));
    relay(drone_side.reader, station_side.writer, up.clone());
    relay(station_side.reader, drone_side.writer, up.clone());

    let vehicle = format!("shield@serial:{drone_path}:115200");
    let _sitl = SitlProcess::start(&[
        "run",
        "--vehicle",
        &vehicle,
        "--gust",
        "0",
        "--duration",
        "120",
    ]);
    let link = ShieldLink::connect(
        &format!("serial:{station_path}:115200")
            .parse()
            .expect("address"),
        ShieldConfig::default(),
    )
    .expect("open the station's serial device");
    assert!(
        eventually(5 * S, || link.status().state == LinkState::Connected),
        "{:?}",
        link.status()
    );
    let t = link.telemetry();
    assert_eq!(t.armed, Some(false));
    assert!(t.height_m.is_some_and(|h| h < 0.1), "{t:?}");
    assert!(t.battery.is_some_and(|b| b.voltage_v > 12.0), "{t:?}");

    link.command(Command::Arm).expect("arm");
    link.command(Command::StartMotors).expect("start motors");
    link.set_sticks(Some(Sticks {
        throttle: 0.7,
        ..Sticks::CENTRED
    }));
    assert!(
        eventually(5 * S, || link.telemetry().height_m.is_some_and(|h| h > 1.0)),
        "did not climb: {:?}",
        link.telemetry()
    );
    link.set_sticks(Some(Sticks::CENTRED));
    std::thread::sleep(S);
    let h0 = link.telemetry().height_m.unwrap_or(f32::NAN);
    std::thread::sleep(2 * S);
    let h1 = link.telemetry().height_m.unwrap_or(f32::NAN);
    assert!((h1 - h0).abs() < 0.1, "altitude hold: {h0} → {h1}");
    assert_eq!(link.telemetry().armed, Some(true));

    // The radio link fades: the station keeps sending, nothing arrives.
    up.store(false, Ordering::Relaxed);
    assert!(
        eventually(10 * S, || link.status().state == LinkState::Lost),
        "{:?}",
        link.status()
    );
    std::thread::sleep(8 * S); // failsafe after 1 s, descent, 1 s on the floor, disarm
    up.store(true, Ordering::Relaxed);
    assert!(eventually(5 * S, || link.status().state == LinkState::Connected));
    let t = link.telemetry();
    assert_eq!(
        t.armed,
        Some(false),
        "the failsafe should have disarmed it: {t:?}"
    );
    assert!(
        t.height_m.is_some_and(|h| h < 0.1),
        "it should be on the floor: {t:?}"
    );
}
