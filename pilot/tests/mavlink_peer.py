"""A ground station for the pilot's MAVLink tests, with pymavlink's own parser.

Binds a UDP port on 127.0.0.1 (the first argument, 0 for any free one), prints
{"port": N} on one line, then collects MAVLink 2 messages for at most the second
argument's seconds, or until a COMMAND_LONG MAV_CMD_NAV_LAND and half a second more.
Prints one JSON object: HEARTBEATs (count, their type, autopilot and state), the
COMMAND_LONGs in order (command id, params 1-7 with NaN as null, target ids), and the
count and names of DEBUG_VECTs.

With a third argument SPEED (m/s) it also plays the autopilot: from the pilot's first
HEARTBEAT it flies straight ahead at SPEED, starting at heading 2.0 rad and position
(5, -3) m, and streams LOCAL_POSITION_NED (with +-1 cm of jitter) and ATTITUDE at
50 Hz. A CONDITION_YAW turns it by param1 degrees at param2 degrees/s (param3 -1 is
counter-clockwise) before it flies on, unless the fourth argument is "no-turn"; a
NAV_LAND stops it.
"""
import json
import math
import os
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

port = int(sys.argv[1])
seconds = float(sys.argv[2])
conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
print(json.dumps({"port": conn.port.getsockname()[1]}), flush=True)

speed = float(sys.argv[3]) if len(sys.argv) > 3 else None
turns = len(sys.argv) <= 4 or sys.argv[4] != "no-turn"
# the autopilot's state: position north/east, heading, the heading it turns to (and
# how fast), landed; started by the pilot's first HEARTBEAT
north, east, yaw = 5.0, -3.0, 2.0
target, rate = None, 0.0
landed = False
started = None
last = None
sent = 0


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def fly(now):
    """Advance the autopilot to `now` and send its pose."""
    global north, east, yaw, target, last, sent
    dt = now - last
    last = now
    if not landed:
        if target is not None:
            diff = wrap(target - yaw)
            step = min(abs(diff), rate * dt)
            yaw = wrap(yaw + math.copysign(step, diff))
            if abs(wrap(target - yaw)) < 1e-9:
                target = None
        else:
            north += speed * dt * math.cos(yaw)
            east += speed * dt * math.sin(yaw)
    jitter = 0.01 if sent % 2 == 0 else -0.01
    ms = int((now - started) * 1000)
    conn.mav.local_position_ned_send(ms, north + jitter, east - jitter, -1.5, 0.0, 0.0, 0.0)
    conn.mav.attitude_send(ms, 0.0, 0.0, yaw, 0.0, 0.0, 0.0)
    sent += 1


heartbeats = []
commands = []
debug = []
bad = 0
deadline = time.monotonic() + seconds
while time.monotonic() < deadline:
    now = time.monotonic()
    if speed is not None and started is not None and now - last >= 0.02:
        fly(now)
    msg = conn.recv_match(blocking=True, timeout=0.005 if speed is not None else 0.1)
    if msg is None:
        continue
    kind = msg.get_type()
    if kind == "BAD_DATA":
        bad += 1
    elif kind == "HEARTBEAT":
        if speed is not None and started is None:
            started = last = time.monotonic()
            fly(started)
        heartbeats.append(
            {
                "type": msg.type,
                "autopilot": msg.autopilot,
                "state": msg.system_status,
                "system": msg.get_srcSystem(),
                "component": msg.get_srcComponent(),
            }
        )
    elif kind == "COMMAND_LONG":
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        commands.append(
            {
                "command": msg.command,
                "params": [None if math.isnan(p) else p for p in params],
                "target": [msg.target_system, msg.target_component],
            }
        )
        if msg.command == mavutil.mavlink.MAV_CMD_NAV_LAND:
            landed = True
            deadline = min(deadline, time.monotonic() + 0.5)
        if msg.command == mavutil.mavlink.MAV_CMD_CONDITION_YAW and turns:
            direction = -1.0 if msg.param3 < 0 else 1.0
            target = wrap(yaw + direction * math.radians(msg.param1))
            rate = math.radians(msg.param2)
    elif kind == "DEBUG_VECT":
        debug.append(msg.name)

print(
    json.dumps(
        {
            "heartbeats": heartbeats,
            "commands": commands,
            "debug_vect": len(debug),
            "debug_names": sorted(set(debug)),
            "bad": bad,
            "poses_sent": sent,
            "final_yaw": yaw,
        }
    ),
    flush=True,
)
