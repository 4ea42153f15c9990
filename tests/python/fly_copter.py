#!/usr/bin/env python3
"""Flies an ArduCopter the way a pymavlink user would, with nothing of this project in it.

Connects, waits for a heartbeat, sets ALT_HOLD, arms, climbs on an RC override (throttle high),
holds at mid throttle, switches to LAND and waits for the autopilot to land and disarm. Prints one
JSON report on stdout: the heights it saw (from GLOBAL_POSITION_INT.relative_alt) at each stage,
the status texts, and whether every step worked. Exits 1 when a step fails.

    python fly_copter.py --connect tcp:127.0.0.1:5760
"""
import argparse
import json
import os
import sys
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True, help="e.g. tcp:127.0.0.1:5760 or udpin:0.0.0.0:14550")
    ap.add_argument("--climb-seconds", type=float, default=3.0)
    ap.add_argument("--hold-seconds", type=float, default=3.0)
    args = ap.parse_args()

    report = {"texts": [], "ok": False}
    master = mavutil.mavlink_connection(args.connect, source_system=250)
    hb = master.wait_heartbeat(timeout=15)
    if hb is None:
        report["error"] = "no heartbeat"
        return finish(report)
    report["autopilot"] = hb.autopilot
    report["vehicle_type"] = hb.type
    master.mav.request_data_stream_send(
        master.target_system, master.target_component, mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1
    )

    state = {"alt": None, "last_hb": 0.0}

    def pump(seconds, throttle=None):
        """Reads messages for `seconds`, sending a heartbeat each second and the override."""
        end = time.time() + seconds
        last_rc = 0.0
        while time.time() < end:
            now = time.time()
            if now - state["last_hb"] >= 1.0:
                master.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                state["last_hb"] = now
            if throttle is not None and now - last_rc >= 0.1:
                master.mav.rc_channels_override_send(
                    master.target_system, master.target_component, 1500, 1500, throttle, 1500, 0, 0, 0, 0
                )
                last_rc = now
            msg = master.recv_match(blocking=True, timeout=0.05)
            if msg is None:
                continue
            t = msg.get_type()
            if t == "GLOBAL_POSITION_INT":
                state["alt"] = msg.relative_alt / 1000.0
            elif t == "STATUSTEXT":
                report["texts"].append(msg.text)

    pump(1.0)
    master.set_mode("ALT_HOLD")
    # The mode shows in the vehicle's next heartbeat (1 Hz): wait for it, up to 5 s.
    deadline = time.time() + 5
    while master.flightmode != "ALT_HOLD" and time.time() < deadline:
        pump(0.2)
    report["mode_after_set"] = master.flightmode
    if master.flightmode != "ALT_HOLD":
        report["error"] = "mode did not change to ALT_HOLD"
        return finish(report)

    master.arducopter_arm()
    deadline = time.time() + 5
    while not master.motors_armed() and time.time() < deadline:
        pump(0.2, throttle=1000)
    if not master.motors_armed():
        report["error"] = "did not arm"
        return finish(report)
    report["armed"] = True

    pump(args.climb_seconds, throttle=1800)
    report["alt_after_climb"] = state["alt"]
    pump(1.0, throttle=1500)
    report["alt_hold_start"] = state["alt"]
    pump(args.hold_seconds, throttle=1500)
    report["alt_hold_end"] = state["alt"]

    master.set_mode("LAND")
    deadline = time.time() + 20
    while master.motors_armed() and time.time() < deadline:
        pump(0.2, throttle=1500)
    report["alt_after_land"] = state["alt"]
    report["disarmed_after_land"] = not master.motors_armed()
    report["ok"] = (
        report["disarmed_after_land"]
        and report["alt_after_climb"] is not None
        and report["alt_after_climb"] > 1.0
        and abs(report["alt_hold_end"] - report["alt_hold_start"]) < 0.2
        and report["alt_after_land"] < 0.1
    )
    return finish(report)


def finish(report):
    print(json.dumps(report))
    sys.stdout.flush()
    return 0 if report["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
