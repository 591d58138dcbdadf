#!/usr/bin/env bash
# The main job: builds topoloc and runs `topoloc demo` on its embedded default: a generated indoor
# world, its graph from the voxel skeleton, a map from rendered views (ONNX backend when
# scripts/setup-models.sh has run, else VLAD, and it says which), a query flight under dim light;
# it prints MNA/OHA/R@N single-frame vs filter, latency and peak memory, and writes
# topoloc-demo.png (top view with graph, trajectory and predictions).
# Extra arguments go to the demo, e.g. `scripts/demo.sh --json`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh
cargo run --release --quiet -p topoloc-cli -- demo "$@"
