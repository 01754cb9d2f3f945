#!/usr/bin/env bash
# Load: four vehicles (two quads X, motor 2 to gamma 0.7 at 35 s; two H3-120 helicopters,
# swash servo 2 to gamma 0.6 at 35 s; each its own seed and system id) at 400 Hz for
# DURATION seconds (default 600) into one headless monitor over UDP on 127.0.0.1.
#
# The flights are simulated first into tlogs (so the sender spends no CPU on physics or
# filters), then sent in real time by benches/load_sender.py, one socket per vehicle.
# Prints: frames sent and received, drops of every kind, gaps, the monitor's latency from a
# frame's receive to its estimates and decisions written (p50, p99, max; measured inside the
# monitor), the monitor's CPU per vehicle (user + system over the streaming time, / 4) and its
# resident memory after the calibration (60 s) and at the end.
#
#   bash benches/load.sh            # 10 minutes
#   DURATION=60 bash benches/load.sh
set -euo pipefail
cd "$(dirname "$0")/.."
duration=${DURATION:-600}
cargo build --release --quiet
bin=$PWD/target/release/ahcmon
tmp=$(mktemp -d)
monitor=
trap '{ [ -n "$monitor" ] && kill "$monitor" 2>/dev/null; } || true; rm -rf "$tmp"' EXIT
i=0
for s in quad-x-motor2-loe-live quad-x-motor2-loe-live heli-swash2-loe-live heli-swash2-loe-live; do
  i=$((i + 1))
  sed -e 's/^rate_hz = .*/rate_hz = 400.0/' -e "s/^duration_s = .*/duration_s = $duration.0/" \
    "replay/scenarios/$s.toml" > "$tmp/v$i.toml"
  "$bin" -q sim --scenario "$tmp/v$i.toml" --seed "$i" --sysid "$i" --tlog "$tmp/v$i.tlog" > /dev/null &
done
wait
echo "load: 4 vehicles x 400 Hz x $duration s; tlogs $(du -ch "$tmp"/v*.tlog | tail -1 | cut -f1)" >&2
port=$(python3 -c 'import socket; s=socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$bin" -q monitor "udpin:127.0.0.1:$port" --headless --exit-idle 3 \
  --decisions "$tmp/decisions.jsonl" --estimates "$tmp/estimates.jsonl" --decimate 40 > "$tmp/summary.txt" &
monitor=$!
# The monitor's CPU ticks (user + system) and resident memory, once a second.
(
  while [ -e "/proc/$monitor/stat" ]; do
    ticks=$(awk '{print $14 + $15}' "/proc/$monitor/stat" 2>/dev/null) || break
    rss=$(awk '/^VmRSS/ {print $2}' "/proc/$monitor/status" 2>/dev/null) || break
    echo "$(date +%s.%N) $ticks $rss"
    sleep 1
  done
) > "$tmp/usage.txt" &
sampler=$!
sleep 1
start=$(date +%s.%N)
python3 benches/load_sender.py "$port" "$tmp"/v1.tlog "$tmp"/v2.tlog "$tmp"/v3.tlog "$tmp"/v4.tlog \
  | sed "s|$tmp/||"
end=$(date +%s.%N)
wait "$monitor"
wait "$sampler" || true
grep -E "^link:|^vehicle sysid|pipeline:|pairing:|dropped|latency" "$tmp/summary.txt" || true
echo "decisions: $(wc -l < "$tmp/decisions.jsonl") lines: $(python3 -c '
import collections, json, sys
c = collections.Counter((d["sysid"], d["event"], d.get("actuator") or "-") for d in map(json.loads, open(sys.argv[1])))
print(", ".join(f"sysid {s} {e} {a} x{n}" for (s, e, a), n in sorted(c.items())))' "$tmp/decisions.jsonl")"
python3 - "$tmp/usage.txt" "$start" "$end" "$(getconf CLK_TCK)" <<'PY'
import sys
rows = [tuple(map(float, l.split())) for l in open(sys.argv[1]) if len(l.split()) == 3]
start, end, hz = float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
cpu_s = rows[-1][1] / hz
stream_s = end - start
after = [r for r in rows if r[0] >= start + 60] or rows
print(f"monitor CPU: {cpu_s:.1f} s over {stream_s:.0f} s of streaming = "
      f"{100 * cpu_s / stream_s:.2f} % of one core, {100 * cpu_s / stream_s / 4:.2f} % per vehicle")
print(f"monitor RSS: {after[0][2] / 1024:.1f} MiB at 60 s, {rows[-1][2] / 1024:.1f} MiB at the end "
      f"(growth {(rows[-1][2] - after[0][2]) / 1024:+.1f} MiB), peak {max(r[2] for r in rows) / 1024:.1f} MiB")
PY
