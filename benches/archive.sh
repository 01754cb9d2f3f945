#!/usr/bin/env bash
# A generated fleet archive and the cost of scanning it.
#
# AIRFRAMES simulated quads X (system ids 1..AIRFRAMES) fly FLIGHTS flights of DURATION
# seconds each (default 50 x 20 x 300 s: 1,000 five-minute flights, about 1.8 GB of tlogs), in
# gusts with 10 % damping mismatch, every flight with its own seed. On every fifth airframe
# motor 2's gain falls FALL a flight from 1.0; the others stay healthy. A profile is
# identified (`ahcmon calibrate`) on one more healthy flight.
#
# Then `ahcmon scan` of the whole archive with that profile on 1 thread and on 2 (wall time,
# flights/s, peak RSS, the rows compared), and `ahcmon history` on the rows: each series'
# alarm against the flight where its truth reaches the loss gain 0.8.
#
#   bash benches/archive.sh                          # 1,000 flights of 5 minutes
#   AIRFRAMES=5 FLIGHTS=20 DURATION=90 bash benches/archive.sh
set -euo pipefail
cd "$(dirname "$0")/.."
airframes=${AIRFRAMES:-50}
flights=${FLIGHTS:-20}
duration=${DURATION:-300}
fall=${FALL:-0.01}
cargo build --release --quiet
bin=$PWD/target/release/ahcmon
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# The live quad scenario without its fault, as long as asked.
base() {
  sed -n '/^\[\[fault\]\]/q;p' replay/scenarios/quad-x-motor2-loe-live.toml |
    sed -e "s/^duration_s = .*/duration_s = $duration.0/" -e "s/^seed = .*/seed = $1/"
}
base 99999 > "$tmp/calibration.toml"
"$bin" -q sim --scenario "$tmp/calibration.toml" --sysid 250 --tlog "$tmp/calibration.tlog" > /dev/null
"$bin" -q calibrate "$tmp/calibration.tlog" --until 40 -o "$tmp/airframe.toml" > /dev/null
mkdir "$tmp/archive"
started=$(date +%s.%N)
for a in $(seq 1 "$airframes"); do
  for m in $(seq 0 $((flights - 1))); do
    f=$(printf '%s/archive/a%03d-f%03d' "$tmp" "$a" "$m")
    base $((a * 1000 + m)) > "$f.toml"
    if [ $((a % 5)) = 1 ]; then
      printf '\n[[fault]]\nactuator = "motor2"\nt = 0.0\ngamma = %s\n' \
        "$(python3 -c "print(round(1 - $fall * $m, 4))")" >> "$f.toml"
    fi
    echo "$f $a"
  done
done | xargs -P 2 -n 2 sh -c '"$0" -q sim --scenario "$1.toml" --sysid "$2" --tlog "$1.tlog" > /dev/null' "$bin"
rm "$tmp"/archive/*.toml
echo "archive: $airframes airframes x $flights flights of $duration s, $(du -sh "$tmp/archive" | cut -f1) of tlogs, flown in $(python3 -c "import time; print(round(time.time() - $started, 1))") s"
for jobs in 1 2; do
  /usr/bin/time -f "%e %M" -o "$tmp/time-$jobs" \
    "$bin" -q scan "$tmp/archive" --profile "$tmp/airframe.toml" --jobs "$jobs" --rows "$tmp/rows-$jobs.jsonl"
  read -r wall rss < "$tmp/time-$jobs"
  n=$((airframes * flights))
  echo "scan on $jobs thread(s): $wall s, $(python3 -c "print(round($n / $wall, 1))") flights/s, peak RSS $((rss / 1024)) MiB"
done
cmp -s "$tmp/rows-1.jsonl" "$tmp/rows-2.jsonl" && echo "rows on 1 and 2 threads: identical" || echo "rows on 1 and 2 threads: DIFFER"
python3 -c "
w = {}
for j in (1, 2):
    wall, _ = open('$tmp/time-%d' % j).read().split()
    w[j] = float(wall)
print(f'speed-up on 2 threads: {w[1] / w[2]:.2f}x')"
"$bin" -q history "$tmp/rows-2.jsonl" --json "$tmp/history.json" > /dev/null
python3 - "$tmp/history.json" "$fall" <<'PY'
import json, math, sys
doc = json.load(open(sys.argv[1]))
fall = float(sys.argv[2])
lost_at = math.ceil(round(0.2 / fall, 6)) + 1  # the flight (1-based) whose truth is 0.8
degrading = [s for s in doc["series"] if s["actuator"] == "motor2" and int(s["airframe"].split()[1]) % 5 == 1]
healthy = [s for s in doc["series"] if s not in degrading]
ahead = [lost_at - s["alarm_from_flight"] for s in degrading if s["alarm_from_flight"]]
print(f"history: {len(ahead)} of {len(degrading)} weakening motors flagged, "
      f"{min(ahead) if ahead else '-'}-{max(ahead) if ahead else '-'} flights before the truth reaches 0.8 (flight {lost_at}); "
      f"{sum(1 for s in healthy if s['alarm_from_flight'])} of {len(healthy)} healthy series flagged")
PY
