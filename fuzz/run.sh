#!/usr/bin/env bash
# Coverage-guided fuzzing of topoloc's C ABI with libFuzzer, on the stable toolchain.
#
#   bash fuzz/run.sh build                 # instrumented library + the four harnesses
#   bash fuzz/run.sh smoke [SECONDS]       # regressions, then every target for SECONDS (60)
#   bash fuzz/run.sh run TARGET SECONDS    # one target, longer (corpus kept in target/fuzz)
#   bash fuzz/run.sh totals                # executions recorded so far, per target
#
# How: the Rust library is built by rustc with LLVM's sanitizer-coverage passes (stable flags:
# -Cpasses=sancov-module and -Cllvm-args=-sanitizer-coverage-*), linked with C harnesses
# (fuzz/harness) compiled by Debian's clang with -fsanitize=fuzzer,address, which supplies
# libFuzzer and its coverage callbacks. See fuzz/README.md.
#
# Bounds (any breach is a failure): no caught panic (TOPOLOC_ERR_PANIC), no crash, no input
# running longer than $TIMEOUT_S s, no single allocation above $MALLOC_LIMIT_MB MB, resident
# memory under $RSS_LIMIT_MB MB. Every run is appended to target/fuzz/runs.tsv.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
work="$repo/target/fuzz"
bin="$work/bin"
# The instrumented build's own cargo target dir, outside the checkout: its dependencies (every
# crate compiled with sanitizer coverage) are then built once per machine and toolchain, not
# once per clone; cargo rebuilds what changed, the checkout's own crates always.
build_dir="${TOPOLOC_FUZZ_TARGET_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/topoloc/fuzz-target}"
triple="$(rustc -vV | sed -n 's/^host: //p')"
TARGETS=(map_load describer_spec image_frame keyframe_db)
TIMEOUT_S=10
MALLOC_LIMIT_MB=256
RSS_LIMIT_MB=2048
CC="${FUZZ_CC:-clang}"

fail() { printf 'fuzz: FAILED: %s\n' "$*" >&2; exit 1; }

# The system libraries a static link against the library needs (tests/c/run.sh pins them).
native_libs() {
    sed -n 's/^PINNED_STATIC_LIBS="\(.*\)"$/\1/p' "$repo/tests/c/run.sh"
}

build() {
    command -v "$CC" >/dev/null || fail "$CC not found: run scripts/install-deps.sh (Debian's clang)"
    local runtime
    runtime="$("$CC" -print-file-name=libclang_rt.fuzzer-x86_64.a)"
    [[ -f "$runtime" ]] || fail "no libFuzzer runtime for $CC: install Debian's libclang-rt-14-dev (scripts/install-deps.sh)"
    # --target: RUSTFLAGS then reach the library and its dependencies, not build scripts.
    local flags=(-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4
        -Cllvm-args=-sanitizer-coverage-inline-8bit-counters
        -Cllvm-args=-sanitizer-coverage-pc-table
        -Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing)
    RUSTFLAGS="${flags[*]}" CARGO_TARGET_DIR="$build_dir" cargo build --quiet --release \
        --manifest-path "$here/Cargo.toml" --target "$triple"
    mkdir -p "$bin"
    local lib="$build_dir/$triple/release/libtopoloc_fuzz.a"
    local t
    for t in "${TARGETS[@]}"; do
        # shellcheck disable=SC2046
        "$CC" -g -O1 -Wall -Wextra -Werror -fsanitize=fuzzer,address -I"$repo/include" "$here/harness/$t.c" "$lib" \
            $(native_libs) -o "$bin/$t"
    done
    cargo run --quiet --release --example fuzz_seeds -- "$work/seeds" 2>/dev/null
    mkdir -p "$work/seeds/image_frame" # its inputs are generated from nothing
    echo "fuzz: built ${TARGETS[*]} in $bin"
}

