#!/usr/bin/env python3
"""Copy a .tlog without the given MAVLink message ids (standard library only).

benches/replay.sh uses it to make the target replay log (ATTITUDE and SERVO_OUTPUT_RAW,
no IMU) from the simulator's, which also streams RAW_IMU (id 27).
Usage: strip_tlog.py IN OUT ID[,ID...]
"""
import sys


def frame_length_and_id(data, at):
    """Length and message id of the MAVLink frame starting at `at` (after the timestamp)."""
    magic, payload = data[at], data[at + 1]
    if magic == 0xFE:  # v1: header 6, CRC 2
        return 6 + payload + 2, data[at + 5]
    if magic == 0xFD:  # v2: header 10, CRC 2, signature 13 when flagged
        signed = data[at + 2] & 1
        msgid = data[at + 7] | data[at + 8] << 8 | data[at + 9] << 16
        return 10 + payload + 2 + 13 * signed, msgid
    raise SystemExit(f"no MAVLink frame at byte {at}")


def main():
    src, dst, ids = sys.argv[1], sys.argv[2], sys.argv[3]
    drop = {int(x) for x in ids.split(",")}
    data = open(src, "rb").read()
    out, i, kept, dropped = bytearray(), 0, 0, 0
    while i + 8 + 10 <= len(data):
        n, msgid = frame_length_and_id(data, i + 8)
        record = data[i : i + 8 + n]
        i += 8 + n
        if msgid in drop:
            dropped += 1
        else:
            out += record
            kept += 1
    open(dst, "wb").write(out)
    print(f"{dst}: kept {kept} records, dropped {dropped}")


if __name__ == "__main__":
    main()
