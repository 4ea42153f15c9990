#!/usr/bin/env python3
"""A MAVLink vehicle made with pymavlink, for the station's interop tests.

It behaves like ArduCopter as far as a ground station can see: it sends boot text (non-MAVLink
bytes) then HEARTBEAT at 1 Hz and telemetry at 10 Hz, answers COMMAND_LONG with COMMAND_ACK
(arm/disarm, DO_SET_MODE, SET_MESSAGE_INTERVAL), obeys SET_MODE, and records every
RC_CHANNELS_OVERRIDE addressed to it. It exits after --seconds, or 1 s after it has been disarmed
following an arm, and prints one JSON report on stdout.
"""
import argparse
import json
import os
import sys
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

COPTER_MODES = {0: "STABILIZE", 2: "ALT_HOLD", 4: "GUIDED", 5: "LOITER", 9: "LAND"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True, help="pymavlink address, e.g. udpout:127.0.0.1:14550")
    ap.add_argument("--sysid", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--no-do-set-mode", action="store_true", help="answer DO_SET_MODE with UNSUPPORTED")
    ap.add_argument("--ignore-message-interval", action="store_true", help="never answer SET_MESSAGE_INTERVAL")
    ap.add_argument("--signing-key", help="64 hex digits: sign everything, accept only signed frames")
    args = ap.parse_args()

    m = mavutil.mavlink_connection(args.connect, source_system=args.sysid, source_component=1, dialect="ardupilotmega")
    mav = m.mav
    if args.signing_key:
        m.setup_signing(bytes.fromhex(args.signing_key), sign_outgoing=True,
                        allow_unsigned_callback=lambda _mav, _msg_id: False)
    report = {
        "overrides": [], "releases": 0, "gcs_heartbeats": 0, "commands": [], "set_mode_messages": 0,
        "data_stream_requests": 0, "armed_history": [], "mode_history": [], "gcs_sysid": None,
    }
    armed = False
    custom_mode = 0
    was_armed = False
    disarmed_at = None
    start = time.time()
    next_hb = 0.0
    next_tel = 0.0

    def ack(cmd, result):
        mav.command_ack_send(cmd, result)

    while time.time() - start < args.seconds:
        now = time.time()
        if now >= next_hb:
            base = mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if armed:
                base |= mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            try:
                mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_QUADROTOR, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                   base, custom_mode, mavutil.mavlink.MAV_STATE_ACTIVE)
            except Exception:
                pass
            next_hb = now + 1.0
        if now >= next_tel:
            try:
                t_ms = int((now - start) * 1000)
                # NED: nose 10 degrees up, heading 90 degrees (east), 1.5 m up, 2 m north, 1 m east.
                mav.attitude_send(t_ms, 0.05, 0.1745, 1.5708, 0, 0, 0)
                mav.local_position_ned_send(t_ms, 2.0, 1.0, -1.5, 0.5, 0, 0)
                mav.sys_status_send(0, 0, 0, 500, 12100, -1, 87, 0, 0, 0, 0, 0, 0)
                mav.distance_sensor_send(t_ms, 20, 700, 150, 0, 0, mavutil.mavlink.MAV_SENSOR_ROTATION_PITCH_270, 0)
            except Exception:
                pass
            next_tel = now + 0.1
        if was_armed and not armed and disarmed_at and now - disarmed_at > 1.0:
            break
        msg = m.recv_match(blocking=True, timeout=0.02)
        if msg is None:
            continue
        t = msg.get_type()
        src = msg.get_srcSystem()
        if t == "HEARTBEAT" and msg.type == mavutil.mavlink.MAV_TYPE_GCS:
            if report["gcs_heartbeats"] == 0:
                # Like ArduPilot SITL's boot text: bytes that are not MAVLink, which the station must
                # skip (sent once we know a station is there, so that TCP does not drop them).
                m.write(b"Init ArduCopter V4.6.0 (fake)\r\n\xfe\x05garbage\xfd\x02\x00")
                mav.statustext_send(mavutil.mavlink.MAV_SEVERITY_INFO, b"fake copter ready")
            report["gcs_heartbeats"] += 1
            report["gcs_sysid"] = src
            report["gcs_compid"] = msg.get_srcComponent()
        elif t == "RC_CHANNELS_OVERRIDE" and msg.target_system == args.sysid:
            ch = [msg.chan1_raw, msg.chan2_raw, msg.chan3_raw, msg.chan4_raw, msg.chan5_raw, msg.chan6_raw,
                  msg.chan7_raw, msg.chan8_raw, msg.chan9_raw, msg.chan18_raw]
            if ch[:4] == [0, 0, 0, 0]:
                report["releases"] += 1
            else:
                report["overrides"].append([round(now - start, 4)] + ch)
        elif t == "COMMAND_LONG" and msg.target_system == args.sysid:
            cmd = msg.command
            report["commands"].append([cmd, msg.confirmation])
            if cmd == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
                armed = msg.param1 == 1.0
                was_armed |= armed
                report["armed_history"].append(armed)
                if not armed:
                    disarmed_at = now
                ack(cmd, mavutil.mavlink.MAV_RESULT_ACCEPTED)
            elif cmd == mavutil.mavlink.MAV_CMD_DO_SET_MODE:
                if args.no_do_set_mode:
                    ack(cmd, mavutil.mavlink.MAV_RESULT_UNSUPPORTED)
                else:
                    custom_mode = int(msg.param2)
                    report["mode_history"].append(COPTER_MODES.get(custom_mode, custom_mode))
                    ack(cmd, mavutil.mavlink.MAV_RESULT_ACCEPTED)
            elif cmd == mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
                if not args.ignore_message_interval:
                    ack(cmd, mavutil.mavlink.MAV_RESULT_ACCEPTED)
            else:
                ack(cmd, mavutil.mavlink.MAV_RESULT_UNSUPPORTED)
        elif t == "SET_MODE" and msg.target_system == args.sysid:
            report["set_mode_messages"] += 1
            custom_mode = msg.custom_mode
            report["mode_history"].append(COPTER_MODES.get(custom_mode, custom_mode))
        elif t == "REQUEST_DATA_STREAM" and msg.target_system == args.sysid:
            report["data_stream_requests"] += 1
    json.dump(report, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
