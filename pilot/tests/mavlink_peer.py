"""A ground station for the pilot's MAVLink tests, with pymavlink's own parser.

Binds a UDP port on 127.0.0.1 (the first argument, 0 for any free one), prints
{"port": N} on one line, then collects MAVLink 2 messages for at most the second
argument's seconds, or until a COMMAND_LONG MAV_CMD_NAV_LAND and half a second more.
Prints one JSON object: HEARTBEATs (count, their type, autopilot and state), the
COMMAND_LONGs in order (command id, params 1-7 with NaN as null, target ids), and the
count and names of DEBUG_VECTs.
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

heartbeats = []
commands = []
debug = []
bad = 0
deadline = time.monotonic() + seconds
while time.monotonic() < deadline:
    msg = conn.recv_match(blocking=True, timeout=0.1)
    if msg is None:
        continue
    kind = msg.get_type()
    if kind == "BAD_DATA":
        bad += 1
    elif kind == "HEARTBEAT":
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
            deadline = min(deadline, time.monotonic() + 0.5)
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
        }
    ),
    flush=True,
)
