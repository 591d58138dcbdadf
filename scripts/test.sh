#!/usr/bin/env bash
# Runs topoloc's tests in one of two tiers and prints each section's time.
#
#   bash scripts/test.sh           # full tier (what .ci/run runs): every layer
#   bash scripts/test.sh --quick   # quick tier, for the edit-test loop (after a first build)
#
# Quick tier: formatting, clippy, the core crate's Rust tests and the header check, the C ABI tests
# against the shared library (no sanitizers, valgrind or static link) and pytest in tree.
#
# Full tier: lints (rustfmt, clippy, rustdoc with -D warnings, the MSRV, clang-format, ruff,
# mypy --strict, shellcheck), every Rust test of the workspace (the header check among them), the
# main job (a small demo run), C (plain, ASan+UBSan, valgrind, static), C++ RAII, the CMake consumer against
# the installed package (with the SLAM adapters and drift demos, shared and static), Python (a
# smoke run in tree, then the whole suite against the installed wheel) and the fuzz smoke runs.
# The release library is built once and reused by the C, C++, CMake and Python sections; a fresh
# clone builds in the machine's shared build cache (below), so dependencies compile once.
#
# With CI=true (as .ci/run is run), a test that needs the ONNX or XFeat model fails instead of
# skipping when the model is missing.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

tier=full
case "${1:-}" in
    "") ;;
    --quick) tier=quick ;;
    --full) tier=full ;;
    *)
        echo "usage: scripts/test.sh [--quick | --full]" >&2
        exit 2
        ;;
esac

# Section timing: each section's wall time, printed as it ends and again as a table at the end.
started=$SECONDS
section_name=""
section_start=$SECONDS
timings=()
end_section() {
    if [[ -n "$section_name" ]]; then
        local took=$((SECONDS - section_start))
        timings+=("$(printf '%5d s  %s' "$took" "$section_name")")
        printf -- '--- %s: %d s\n' "$section_name" "$took"
    fi
}
section() {
    end_section
    section_name="$1"
    section_start=$SECONDS
    printf '\n=== %s ===\n' "$1"
}
summary() {
    end_section
    section_name=""
    printf '\n=== Section times (%s tier) ===\n' "$tier"
    printf '%s\n' "${timings[@]}"
    printf '%5d s  total\n' "$((SECONDS - started))"
}
# The failing section's name is kept before `summary` clears it.
failed_section=""
trap 'status=$?; if ((status != 0)); then failed_section="${section_name:-set-up}"; summary; echo "FAILED in: $failed_section" >&2; fi' EXIT

# A checkout without a target/ folder (a fresh clone) builds in the machine's shared build cache:
# target/ becomes a link to it, so compiled dependencies are reused across clones (cargo rebuilds
# what changed, the checkout's own crates always). TOPOLOC_BUILD_CACHE=none keeps a private one.
build_cache="${TOPOLOC_BUILD_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/topoloc/target}"
if [[ ! -e "$root/target" && "$build_cache" != none ]]; then
    mkdir -p "$build_cache"
    ln -s "$build_cache" "$root/target"
    echo "test.sh: target/ -> $build_cache (the shared build cache; TOPOLOC_BUILD_CACHE=none: a private one)"
fi

section "Set-up (system packages, Python packages, models)"
bash scripts/install-deps.sh
bash scripts/setup-models.sh

section "Rust formatting and lints"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --quiet -- -D warnings

if [[ "$tier" == full ]]; then
    section "Rust docs (0 warnings) and the MSRV"
    # Libraries and binaries apart: the CLI binary and the library are both named topoloc.
    RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --lib --quiet
    RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --bins --quiet
    bash scripts/check-msrv.sh

    section "C, C++, Python and shell lints"
    bash scripts/lint.sh
fi

section "Rust tests"
# nextest runs the tests of every binary in one pool: the long CLI tests no longer leave the
# second core idle. (The crates have no runnable doc tests: their examples are ```text.)
# The header check is a test of tools/gen-header (the checked-in topoloc.h is what it generates).
if [[ "$tier" == quick ]]; then
    cargo nextest run -p topoloc -p topoloc-gen-header --cargo-quiet --status-level fail \
        --final-status-level slow
else
    cargo nextest run --workspace --cargo-quiet --status-level fail --final-status-level slow
fi

section "Release library"
# The same invocation as CMake and the Python wheel use, so that they find it built.
cargo build --release --lib --quiet
export TOPOLOC_TARGET_DIR="$root/target/release"

if [[ "$tier" == quick ]]; then
    section "C ABI tests (shared library only)"
    TOPOLOC_C_RUNS=shared bash tests/c/run.sh

    section "Python shim (in tree)"
    TOPOLOC_LIBRARY="$root/target/release/libtopoloc.so" python3 -m pytest -q python/tests
    summary
    echo "Quick tier passed"
    exit 0
fi

section "Release CLI (it runs the demo and generates the drift demos' sequences)"
# As scripts/demo.sh builds it (cargo run -p topoloc-cli), so the demo finds it built.
cargo build --release -p topoloc-cli --quiet

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

section "C ABI tests (shared, ASan+UBSan, valgrind, static)"
TOPOLOC_CHECK_STATIC_LIBS=1 bash tests/c/run.sh

section "C++ RAII tests"
bash tests/cpp/run.sh

section "CMake consumer (find_package against the installed prefix)"
bash tests/consumer/run.sh

section "Python shim (smoke run in tree)"
TOPOLOC_LIBRARY="$root/target/release/libtopoloc.so" python3 -m pytest -q \
    python/tests/test_package.py python/tests/test_library.py python/tests/test_localizer.py

section "Python package (the whole suite against the wheel installed into target/py-venv)"
bash python/tests/run_installed.sh

section "GRNN training smoke (python/train: train -> export -> load -> localize, typed errors)"
bash python/train/setup.sh
TOPOLOC_LIBRARY="$root/target/release/libtopoloc.so" /usr/bin/python3 python/train/smoke.py

section "Fuzzing (libFuzzer on the C ABI: kept crashers, then a minute per target)"
bash fuzz/run.sh build
bash fuzz/run.sh smoke 60

summary
echo "All test layers passed"
