#!/usr/bin/env bash
# Replay benchmark (DESIGN.md targets): a one-hour tlog from the simulator (quad X, ATTITUDE +
# SERVO_OUTPUT_RAW + RAW_IMU at 50 Hz, 4 actuators) through both filters and the diagnosis.
# Reports wall time and peak RSS from GNU time.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
tmp=$(mktemp -d)
./target/release/ahcmon sim --scenario replay/scenarios/quad-x-1h.toml --tlog "$tmp/1h.tlog" >/dev/null
ls -l "$tmp/1h.tlog"
/usr/bin/time -v ./target/release/ahcmon replay "$tmp/1h.tlog" 2>&1 >/dev/null \
  | grep -E "Elapsed|Maximum resident"
rm -rf "$tmp"
