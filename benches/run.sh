#!/usr/bin/env bash
# Criterion benchmarks and filterpy's UKF timed in the same run, with the speed-up.
set -euo pipefail
cd "$(dirname "$0")/.."
py=.venv/bin/python; [ -x "$py" ] || py=python3
cargo bench --bench filters -- --noplot 2>&1 | tee target/bench.txt | grep -E "^step/|^paper-run|^vehicle-step|time:"
fp=$("$py" benches/filterpy_ukf_timing.py | awk '{print $(NF-1)}')
echo "filterpy UKF step (n=5): ${fp} us"
for f in ukf mit-ukf mit-esmf; do
  ours=$(grep "^step/$f " target/bench.txt | grep -o 'time: *\[[^]]*' | awk '{print $4, $5}')
  val=$(echo "$ours" | awk '{v=$1; if ($2=="ns") v/=1000; print v}')
  echo "$f: ${val} us/step -> $(awk -v a="$fp" -v b="$val" 'BEGIN{printf "%.0f", a/b}')x faster than filterpy's UKF"
done
