#!/usr/bin/env bash
# The main job: builds topoloc and runs `topoloc demo` on its embedded default (a generated map
# and camera descriptor stream), printing accuracy metrics and per-frame latency.
# Extra arguments go to the demo, e.g. `scripts/demo.sh --json`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh
cargo run --release --quiet -p topoloc-cli -- demo "$@"
