//! Both links through the fault-injecting proxy (`tests::faults`) on real pseudo-terminals and
//! loopback sockets: chunks dropped, duplicated, corrupted, reordered and delayed, the line
//! stalled, the connection cut.

mod common;

use std::collections::HashSet;
use std::time::{Duration, Instant};

use common::copter;
use link::mavlink::{MavlinkConfig, MavlinkLink, MavlinkVehicle};
use link::shield::{EmulatorConfig, EmulatorServer, Sensors, ShieldConfig, ShieldLink};
use link::{ChannelMap, Command, LinkState, Sticks, Transport, VehicleLink};
use sitl::Sitl;
use tests::eventually;
use tests::faults::{Counts, Direction, FaultProxy, Faults};

const S: Duration = Duration::from_secs(1);

/// A shield emulator on the proxy's vehicle pseudo-terminal, and the station's link on the other.
fn shield_through(proxy: &FaultProxy) -> (EmulatorServer, ShieldLink) {
    let vehicle = format!(
        "serial:{}:115200",
        proxy.vehicle_path().expect("a pty proxy")
    );
    let emulator = EmulatorServer::spawn(
        Transport::open(&vehicle.parse().expect("address")).expect("open the vehicle's pty"),
        EmulatorConfig::default(),
    );
    let link = ShieldLink::connect(
        &proxy.station_address().parse().expect("address"),
        ShieldConfig::default(),
    )
    .expect("open the station's pty");
    assert!(
        eventually(5 * S, || link.status().state == LinkState::Connected),
        "{:?}",
        link.status()
    );
    (emulator, link)
}

/// A command through a lossy line: the link retries on its own; an operator tries again.
fn command_until_done(link: &dyn VehicleLink, command: Command) {
    let mut last = None;
    for _ in 0..5 {
        match link.command(command) {
            Ok(()) => return,
            Err(e) => last = Some(e),
        }
    }
    panic!("{command:?} failed five times: {last:?}");
}

#[test]
fn the_shield_never_applies_a_wrong_pulse_through_a_lossy_pseudo_terminal() {
    let proxy = FaultProxy::pty(7).expect("pseudo-terminals");
    let (emulator, link) = shield_through(&proxy);
    proxy.set_both(Faults::all(0.05, Duration::from_millis(3)));
    command_until_done(&link, Command::Arm);
    command_until_done(&link, Command::StartMotors);

    let map = ChannelMap::thesis_naza();
    let mut commanded = HashSet::new();
    let mut last = None;
    for i in 0..40 {
        let t = i as f32 / 40.0;
        let sticks = Sticks {
            roll: 0.5 * (6.0 * t).sin(),
            pitch: -0.4 * (4.0 * t).cos(),
            yaw: 0.3 * t,
            throttle: 0.2 + 0.5 * t,
        };
        let pulses = map.pulses(&sticks);
        commanded.insert(pulses);
        last = Some(pulses);
        link.set_sticks(Some(sticks));
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        eventually(2 * S, || emulator.with(|e| e.outputs()) == last),
        "the last sticks never arrived"
    );
    let (history, bad, flags) =
        emulator.with(|e| (e.history().to_vec(), e.commands_bad, e.flags()));
    let first = history
        .iter()
        .position(|p| commanded.contains(p))
        .expect("sticks applied");
    let wrong: Vec<_> = history[first..]
        .iter()
        .filter(|p| !commanded.contains(p))
        .collect();
    assert!(wrong.is_empty(), "pulses nobody commanded: {wrong:?}");
    let distinct: HashSet<_> = history[first..].iter().collect();
    assert!(
        distinct.len() >= 30,
        "only {} of 40 stick settings reached the outputs",
        distinct.len()
    );
    assert!(
        flags.armed && !flags.failsafe,
        "5 % loss must not trip the failsafe: {flags:?}"
    );
    let up = proxy.counts(Direction::Up);
    assert!(
        up.corrupted > 0 && up.dropped > 0 && up.duplicated > 0 && up.reordered > 0,
        "every fault must have happened: {up:?}"
    );
    assert!(bad > 0, "the shield must have refused corrupted commands");
    assert!(
        link.status().frames_bad > 0,
        "the station must have refused corrupted telemetry"
    );
}

#[test]
fn a_stalled_line_trips_the_shield_failsafe_and_is_seen_lost_within_its_bounds_then_recovers() {
    let proxy = FaultProxy::pty(11).expect("pseudo-terminals");
    let (emulator, link) = shield_through(&proxy);
    command_until_done(&link, Command::Arm);
    command_until_done(&link, Command::StartMotors);
    link.set_sticks(Some(Sticks::CENTRED));
    emulator.with(|e| {
        e.set_sensors(Sensors {
            sonar_mm: Some(1200),
            ..Default::default()
        })
    });
    std::thread::sleep(Duration::from_millis(300));

    let stalled = Instant::now();
    proxy.stall(true);
    // The shield lands after 1 s without a command; the station calls the link lost after five
    // 0.2 s telemetry periods.
    assert!(eventually(3 * S, || emulator.with(|e| e.flags().failsafe)));
    let failsafe_after = stalled.elapsed();
    assert!(eventually(3 * S, || link.status().state == LinkState::Lost));
    let lost_after = stalled.elapsed();
    assert!(
        failsafe_after <= Duration::from_millis(1400),
        "failsafe after {failsafe_after:?} (bound 1 s)"
    );
    assert!(
        lost_after <= Duration::from_millis(1400),
        "lost after {lost_after:?} (bound 1 s)"
    );
    assert!(emulator.with(|e| e.flags().landing));

    proxy.stall(false);
    assert!(eventually(3 * S, || link.status().state == LinkState::Connected));
    // The shield keeps landing (a failsafe is not undone by a returning station) and the station
    // sees it in the telemetry.
    assert!(eventually(S, || link.telemetry().armed == Some(true)));
    assert!(emulator.with(|e| e.flags().landing));
}

