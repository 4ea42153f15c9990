//! A vehicle that sends numbers that are no numbers (NaN or infinite attitude and position, as
//! a broken sensor or a corrupt field would): the MAVLink adapter keeps the last good values
//! rather than hand NaN to the station's controllers, display and log. The vehicle is a raw socket
//! writing MAVLink 2 frames, so it can send what no real autopilot library would.

use std::io::Write;
use std::net::{TcpListener, TcpStream};
use std::time::Duration;

use link::VehicleLink;
use link::mavlink::{MavlinkConfig, MavlinkLink};
use mavlink::dialects::ardupilotmega::{
    ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavMessage, MavModeFlag,
    MavSeverity, MavState, MavType, STATUSTEXT_DATA,
};
use mavlink::{MavHeader, write_v2_msg};
use tests::eventually;

const S: Duration = Duration::from_secs(1);

/// Writes `msg` as vehicle 1, `seq` its sequence number.
fn send(stream: &mut TcpStream, seq: &mut u8, msg: &MavMessage) {
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: *seq,
    };
    *seq = seq.wrapping_add(1);
    write_v2_msg(stream, header, msg).expect("write a frame");
    stream.flush().expect("flush");
}

fn attitude(roll: f32, pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        roll,
        pitch,
        yaw,
        ..ATTITUDE_DATA::default()
    })
}

/// A status text: sent after other frames, its arrival shows they have been read (the link
/// takes frames in order).
fn text(text: &str) -> MavMessage {
    MavMessage::STATUSTEXT(STATUSTEXT_DATA {
        severity: MavSeverity::MAV_SEVERITY_INFO,
        text: text.into(),
        ..STATUSTEXT_DATA::default()
    })
}

fn position(x: f32, vx: f32) -> MavMessage {
    MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        x,
        vx,
        ..LOCAL_POSITION_NED_DATA::default()
    })
}

#[test]
fn attitude_and_position_that_are_no_numbers_are_dropped_and_the_last_good_ones_kept() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("address").port();
    let link = MavlinkLink::connect(
        &format!("tcpout:127.0.0.1:{port}").parse().expect("address"),
        MavlinkConfig::default(),
    )
    .expect("connect");
    let (mut stream, _) = listener.accept().expect("the link connects");
    let mut seq = 0;
    let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    });
    send(&mut stream, &mut seq, &heartbeat);
    let vehicle = link
        .wait_for_vehicle(5 * S)
        .expect("the heartbeat is heard");

    let read = |marker: &str| {
        eventually(5 * S, || {
            vehicle.take_status_texts().iter().any(|s| s.text == marker)
        })
    };
    // Garbage first: nothing is taken.
    send(&mut stream, &mut seq, &attitude(0.1, 0.2, f32::NAN));
    send(&mut stream, &mut seq, &position(f32::INFINITY, 0.0));
    send(&mut stream, &mut seq, &text("first garbage sent"));
    assert!(read("first garbage sent"));
    let t = vehicle.telemetry();
    assert_eq!((t.attitude, t.yaw_rad, t.position_m), (None, None, None));
    // Then good values, which are taken…
    send(&mut stream, &mut seq, &attitude(0.1, 0.2, 0.5));
    send(&mut stream, &mut seq, &position(2.0, 0.5));
    assert!(eventually(5 * S, || {
        let t = vehicle.telemetry();
        t.attitude.is_some() && t.position_m.is_some()
    }));
    // …and garbage again, after which the good ones stand.
    send(&mut stream, &mut seq, &attitude(f32::NAN, 0.0, 0.0));
    send(&mut stream, &mut seq, &position(1.0, f32::NEG_INFINITY));
    send(&mut stream, &mut seq, &text("more garbage sent"));
    assert!(read("more garbage sent"));
    let t = vehicle.telemetry();
    let a = t.attitude.expect("attitude");
    assert!(
        (a.roll - 0.1).abs() < 1e-6 && (a.pitch + 0.2).abs() < 1e-6 && (a.yaw + 0.5).abs() < 1e-6,
        "{a:?}"
    );
    assert_eq!(t.yaw_rad, Some(-0.5));
    assert_eq!(t.position_m, Some([2.0, -0.0, -0.0]));
    assert_eq!(t.velocity_mps, Some([0.5, -0.0, -0.0]));
}
