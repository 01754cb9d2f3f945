"""A planner-side listener (pymavlink, udpin) for ahcmon's alerts: prints one JSON object with
what arrived from component 191: heartbeats (type, autopilot), STATUSTEXT texts, the
NAMED_VALUE_FLOAT names and the AHC_ESTIMATE messages, decoded with pymavlink's own code
generator (mavgen) run on dialects/ahcmon.xml, as a user of the dialect would. Exits when it has
seen a fault STATUSTEXT, values and estimates of four actuators, or at timeout."""
import contextlib
import importlib.util
import json
import math
import os
import socket
import sys
import tempfile
import time

from pymavlink.generator import mavgen

port, timeout = int(sys.argv[1]), float(sys.argv[2])
xml = os.path.join(os.path.dirname(__file__), "..", "..", "dialects", "ahcmon.xml")
with tempfile.TemporaryDirectory() as tmp:
    out = os.path.join(tmp, "ahcmon_dialect.py")
    opts = mavgen.Opts(out, wire_protocol="2.0", language="Python3", validate=False)
    with contextlib.redirect_stdout(sys.stderr):  # mavgen reports progress on stdout
        generated = mavgen.mavgen(opts, [xml])
    if not generated:
        sys.exit("mavgen failed on dialects/ahcmon.xml")
    spec = importlib.util.spec_from_file_location("ahcmon_dialect", out)
    dialect = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(dialect)

# A plain socket and the generated parser: mavutil would swap its parser for ardupilotmega's on
# the first MAVLink 2 frame.
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", port))
sock.settimeout(0.5)
parser = dialect.MAVLink(None)
parser.robust_parsing = True


def receive():
    """The messages of one datagram (none at a timeout)."""
    try:
        data, _ = sock.recvfrom(65535)
    except socket.timeout:
        return []
    return parser.parse_buffer(data) or []


print("ready", flush=True)
seen = {"heartbeat": [], "statustext": [], "named_value_float": [], "ahc_estimate": 0, "sysids": [],
        "ahc_estimate_names": [], "ahc_estimate_bad": [], "set_unexcited": [], "bad_data": 0,
        "set_output_bounded": 0, "command_ref_nonzero": 0}


def check_estimate(m):
    """The probable bounds finite around their estimate; each guaranteed coefficient either NaN
    with its not-excited bit or finite with lo <= estimate <= hi; the output bounds ordered."""
    bad = []
    if not (m.ukf_gamma_lo <= m.ukf_gamma <= m.ukf_gamma_hi):
        bad.append("ukf gamma")
    for bit, (est, lo, hi) in enumerate([(m.set_gamma, m.set_gamma_lo, m.set_gamma_hi),
                                         (m.set_delta, m.set_delta_lo, m.set_delta_hi)]):
        if m.set_unexcited & (1 << bit):
            if not all(math.isnan(v) for v in (est, lo, hi)):
                bad.append(f"set {bit}: numbers with the not-excited bit")
        elif not (lo <= est <= hi):
            bad.append(f"set {bit}: {lo} {est} {hi}")
    # The extension fields: the output at the recent command, probable always, guaranteed or
    # NaN (not excited) as a pair.
    if not (math.isfinite(m.command_ref) and m.ukf_output_lo <= m.ukf_output_hi):
        bad.append(f"output: {m.command_ref} {m.ukf_output_lo} {m.ukf_output_hi}")
    lo, hi = m.set_output_lo, m.set_output_hi
    if math.isnan(lo) != math.isnan(hi) or (not math.isnan(lo) and not lo <= hi):
        bad.append(f"set output: {lo} {hi}")
    return bad


def handle(m):
    if m.get_type() == "BAD_DATA":
        seen["bad_data"] += 1
        return
    if m.get_srcComponent() != 191:
        return
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
    elif t == "AHC_ESTIMATE":
        seen["ahc_estimate"] += 1
        name = m.name.rstrip("\0") if isinstance(m.name, str) else m.name.decode().rstrip("\0")
        if name not in seen["ahc_estimate_names"]:
            seen["ahc_estimate_names"].append(name)
        if m.set_unexcited not in seen["set_unexcited"]:
            seen["set_unexcited"].append(m.set_unexcited)
        seen["ahc_estimate_bad"] += [f"{name}: {b}" for b in check_estimate(m)]
        # The extension fields arrived (a sender without them reads as zeros here).
        seen["set_output_bounded"] += int(math.isfinite(m.set_output_lo) and m.set_output_lo < m.set_output_hi)
        seen["command_ref_nonzero"] += int(m.command_ref != 0.0)


end = time.time() + timeout
while time.time() < end:
    for m in receive():
        handle(m)
    if (any("swash2" in s[1] for s in seen["statustext"]) and seen["named_value_float"]
            and len(seen["ahc_estimate_names"]) >= 4):
        break
print(json.dumps(seen), flush=True)
