#!/usr/bin/env bash
# The main job: installs what is missing (scripts/install-deps.sh), sets up the default model
# (scripts/setup-models.sh: ONNX Runtime, MobileNetV2 MLF and XFeat in ~/.cache/topoloc; idempotent,
# ~30 s the first time, needs the network then), builds topoloc and runs `topoloc demo` on its
# embedded default: a generated indoor world, its graph from the voxel skeleton, a map from
# rendered views with the ONNX backend, a query flight under dim light; it prints MNA/OHA/R@N
# single-frame vs filter vs metric mode vs verification, latency and peak memory, and writes
# topoloc-demo.png (top view with graph, trajectory and the predictions of the configuration with
# the highest MNA, ties broken by OHA, named in the picture and in the output).
# When the model cannot be set up the demo fails with setup-models's message: it does not fall back
# to VLAD silently. `--backend vlad` asks for the VLAD fallback and skips the model set-up.
# Extra arguments go to the demo, e.g. `scripts/demo.sh --json` (stdout is then one JSON object;
# the set-up steps write to stderr).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh >&2

vlad=0
prev=""
for arg in "$@"; do
  [[ "$arg" == "--backend=vlad" || ("$prev" == "--backend" && "$arg" == "vlad") ]] && vlad=1
  prev="$arg"
done
if ((!vlad)); then
  if ! bash scripts/setup-models.sh >&2; then
    echo "demo: scripts/setup-models.sh failed (its message is above), so the default ONNX backend" \
      "is not set up; the demo does not fall back to VLAD silently. Fix the cause (network, pip," \
      "apt) and run again, or ask for the fallback: scripts/demo.sh --backend vlad" >&2
    exit 1
  fi
fi
cargo run --release --quiet -p topoloc-cli -- demo "$@"
