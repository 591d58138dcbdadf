#!/usr/bin/env bash
# Runs every test layer: formatting and lints, Rust (unit, integration, FFI, the layer order),
# the header check, the main job (a small demo run), C (plain, ASan+UBSan, valgrind, static),
# C++ RAII, the CMake consumer against the installed package (with the SLAM adapters and drift
# demos, shared and static), Python (in tree and the installed wheel), and the fuzz smoke runs.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/install-deps.sh
bash scripts/setup-models.sh

section() { printf '\n=== %s ===\n' "$1"; }

section "Rust formatting and lints"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --quiet -- -D warnings

section "Rust tests"
cargo test --workspace --quiet

section "C header is current"
cargo run --quiet -p topoloc-gen-header -- --check

section "Release library and tools (the CLI generates the demos' sequences)"
cargo build --release --workspace --quiet
export TOPOLOC_TARGET_DIR="$root/target/release"

section "The main job (scripts/demo.sh as the README runs it, on a small world)"
bash scripts/demo.sh --rooms 2 --legs 1 --plot target/demo-smoke.png --json >target/demo-smoke.json
python3 - <<'PY'
import json, os
report = json.load(open("target/demo-smoke.json"))
assert report["backend"].startswith("onnx"), f"demo ran {report['backend']!r}, not the ONNX default"
assert report["plotted_configuration"] in report["configurations"], report["plotted_configuration"]
assert os.path.getsize("target/demo-smoke.png") > 0, "demo wrote no top view"
print(f"demo: {report['backend'].split(' ')[0]}, plotted {report['plotted_configuration']}, MNA {report['mna']:.3f}")
PY

section "C ABI tests"
TOPOLOC_CHECK_STATIC_LIBS=1 bash tests/c/run.sh

section "C++ RAII tests"
bash tests/cpp/run.sh

section "CMake consumer (find_package against the installed prefix)"
bash tests/consumer/run.sh

section "Python shim"
TOPOLOC_LIBRARY="$root/target/release/libtopoloc.so" python3 -m pytest -q python/tests

section "Python package (wheel installed into target/py-venv)"
bash python/tests/run_installed.sh

section "Fuzzing (libFuzzer on the C ABI: kept crashers, then a minute per target)"
bash fuzz/run.sh build
bash fuzz/run.sh smoke 60

section "All test layers passed"
