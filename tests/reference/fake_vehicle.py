"""A stand-in autopilot (pymavlink): sends HEARTBEAT (quadrotor; ArduPilot, or the
MAV_AUTOPILOT given as the third argument, e.g. 12 for PX4) to the monitor's udpin port for a
few seconds, answers COMMAND_LONG with COMMAND_ACK (accepted; not at all with "noack" as the
fourth argument), and prints as JSON everything the monitor sent it."""
import json
import sys
import time

from pymavlink import mavutil

port, secs = int(sys.argv[1]), float(sys.argv[2])
autopilot = int(sys.argv[3]) if len(sys.argv) > 3 else 3
ack = not (len(sys.argv) > 4 and sys.argv[4] == "noack")
m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
got = []
end = time.time() + secs
next_hb = 0.0
while time.time() < end:
    if time.time() >= next_hb:
        # MAV_TYPE_QUADROTOR, the autopilot, armed + custom mode
        m.mav.heartbeat_send(2, autopilot, 129, 4, 4)
        next_hb = time.time() + 0.5
    msg = m.recv_match(blocking=True, timeout=0.1)
    if msg is None or msg.get_type() == "BAD_DATA":
        continue
    d = {"type": msg.get_type(), "src": [msg.get_srcSystem(), msg.get_srcComponent()]}
    if msg.get_type() == "COMMAND_LONG":
        d.update(
            command=msg.command,
            param1=msg.param1,
            param2=msg.param2,
            target=[msg.target_system, msg.target_component],
        )
        if ack:
            m.mav.command_ack_send(msg.command, 0)
    got.append(d)
print(json.dumps(got))
