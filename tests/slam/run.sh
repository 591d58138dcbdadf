#!/usr/bin/env bash
# Runs the drift-correction demos of cpp-examples (vins_drift_demo, orbslam_drift_demo), built
# against the installed package by tests/consumer/run.sh, on a generated revisit sequence:
#  - a full run each, whose JSON must show loops used, none of them false, and a corrected ATE
#    at most 20 % of the raw odometry's (the issue's target, on test world 0 under dim light);
#  - a short run each under valgrind memcheck (a VLAD describer, so that ONNX Runtime is not
#    loaded): no invalid access, no definite or indirect leak.
#
#   bash tests/slam/run.sh BUILD_DIR
#
#   TOPOLOC_CLI   the topoloc command-line tool (default: <repo>/target/release/topoloc)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
build="${1:?usage: tests/slam/run.sh BUILD_DIR (the cpp-examples build)}"
cli="${TOPOLOC_CLI:-$repo/target/release/topoloc}"
[[ -x "$cli" ]] || { echo "tests/slam/run.sh: $cli not found; build it: cargo build --release -p topoloc-cli" >&2; exit 1; }
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

echo "generating the describer maps (a training world) and a test sequence"
"$cli" simulate --split train --world 0 --legs 1 --rate-hz 2 --condition bright --out "$work/describer" >/dev/null
"$cli" simulate --split train --world 0 --legs 1 --rate-hz 2 --condition bright --backend vlad --out "$work/vlad" >/dev/null
"$cli" simulate --split test --world 0 --legs 6 --rate-hz 2 --condition dim --depth --out "$work/seq" >/dev/null

for demo in vins_drift_demo orbslam_drift_demo; do
    echo "== $demo: full run"
    json="$("$build/$demo" --sequence "$work/seq/traj-000" --describer "$work/describer/map.topoloc" \
        --out "$work/$demo.png" --json)"
    echo "$json"
    python3 - "$json" "$work/$demo.png" <<'PY'
import json, sys
r = json.loads(sys.argv[1])
assert r["loops_used"] >= 5, f"too few loops used: {r}"
assert r["false_used"] == 0, f"false loops in the pose graph: {r}"
assert r["ate_corrected_m"] <= 0.2 * r["ate_raw_m"], f"corrected ATE above 20 % of raw: {r}"
assert open(sys.argv[2], "rb").read(8) == b"\x89PNG\r\n\x1a\n", "no PNG written"
PY
    echo "== $demo: valgrind memcheck (20 keyframes, VLAD describer)"
    valgrind --quiet --error-exitcode=9 --leak-check=full --errors-for-leak-kinds=definite,indirect \
        "$build/$demo" --sequence "$work/seq/traj-000" --describer "$work/vlad/map.topoloc" \
        --max-keyframes 20 --json
done
echo "== drift demos: all checks passed"