/// The station's MAVLink link through the proxy, and the first vehicle it hears.
fn station_through(proxy: &FaultProxy) -> (MavlinkLink, MavlinkVehicle) {
    let link = MavlinkLink::connect(
        &proxy.station_address().parse().expect("address"),
        MavlinkConfig::default(),
    )
    .expect("open the link");
    let vehicle = link
        .wait_for_vehicle(5 * S)
        .expect("no vehicle heard through the proxy");
    (link, vehicle)
}

/// The yaw stick the simulated flight controller acts on.
fn yaw_at_vehicle(sitl: &Sitl) -> f32 {
    sitl.with_sim(|s| s.vehicle(0).sticks().yaw)
}

fn yaw_arrives(sitl: &Sitl, yaw: f32, limit: Duration) -> bool {
    eventually(limit, || (yaw_at_vehicle(sitl) - yaw).abs() < 0.02)
}

const SLOW_TURN: Sticks = Sticks {
    roll: 0.0,
    pitch: 0.0,
    yaw: 0.3,
    throttle: -1.0,
};

#[test]
fn mavlink_over_a_lossy_udp_link_arms_and_its_overrides_arrive() {
    let sitl = copter("udpin:127.0.0.1:0");
    let vehicle = sitl.endpoint_addrs()[0].expect("a UDP port");
    let proxy = FaultProxy::udp(vehicle, 3).expect("proxy");
    proxy.set_both(Faults {
        drop: 0.1,
        duplicate: 0.05,
        corrupt: 0.05,
        reorder: 0.05,
        delay: Duration::from_millis(10),
        jitter: Duration::from_millis(20),
    });
    let (_link, v) = station_through(&proxy);
    v.set_sticks(Some(SLOW_TURN));
    command_until_done(&v, Command::Arm);
    assert!(yaw_arrives(&sitl, 0.3, 3 * S), "overrides never arrived");

    // At least five seconds of lossy flight, and on until each way has lost more than five chunks
    // and the telemetry has been corrupted and duplicated (the downlink carries only ~8 chunks a
    // second, so five seconds alone sometimes saw just five drops): the link never counts as lost
    // and the vehicle stays armed.
    let start = Instant::now();
    let faults_seen = |up: Counts, down: Counts| {
        up.dropped > 5 && down.dropped > 5 && down.corrupted > 0 && down.duplicated > 0
    };
    while start.elapsed() < 5 * S
        || (start.elapsed() < 30 * S
            && !faults_seen(proxy.counts(Direction::Up), proxy.counts(Direction::Down)))
    {
        assert_ne!(v.status().state, LinkState::Lost, "{:?}", v.status());
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(sitl.with_sim(|s| s.vehicle(0).state().armed));
    assert!((yaw_at_vehicle(&sitl) - 0.3).abs() < 0.02);
    let (up, down) = (proxy.counts(Direction::Up), proxy.counts(Direction::Down));
    assert!(up.dropped > 5 && down.dropped > 5, "{up:?} {down:?}");
    assert!(down.corrupted > 0 && down.duplicated > 0, "{down:?}");
    assert!(
        v.status().frames_bad > 0,
        "corrupted telemetry must be refused"
    );
}

#[test]
fn mavlink_over_tcp_sees_a_stall_within_its_bound_and_overrides_resume_after_a_reconnect() {
    let sitl = copter("tcpin:127.0.0.1:0");
    let vehicle = sitl.endpoint_addrs()[0].expect("a TCP port");
    let proxy = FaultProxy::tcp(vehicle, 5).expect("proxy");
    let (_link, v) = station_through(&proxy);
    v.set_sticks(Some(SLOW_TURN));
    assert!(yaw_arrives(&sitl, 0.3, 3 * S));
    assert!(eventually(3 * S, || v.status().state == LinkState::Connected));

    // Silence: lost after five heartbeat periods (5 s) without a heartbeat; the autopilot drops
    // the stale overrides after RC_OVERRIDE_TIME (3 s) and the idle radio's centred yaw rules.
    let stalled = Instant::now();
    proxy.stall(true);
    assert!(eventually(8 * S, || v.status().state == LinkState::Lost));
    let lost_after = stalled.elapsed();
    assert!(
        lost_after >= Duration::from_millis(3900) && lost_after <= Duration::from_millis(5500),
        "lost after {lost_after:?} (five 1 s heartbeat periods since the last heartbeat)"
    );
    assert!(yaw_arrives(&sitl, 0.0, S), "stale overrides still applied");

    proxy.stall(false);
    assert!(eventually(3 * S, || v.status().state == LinkState::Connected));
    assert!(yaw_arrives(&sitl, 0.3, 2 * S), "overrides did not resume");

    // The connection is cut: the link reconnects and the sticks set meanwhile arrive.
    let connections = v.status().connections;
    proxy.disconnect();
    v.set_sticks(Some(Sticks {
        yaw: -0.3,
        ..SLOW_TURN
    }));
    assert!(
        eventually(10 * S, || v.status().connections > connections
            && v.status().state == LinkState::Connected),
        "{:?}",
        v.status()
    );
    assert!(
        yaw_arrives(&sitl, -0.3, 3 * S),
        "overrides did not resume after the reconnect"
    );
}
