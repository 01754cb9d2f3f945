"""Re-sign a tlog with pymavlink's MAVLink 2 signing: every frame as it was (system,
component, sequence, the tlog's receive stamp), signed with the key given in hex. Then, after
the middle of the log, two frames a forger would send as the vehicle: an ATTITUDE signed with
another key and one not signed at all. Prints one JSON object: frames written, forged, unsigned.

    sign_tlog.py IN.tlog OUT.tlog KEYHEX
"""
import json
import os
import struct
import sys

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

src, dst, key_hex = sys.argv[1], sys.argv[2], sys.argv[3]
key = bytes.fromhex(key_hex)


class Sink:
    """pymavlink's MAVLink object writes to a file-like object; we take the bytes."""

    def __init__(self):
        self.buf = b""

    def write(self, b):
        self.buf += b


def signer(secret):
    out = Sink()
    mav = mavlink.MAVLink(out)
    mav.signing.secret_key = secret
    mav.signing.link_id = 1
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = 1
    return mav, out


good, good_out = signer(key)
bad, bad_out = signer(bytes(32 * [0x5A]))
plain_out = Sink()
plain = mavlink.MAVLink(plain_out)

log = mavutil.mavlink_connection(src, dialect="ardupilotmega")
msgs = []
while True:
    m = log.recv_msg()
    if m is None:
        break
    if m.get_type() == "BAD_DATA":
        continue
    msgs.append(m)

written = forged = unsigned = 0
with open(dst, "wb") as f:
    for i, m in enumerate(msgs):
        good.srcSystem, good.srcComponent = m.get_srcSystem(), m.get_srcComponent()
        good.seq = m.get_seq()
        good_out.buf = b""
        good.send(m)
        stamp = int(m._timestamp * 1e6)
        f.write(struct.pack(">Q", stamp) + good_out.buf)
        written += 1
        if i == len(msgs) // 2:
            att = mavlink.MAVLink_attitude_message(1000, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            for mav, out in ((bad, bad_out), (plain, plain_out)):
                mav.srcSystem, mav.srcComponent = 1, 1
                out.buf = b""
                mav.send(att)
                f.write(struct.pack(">Q", stamp) + out.buf)
            forged += 1
            unsigned += 1
print(json.dumps({"written": written, "forged": forged, "unsigned": unsigned}))
