#!/usr/bin/env bash
# `ahcmon replay` on every log of the external data (tlog, DataFlash, ULog; told by content):
# wall time, peak RSS and MB/s per file, the samples paired and the fault decisions made
# (a healthy flight should make none; benches/datasets.sh judges them against the truth).
# The data's folder: AHCMON_SHARED_DATA, else ../shared/data beside the repository.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${AHCMON_SHARED_DATA:-../shared/data}
cargo build --release --quiet
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
printf '%-62s %8s %7s %8s %8s %7s %6s\n' file MB s MiB MB/s samples faults
find "$data" -type f \( -name '*.tlog' -o -iname '*.bin' -o -name '*.ulg' \) | sort | while read -r f; do
  size=$(stat -c %s "$f")
  # GNU time's elapsed is in 0.01 s, too coarse for these logs: the wall clock in ns instead.
  start=$(date +%s.%N)
  /usr/bin/time -f '%M' -o "$tmp/time" ./target/release/ahcmon replay "$f" --headless \
    --decisions "$tmp/d.jsonl" >"$tmp/out" 2>"$tmp/err" || true
  end=$(date +%s.%N)
  secs=$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.4f", b - a }')
  kib=$(tail -n 1 "$tmp/time")
  samples=$({ grep -o 'telemetry: [0-9]* samples' "$tmp/out" || true; } | awk '{s+=$2} END {print s+0}')
  faults=$(grep -c '"event": *"fault"' "$tmp/d.jsonl" 2>/dev/null || true)
  awk -v f="${f#"$data"/}" -v b="$size" -v s="$secs" -v k="$kib" -v n="$samples" -v x="${faults:-0}" \
    'BEGIN { mbs = (s > 0) ? b / 1e6 / s : 0; printf "%-62s %8.2f %7.3f %8.1f %8.0f %7d %6d\n", f, b / 1e6, s, k / 1024, mbs, n, x }'
done
