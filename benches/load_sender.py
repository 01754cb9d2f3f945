#!/usr/bin/env python3
"""Send tlogs to one UDP port in real time, each from its own socket (its own vehicle).

Usage: load_sender.py PORT TLOG...

A tlog record is an 8-byte big-endian microsecond stamp and one MAVLink frame. The logs are
merged on their stamps, each shifted to start now, and every frame is sent when its stamp
comes due (frames that fall due together go out together). Prints, per log, the frames sent,
and how late the sender ran against the logs' clock (p50, p99, max), so that a late sender is
not taken for a slow monitor.
"""

import heapq
import socket
import struct
import sys
import time


def frames(path):
    data = open(path, "rb").read()
    i, out = 0, []
    while i + 8 < len(data):
        (stamp,) = struct.unpack_from(">Q", data, i)
        magic = data[i + 8]
        if magic == 0xFD:
            n = 12 + data[i + 9] + (13 if data[i + 10] & 1 else 0)
        elif magic == 0xFE:
            n = 8 + data[i + 9]
        else:
            raise SystemExit(f"{path}: no MAVLink magic at byte {i + 8}")
        out.append((stamp, data[i + 8 : i + 8 + n]))
        i += 8 + n
    return out


def main():
    port = int(sys.argv[1])
    logs = [frames(p) for p in sys.argv[2:]]
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in logs]
    merged = heapq.merge(
        *[[(s - log[0][0], k, f) for s, f in log] for k, log in enumerate(logs)]
    )
    sent = [0] * len(logs)
    late = []
    start = time.monotonic()
    for stamp_us, k, frame in merged:
        due = start + stamp_us * 1e-6
        now = time.monotonic()
        if due > now:
            time.sleep(due - now)
        else:
            late.append(now - due)
        socks[k].sendto(frame, ("127.0.0.1", port))
        sent[k] += 1
    total = sum(sent)
    late += [0.0] * (total - len(late))
    late.sort()
    for path, n in zip(sys.argv[2:], sent):
        print(f"sent {n} frames from {path}")
    print(
        f"sender late against the logs' clock: p50 {late[total // 2] * 1e3:.2f} ms, "
        f"p99 {late[int(total * 0.99)] * 1e3:.2f} ms, max {late[-1] * 1e3:.2f} ms "
        f"over {total} frames in {time.monotonic() - start:.1f} s"
    )


main()
