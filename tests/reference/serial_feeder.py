"""A serial link for the monitor's serial transport test: opens a pseudo-terminal pair, prints
the device name of its slave end, and writes the MAVLink frames of a .tlog (read by pymavlink)
to it in raw mode, with every 100th frame corrupted (one payload byte flipped: a bad CRC) and
300 bytes of garbage in the middle (a resync). Prints a JSON report of what it wrote when done,
then keeps the line open a few seconds so the reader sees silence, not a hang-up."""
import json
import os
import pty
import sys
import time
import tty

from pymavlink import mavutil

master, slave = pty.openpty()
tty.setraw(slave)
print(os.ttyname(slave), flush=True)

conn = mavutil.mavlink_connection(sys.argv[1])
limit = int(sys.argv[2])
frames, corrupted = [], 0
while len(frames) < limit:
    msg = conn.recv_match(blocking=False)
    if msg is None:
        break
    if msg.get_type() == "BAD_DATA":
        continue
    buf = bytearray(msg.get_msgbuf())
    if len(frames) % 100 == 99 and len(buf) > 12:
        buf[10] ^= 0x5A
        corrupted += 1
    frames.append(bytes(buf))

# Non-blocking with a deadline: if nobody reads the device, fail instead of hanging the test.
os.set_blocking(master, False)
deadline = time.monotonic() + 20


def write_all(data):
    while data:
        try:
            data = data[os.write(master, data):]
        except BlockingIOError:
            if time.monotonic() > deadline:
                sys.exit("serial_feeder: nobody read the device for 20 s")
            time.sleep(0.001)


time.sleep(0.5)  # the monitor opens the device
for i, f in enumerate(frames):
    if i == len(frames) // 2:
        write_all(bytes((k * 37 + 11) % 256 for k in range(300)))
    write_all(f)
    if i % 50 == 0:
        time.sleep(0.002)  # a radio's pace, roughly
print(json.dumps({"frames": len(frames), "corrupted": corrupted}), flush=True)
time.sleep(4)
