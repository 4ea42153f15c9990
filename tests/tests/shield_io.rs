//! The shield adapter against the shield emulator over real I/O: a pseudo-terminal pair and
//! loopback TCP.

use std::io::Write;
use std::time::Duration;

use link::shield::{EmulatorConfig, EmulatorServer, ShieldConfig, ShieldLink};
use link::{
    ChannelMap, Command, FlightMode, LinkState, Pulses, Sticks, Transport, VehicleClock,
    VehicleLink,
};
use tests::{eventually, pty_pair};

const S: Duration = Duration::from_secs(1);

#[test]
fn flies_the_emulator_over_a_pseudo_terminal_through_noise() {
    let (path, conn, mut line) = pty_pair();
    let emulator = EmulatorServer::spawn_on(conn, EmulatorConfig::default());
    let link = ShieldLink::connect(
        &format!("serial:{path}:115200").parse().expect("address"),
        ShieldConfig::default(),
    )
    .expect("open the pty");
    assert!(
        eventually(3 * S, || link.status().state == LinkState::Connected),
        "{:?}",
        link.status()
    );
    let t = link.telemetry();
    assert_eq!(t.battery.map(|b| b.voltage_v), Some(12.6));
    assert_eq!(t.height_m, Some(0.0));
    assert_eq!(t.armed, Some(false));
    // The heading is stamped on the link's clock as it arrives, each new one anew.
    let at = t.heading_at.expect("heading stamped");
    assert!(at <= VehicleClock::wall().now(), "{at:?}");
    assert!(eventually(S, || link
        .telemetry()
        .heading_at
        .is_some_and(|later| later > at)));

    // Start is refused before arming; then arm, start.
    assert!(link.command(Command::StartMotors).is_err());
    link.command(Command::Arm).expect("arm");
    link.command(Command::StartMotors).expect("start motors");
    assert!(emulator.with(|e| e.flags().armed && e.flags().motors_running));
    assert!(eventually(S, || link.telemetry().armed == Some(true)));
    assert!(matches!(
        link.command(Command::SetMode(FlightMode::Loiter)),
        Err(link::CommandError::Unsupported { .. })
    ));

    let sticks = Sticks {
        roll: 0.2,
        pitch: -0.4,
        yaw: 0.1,
        throttle: 0.5,
    };
    let want = ChannelMap::thesis_naza().pulses(&sticks);
    link.set_sticks(Some(sticks));
    assert!(eventually(S, || emulator.with(|e| e.outputs()) == Some(want)));

    // Nobody else may open the device while the link has it (serialport locks it).
    assert!(serialport::new(&path, 115_200).open().is_err());
    // Noise from a second writer on the same line, and noise from the shield's side.
    let mut x: u32 = 12345;
    for _ in 0..50 {
        let burst: Vec<u8> = (0..64)
            .map(|_| {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                (x >> 16) as u8
            })
            .collect();
        line.write_all(&burst).expect("write noise");
        emulator.with(|e| e.queue_upstream_raw(&burst));
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(300));
    let (history, bad, flags) =
        emulator.with(|e| (e.history().to_vec(), e.commands_bad, e.flags()));
    assert!(bad > 0, "the shield must have dropped the noise");
    let first = history
        .iter()
        .position(|p| *p == want)
        .expect("sticks applied");
    let wrong: Vec<&Pulses> = history[first..].iter().filter(|p| **p != want).collect();
    assert!(wrong.is_empty(), "noise produced pulses {wrong:?}");
    assert!(
        flags.armed && !flags.failsafe,
        "noise must not disarm or trip the failsafe: {flags:?}"
    );
    assert!(link.status().frames_bad > 0);
    assert_eq!(link.status().state, LinkState::Connected);

    link.command(Command::Disarm).expect("disarm");
    assert!(!emulator.with(|e| e.flags().armed));
}

#[test]
fn tcp_link_loss_is_seen_by_both_sides() {
    let transport = Transport::open(&"tcpin:127.0.0.1:0".parse().expect("address")).expect("bind");
    let port = transport.local_addr().expect("bound").port();
    let emulator = EmulatorServer::spawn(transport, EmulatorConfig::default());
    let link = ShieldLink::connect(
        &format!("tcpout:127.0.0.1:{port}").parse().expect("address"),
        ShieldConfig::default(),
    )
    .expect("connect");
    assert!(eventually(3 * S, || link.status().state == LinkState::Connected));
    link.command(Command::Arm).expect("arm");
    link.set_sticks(Some(Sticks::CENTRED));
    emulator.with(|e| {
        e.set_sensors(link::shield::Sensors {
            sonar_mm: Some(1200),
            ..Default::default()
        })
    });

    // The station goes away: the shield lands on its own within its 1 s failsafe.
    drop(link);
    assert!(eventually(2 * S, || emulator
        .with(|e| e.flags().failsafe && e.flags().landing)));

    // A new station connects to the same shield; then the shield goes away: the station sees the
    // link degrade and be lost within 5 telemetry periods (1 s).
    let link = ShieldLink::connect(
        &format!("tcpout:127.0.0.1:{port}").parse().expect("address"),
        ShieldConfig::default(),
    )
    .expect("connect");
    assert!(eventually(3 * S, || link.status().state == LinkState::Connected));
    drop(emulator);
    assert!(eventually(S, || link.status().state == LinkState::Degraded));
    assert!(
        eventually(2 * S, || link.status().state == LinkState::Lost),
        "{:?}",
        link.status()
    );
}
