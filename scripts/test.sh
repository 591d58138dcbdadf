#!/usr/bin/env bash
# Runs every test layer: formatting and lints, Rust (unit, integration, FFI, the layer order),
# the header check, C (plain, ASan+UBSan, valgrind, static), C++ RAII, the CMake consumer against
# the installed package (with the SLAM adapters and drift demos, shared and static), and Python.
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
