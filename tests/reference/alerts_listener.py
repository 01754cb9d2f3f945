"""A planner-side listener (pymavlink, udpin) for ahcmon's alerts: prints one JSON object with
what arrived from component 191: heartbeats (type, autopilot), STATUSTEXT texts and the
NAMED_VALUE_FLOAT names. Exits when it has seen a fault STATUSTEXT and values, or at timeout."""
import json
import sys
import time

from pymavlink import mavutil

port, timeout = int(sys.argv[1]), float(sys.argv[2])
conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
print("ready", flush=True)
seen = {"heartbeat": [], "statustext": [], "named_value_float": [], "ahc_estimate": 0, "sysids": []}
end = time.time() + timeout
while time.time() < end:
    m = conn.recv_match(blocking=True, timeout=0.5)
    if m is None or m.get_srcComponent() != 191:
        continue
    if m.get_srcSystem() not in seen["sysids"]:
        seen["sysids"].append(m.get_srcSystem())
    t = m.get_type()
    if t == "HEARTBEAT":
        seen["heartbeat"].append([m.type, m.autopilot])
    elif t == "STATUSTEXT":
        seen["statustext"].append([m.severity, m.text])
    elif t == "NAMED_VALUE_FLOAT":
        if m.name not in seen["named_value_float"]:
            seen["named_value_float"].append(m.name)
    elif t == "UNKNOWN_42900" or m.get_msgId() == 42900:
        seen["ahc_estimate"] += 1
    if any("swash2" in s[1] for s in seen["statustext"]) and seen["named_value_float"]:
        break
print(json.dumps(seen), flush=True)