# libFuzzer options and the environment of one target.
target_args() {
    local t="$1"
    case "$t" in
        map_load) echo "-max_len=262144" ;;
        describer_spec) echo "-max_len=4096 -dict=$here/describer_spec.dict" ;;
        image_frame) echo "-max_len=8192" ;;
        keyframe_db) echo "-max_len=8192" ;;
        *) fail "unknown target '$t' (one of: ${TARGETS[*]})" ;;
    esac
}
export TOPOLOC_FUZZ_BASE_MAP="$work/seeds/base/onnx.topoloc"
export TOPOLOC_FUZZ_IMAGE_MAP="$work/seeds/base/vlad.topoloc"
# ASan: allocations above the limit and leaks are failures; Rust's allocator is malloc here.
export ASAN_OPTIONS="allocator_may_return_null=0:detect_leaks=1:malloc_limit_mb=$MALLOC_LIMIT_MB"

# Runs the kept crashers of a target (each must now pass), then fuzzes it for $2 seconds.
run_target() {
    local t="$1" seconds="$2"
    [[ -x "$bin/$t" ]] || fail "$bin/$t missing: bash fuzz/run.sh build"
    [[ -f "$TOPOLOC_FUZZ_BASE_MAP" ]] || export TOPOLOC_FUZZ_BASE_MAP="$work/seeds/base/vlad.topoloc"
    local corpus="$work/corpus/$t" artifacts="$work/artifacts/$t/" log="$work/logs/$t.log"
    mkdir -p "$corpus" "$artifacts" "$(dirname "$log")"
    local regressions=()
    mapfile -t regressions < <(find "$here/regressions/$t" -type f ! -name '*.md' 2>/dev/null | sort)
    if ((${#regressions[@]})); then
        "$bin/$t" -timeout=$TIMEOUT_S -rss_limit_mb=$RSS_LIMIT_MB "${regressions[@]}" \
            >"$work/logs/$t.regressions.log" 2>&1 ||
            fail "$t: a kept crasher fails again (see $work/logs/$t.regressions.log)"
        echo "fuzz: $t: ${#regressions[@]} kept crashers pass"
    fi
    local status=0
    # shellcheck disable=SC2046
    "$bin/$t" $(target_args "$t") -timeout=$TIMEOUT_S -rss_limit_mb=$RSS_LIMIT_MB \
        -malloc_limit_mb=$MALLOC_LIMIT_MB -max_total_time="$seconds" -print_final_stats=1 \
        -artifact_prefix="$artifacts" "$corpus" "$work/seeds/$t" "$here/regressions/$t" \
        >"$log" 2>&1 || status=$?
    local runs
    runs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)"
    printf '%s\t%s\t%s\t%s\t%s\n' "$(date -u +%FT%TZ)" "$t" "${runs:-0}" "$seconds" "$status" \
        >>"$work/runs.tsv"
    if ((status != 0)); then
        grep -E 'ERROR|SUMMARY|panic|Test unit written' "$log" | head -n 20 >&2 || true
        fail "$t: libFuzzer exited with $status after ${runs:-?} executions (log: $log); keep the crasher in fuzz/regressions/$t/"
    fi
    echo "fuzz: $t: ${runs:-0} executions in ${seconds}s, no crash, hang or oversized allocation"
}

totals() {
    [[ -f "$work/runs.tsv" ]] || { echo "no runs recorded"; return; }
    awk -F'\t' '{ runs[$2] += $3; secs[$2] += $4; bad[$2] += ($5 != 0); all += $3 }
        END { for (t in runs) printf "%-15s %12d executions %8d s %d failed runs\n", t, runs[t], secs[t], bad[t];
              printf "%-15s %12d executions\n", "total", all }' "$work/runs.tsv"
}

case "${1:-}" in
    build) build ;;
    smoke)
        seconds="${2:-60}"
        for t in "${TARGETS[@]}"; do run_target "$t" "$seconds"; done
        ;;
    run) [[ $# -eq 3 ]] || fail "usage: fuzz/run.sh run TARGET SECONDS"; run_target "$2" "$3" ;;
    totals) totals ;;
    *) fail "usage: fuzz/run.sh build | smoke [SECONDS] | run TARGET SECONDS | totals" ;;
esac
