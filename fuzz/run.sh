#!/usr/bin/env bash
# A fuzzing campaign over every target, one after the other, on nightly with cargo-fuzz
# (`cargo install cargo-fuzz`): SECONDS_PER_TARGET each (default 600), seeded by seed.sh.
# Prints per target the inputs run, the time, and whether anything crashed or hung (a hang
# is an input that takes over 10 s; the crashing input is saved in fuzz/artifacts/TARGET/).
#   bash fuzz/run.sh 600            # every target
#   bash fuzz/run.sh 60 tlog ulog   # some
set -uo pipefail
cd "$(dirname "$0")"
budget=${1:-600}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(tlog datagrams dataflash ulog profile scenario)
[ -d corpus ] || bash seed.sh
# No sanitizer: the code fuzzed is safe Rust, where a panic or a hang is what there is to find.
cargo +nightly fuzz build -O -s none >&2 || exit 1
mkdir -p logs
for t in "${targets[@]}"; do
  case $t in
    ulog) len=262144 ;;  # a ULog's definitions come before its first data
    *) len=4096 ;;
  esac
  cargo +nightly fuzz run -O -s none "$t" "corpus/$t" -- -max_total_time="$budget" \
    -max_len="$len" -timeout=10 -rss_limit_mb=4096 -print_final_stats=1 > "logs/$t.txt" 2>&1
  rc=$?
  runs=$(grep -oE "stat::number_of_executed_units: *[0-9]+" "logs/$t.txt" | grep -oE "[0-9]+$")
  secs=$(grep -oE "Done [0-9]+ runs in [0-9]+ second" "logs/$t.txt" | grep -oE "in [0-9]+" | grep -oE "[0-9]+")
  found=$(grep -cE "deadly signal|ERROR: libFuzzer: timeout|out-of-memory" "logs/$t.txt")
  echo "$t: ${runs:-0} inputs in ${secs:-?} s (exit $rc, $found crashes or hangs)"
done
