"""Count the messages of a .tlog per type with pymavlink (the reference GCS library): one
`TYPE COUNT` line per type, then `BAD_DATA n`."""
import sys
from collections import Counter

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
counts = Counter()
while True:
    msg = conn.recv_match(blocking=False)
    if msg is None:
        break
    counts[msg.get_type()] += 1
bad = counts.pop("BAD_DATA", 0)
for name, n in sorted(counts.items()):
    print(name, n)
print("BAD_DATA", bad)
