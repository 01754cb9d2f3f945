"""What the reference readers see in a vehicle's own log, as JSON: pymavlink's DFReader for
ArduPilot DataFlash (.bin), pyulog for PX4 ULog (.ulg). Counts of the messages ahcmon maps,
the total, and the first values of the rates, outputs and a_z (the fields ahcmon reads)."""
import json
import math
import sys

path = sys.argv[1]
with open(path, "rb") as f:
    head = f.read(8)
out = {}
if head.startswith(b"ULog"):
    from pyulog import ULog

    u = ULog(path)
    topics = {(d.name, d.multi_id): d.data for d in u.data_list}
    av = topics.get(("vehicle_angular_velocity", 0))
    ao = topics.get(("actuator_outputs", 0))
    sc = topics.get(("sensor_combined", 0))
    out["rates"] = 0 if av is None else len(av["timestamp"])
    out["outputs"] = 0 if ao is None else len(ao["timestamp"])
    out["params"] = len(u.initial_parameters) + len(u.changed_parameters)
    ts = "timestamp_sample" if av is not None and "timestamp_sample" in av else "timestamp"
    out["first_rates"] = [] if av is None else [
        [int(av[ts][i]), *(float(av[f"xyz[{k}]"][i]) for k in range(3))] for i in range(5)
    ]
    out["first_outputs"] = [] if ao is None else [
        [int(ao["timestamp"][i]), *(float(ao[f"output[{k}]"][i]) for k in range(4))]
        for i in range(5)
    ]
else:
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(path)
    counts = {}
    first = {"RATE": [], "RCOU": [], "IMU": []}
    total = 0
    while True:
        m = r.recv_msg()
        if m is None:
            break
        total += 1
        t = m.get_type()
        if t == "IMU" and getattr(m, "I", 0) != 0:
            t = "IMU_OTHER"
        counts[t] = counts.get(t, 0) + 1
        if t in first and len(first[t]) < 5:
            if t == "RATE":
                first[t].append([m.TimeUS, *(math.radians(getattr(m, k)) for k in "RPY")])
            elif t == "RCOU":
                first[t].append([m.TimeUS, *(float(getattr(m, f"C{k}")) for k in range(1, 5))])
            else:
                first[t].append([m.TimeUS, float(m.AccZ)])
    out["messages"] = total
    out["rates"] = counts.get("RATE", 0)
    out["outputs"] = counts.get("RCOU", 0)
    out["az"] = counts.get("IMU", 0)
    out["params"] = counts.get("PARM", 0)
    out["first_rates"] = first["RATE"]
    out["first_outputs"] = first["RCOU"]
    out["first_az"] = first["IMU"]
print(json.dumps(out))
