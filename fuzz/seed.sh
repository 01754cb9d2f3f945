#!/usr/bin/env bash
# Seed corpus for the fuzz targets, in fuzz/corpus/<target>/ (not committed): the heads of the
# repository's tlogs, profiles and scenarios, and, where ../shared/data is present, the heads
# of its tlogs, DataFlash and ULog logs. Heads, so that each run of a target is short: 64 KiB
# of a tlog or DataFlash log (its formats and parameters and the first seconds of flight),
# 256 KiB of a ULog (whose definitions come first and run long).
set -euo pipefail
cd "$(dirname "$0")"
root=..
shared=$root/../shared/data
c=corpus
mkdir -p $c/tlog $c/datagrams $c/dataflash $c/ulog $c/profile $c/scenario
n=0
for f in "$root"/replay/tlogs/*/*.tlog "$shared"/*/*.tlog "$shared"/*/*/*.tlog; do
  [ -f "$f" ] || continue
  n=$((n + 1))
  head -c 65536 "$f" > "$c/tlog/seed$n"
  # The same frames without their stamps, as datagrams of 128 bytes (first byte 127).
  python3 - "$f" "$c/datagrams/seed$n" <<'PY'
import sys
data = open(sys.argv[1], "rb").read(65536)
out, i = bytearray([127]), 0
while i + 10 < len(data):
    m = data[i + 8]
    n = 12 + data[i + 9] + (13 if m == 0xFD and data[i + 10] & 1 else 0) if m == 0xFD else 8 + data[i + 9]
    out += data[i + 8 : i + 8 + n]
    i += 8 + n
open(sys.argv[2], "wb").write(out)
PY
done
for f in "$shared"/*/*.BIN "$shared"/*/*.bin; do
  [ -f "$f" ] || continue
  n=$((n + 1))
  head -c 65536 "$f" > "$c/dataflash/seed$n"
done
for f in "$shared"/*/*.ulg; do
  [ -f "$f" ] || continue
  n=$((n + 1))
  head -c 262144 "$f" > "$c/ulog/seed$n"
done
cp "$root"/replay/profiles/*.toml $c/profile/
cp "$root"/replay/scenarios/*.toml $c/scenario/
for t in tlog datagrams dataflash ulog profile scenario; do
  echo "$t: $(ls $c/$t | wc -l) seeds"
done
