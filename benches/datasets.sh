#!/usr/bin/env bash
# The dataset benchmark: every labelled case of the external logs (tests/datasets/*.toml name
# them, with their truth) replayed and scored; one table on stdout, the JSON in
# target/datasets.json. The logs are not in the repository: give their folder as the first
# argument or AHCMON_SHARED_DATA (default ../shared/data).
set -euo pipefail
cd "$(dirname "$0")/.."
data="${1:-${AHCMON_SHARED_DATA:-../shared/data}}"
cargo build --release --quiet
./target/release/ahcmon benchmark tests/datasets/*.toml --data "$data" --json target/datasets.json
echo "JSON: target/datasets.json" >&2
