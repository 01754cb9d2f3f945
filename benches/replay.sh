#!/usr/bin/env bash
# Replay benchmark (the targets in docs/results.md): a one-hour tlog from the simulator (quad X, ATTITUDE +
# SERVO_OUTPUT_RAW + RAW_IMU at 50 Hz, 4 actuators) through both filters and the diagnosis.
# Reports wall time and peak RSS from GNU time: on one core (one rayon thread pinned to CPU 0,
# so the two filters step in turn) and as `replay` runs by default (the two filters of a
# vehicle on two cores). The target log has ATTITUDE and SERVO_OUTPUT_RAW only: the same
# log without RAW_IMU, where the monitor estimates from the rates (n = 11, 3 measurements);
# with RAW_IMU it also fits a_z (4 measurements), which costs about a fifth more.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
./target/release/ahcmon sim --scenario replay/scenarios/quad-x-1h.toml --tlog "$tmp/1h.tlog" >/dev/null
ls -l "$tmp/1h.tlog"
python3 benches/strip_tlog.py "$tmp/1h.tlog" "$tmp/1h-design.tlog" 27
echo "target log (ATTITUDE + SERVO_OUTPUT_RAW), one core:"
RAYON_NUM_THREADS=1 taskset -c 0 /usr/bin/time -v ./target/release/ahcmon replay "$tmp/1h-design.tlog" 2>&1 >/dev/null \
  | grep -E "Elapsed|Maximum resident"
echo "with RAW_IMU (a_z), one core:"
RAYON_NUM_THREADS=1 taskset -c 0 /usr/bin/time -v ./target/release/ahcmon replay "$tmp/1h.tlog" 2>&1 >/dev/null \
  | grep -E "Elapsed|Maximum resident"
echo "with RAW_IMU (a_z), default (two filters on two cores):"
/usr/bin/time -v ./target/release/ahcmon replay "$tmp/1h.tlog" 2>&1 >/dev/null \
  | grep -E "Elapsed|Maximum resident"
