#!/usr/bin/env bash
# C ABI tests of topoloc, against an already built library (cargo build --release --lib).
#
#   bash tests/c/run.sh
#
# Environment:
#   TOPOLOC_TARGET_DIR        directory holding libtopoloc.so and libtopoloc.a
#                             (default: <repo>/target/release)
#   TOPOLOC_C_BUILD_DIR       where test binaries go (default: <repo>/build/c-tests; recreated)
#   TOPOLOC_CHECK_STATIC_LIBS set to 1 to also ask cargo which system libraries a static link needs
#                             and fail if that differs from the list pinned below (runs cargo)
#   TOPOLOC_C_RUNS            "shared" stops after the run against the shared library (the quick
#                             tier of scripts/test.sh); default: every run
#   CC, CXX                   compilers (default: cc, c++)
#
# Sections: exported symbols vs header, SONAME, header alone (C11 and C++17), the test program
# against the shared library, again under ASan+UBSan, under ThreadSanitizer, under valgrind (if
# installed), and linked statically against libtopoloc.a.
#
# The test program, test_topoloc, is one binary built from main.c (the entry point), harness.c
# and harness.h (the CHECK macros, the generated worlds, shared helpers) and one test_<section>.c
# per section of include/topoloc.h; every run prints "<N> passed, 0 failed".
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$repo/scripts/lib.sh"
target="$(release_library_dir "$repo")"
build="${TOPOLOC_C_BUILD_DIR:-$repo/build/c-tests}"
CC="${CC:-cc}"
CXX="${CXX:-c++}"

# System libraries a static link against libtopoloc.a needs, as printed ONCE by
#   cargo rustc --release --lib --crate-type staticlib -- --print native-static-libs
# (rustc 1.95, x86_64-unknown-linux-gnu, glibc). CMakeLists.txt's TOPOLOC_NATIVE_STATIC_LIBS must
# be the same string (checked below); it feeds Topoloc::topoloc_static and topoloc.pc.
# TOPOLOC_CHECK_STATIC_LIBS=1 re-asks cargo and fails when the list changes (e.g. after adding a
# dependency or a toolchain update).
PINNED_STATIC_LIBS="-ldl -lstdc++ -lopencv_calib3d -lopencv_features2d -lopencv_flann -lopencv_imgcodecs -lopencv_imgproc -lopencv_core -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc"

CFLAGS_STRICT=(-std=c11 -Wall -Wextra -Werror -pedantic)
# The README's loop-closure function, extracted into the build dir below (test_readme.c runs it).
README_SNIPPET="$build/readme_close_loops.c"
TEST_SOURCES=("$here/main.c" "$here/harness.c" "$here"/test_*.c "$README_SNIPPET")
CXXFLAGS_STRICT=(-std=c++17 -Wall -Wextra -Werror -pedantic)

# Runs a test binary, shows its output, and checks its exit status and its summary line.
run_test() {
    local log="$1"
    shift
    local status=0
    "$@" 2>&1 | tee "$log" || status=$?
    [[ $status -eq 0 ]] || fail "$* exited with status $status"
    grep -Eq '^[0-9]+ passed, 0 failed$' "$log" || fail "$*: no '<N> passed, 0 failed' line"
}

[[ -f "$target/libtopoloc.a" ]] ||
    fail "$target/libtopoloc.a is missing; build it with: cargo build --release --lib"

rm -rf "$build"
# The library's SONAME is libtopoloc.so.MAJOR (libtopoloc.so.0.MINOR before 1.0, see build.rs),
# which is what the test programs ask the dynamic loader for: give them the installed layout
# (soname link and dev link).
major="$(sed -n 's/^#define TOPOLOC_VERSION_MAJOR \([0-9][0-9]*\)$/\1/p' "$repo/include/topoloc.h")"
minor="$(sed -n 's/^#define TOPOLOC_VERSION_MINOR \([0-9][0-9]*\)$/\1/p' "$repo/include/topoloc.h")"
[[ -n "$major" && -n "$minor" ]] || fail "no TOPOLOC_VERSION_MAJOR/MINOR in include/topoloc.h"
expected_soname="$(soname_of_version "$major" "$minor")"
link_library_dir "$target/libtopoloc.so" "$expected_soname" "$build/lib"
# The README's C block that defines close_loops, unchanged (a new host copies it as is).
awk '/^```c$/ { block = ""; inside = 1; next }
     /^```$/ && inside { inside = 0; if (block ~ /\nint close_loops\(/) { printf "%s", block; found = 1; exit } next }
     inside { block = block $0 "\n" }
     END { if (!found) exit 1 }' "$repo/README.md" >"$README_SNIPPET" ||
    fail "README.md has no C block defining close_loops (tests/c/test_readme.c runs it)"
# -lm: the test program itself uses libm (cos, sin).
LINK_SHARED=(-L"$build/lib" "-Wl,-rpath,$build/lib" -ltopoloc -pthread -lm)

echo "library:   $target"
echo "build dir: $build"
echo "compilers: $("$CC" --version | head -n1) / $("$CXX" --version | head -n1)"

section "SONAME"
soname="$(library_soname "$target/libtopoloc.so")"
echo "SONAME: ${soname:-<none>}"
[[ "$soname" == "$expected_soname" ]] || fail "SONAME is '${soname}', expected $expected_soname"

section "exported symbols match the header's declarations"
header_functions="$(grep -E '^[A-Za-z_][A-Za-z0-9_ ]*[ *]topoloc_[a-z0-9_]+\(' "$repo/include/topoloc.h" |
    sed -E 's/^.*[ *](topoloc_[a-z0-9_]+)\(.*$/\1/' | sort -u)"
exported="$(nm -D --defined-only "$target/libtopoloc.so" | awk '$2 == "T" && $3 ~ /^topoloc_/ { print $3 }' | sort -u)"
missing="$(comm -23 <(echo "$header_functions") <(echo "$exported"))"
extra="$(comm -13 <(echo "$header_functions") <(echo "$exported"))"
echo "$(echo "$header_functions" | wc -l) functions declared, $(echo "$exported" | wc -l) exported"
[[ -z "$missing" ]] || fail "declared in topoloc.h but not exported by the library: $missing"
[[ -z "$extra" ]] || fail "exported by the library but not declared in topoloc.h: $extra"
# readelf, not nm: the archive's objects carry embedded LLVM bitcode, which binutils' nm hands to
# the system LLVM plugin (older than rustc's LLVM) and then reports no symbols.
static_exported="$(readelf -Ws "$target/libtopoloc.a" 2>/dev/null |
    awk '$4 == "FUNC" && $5 == "GLOBAL" && $7 != "UND" && $8 ~ /^topoloc_/ { print $8 }' | sort -u)"
[[ "$static_exported" == "$exported" ]] || fail "libtopoloc.a and libtopoloc.so define different topoloc_ functions"

section "header alone: C11 and C++17, included twice"
"$CC" "${CFLAGS_STRICT[@]}" -Wstrict-prototypes -Wundef -Wshadow -I"$repo/include" \
    "$here/header_alone.c" -o "$build/header_alone_c" "${LINK_SHARED[@]}"
"$CXX" "${CXXFLAGS_STRICT[@]}" -Wundef -Wshadow -I"$repo/include" \
    "$here/header_alone.cpp" -o "$build/header_alone_cpp" "${LINK_SHARED[@]}"
"$build/header_alone_c"
"$build/header_alone_cpp"
echo "ok"

section "test_topoloc: shared library"
"$CC" "${CFLAGS_STRICT[@]}" -g -O1 -I"$repo/include" "${TEST_SOURCES[@]}" \
    -o "$build/test_topoloc" "${LINK_SHARED[@]}"
run_test "$build/shared.log" "$build/test_topoloc"

if [[ "${TOPOLOC_C_RUNS:-all}" == shared ]]; then
    section "C ABI checks passed (shared library only: TOPOLOC_C_RUNS=shared)"
    exit 0
fi

section "test_topoloc: AddressSanitizer + UndefinedBehaviorSanitizer"
"$CC" "${CFLAGS_STRICT[@]}" -g -O1 -fsanitize=address,undefined -fno-omit-frame-pointer \
    -I"$repo/include" "${TEST_SOURCES[@]}" -o "$build/test_topoloc_asan" "${LINK_SHARED[@]}"
lsan_env=()
if [[ -f "$here/lsan.supp" ]]; then
    lsan_env=(LSAN_OPTIONS="suppressions=$here/lsan.supp:print_suppressions=1")
fi
run_test "$build/asan.log" env ASAN_OPTIONS=detect_leaks=1 \
    UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 "${lsan_env[@]}" "$build/test_topoloc_asan"

section "test_topoloc: ThreadSanitizer (the C side: callers' threads, shared maps, busy handles)"
# The Rust library is not instrumented (that needs a nightly toolchain), so TSan cannot see its
# synchronisation (Rust atomics: the handles' busy flag, rayon's and std's thread hand-offs) and
# would report the library's intercepted memcpy/memset as races. tsan.supp ignores interceptor
# calls made from libtopoloc.so; TSan then checks every access of the C side (results,
# descriptors, callbacks' state, the threads' own data) against pthread's synchronisation.
"$CC" "${CFLAGS_STRICT[@]}" -g -O1 -fsanitize=thread -I"$repo/include" "${TEST_SOURCES[@]}" \
    -o "$build/test_topoloc_tsan" "${LINK_SHARED[@]}"
run_test "$build/tsan.log" env TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$here/tsan.supp" \
    "$build/test_topoloc_tsan"

section "test_topoloc: valgrind"
if command -v valgrind >/dev/null 2>&1; then
    # valgrind.supp holds only a commented one-time allocation of the Rust runtime.
    # On one CPU: OpenCV's parallel loops (cv::kmeans when fitting a VLAD codebook) run on TBB,
    # whose worker threads live until the process exits, and valgrind reports the TLS block of
    # any thread alive at exit as "possibly lost". With one CPU TBB starts no worker. valgrind
    # runs one thread at a time anyway, so this costs nothing.
    one_cpu=()
    if command -v taskset >/dev/null 2>&1; then
        cpu="$(sed -n 's/^Cpus_allowed_list:[[:space:]]*\([0-9][0-9]*\).*/\1/p' /proc/self/status)"
        [[ -n "$cpu" ]] && one_cpu=(taskset -c "$cpu")
    fi
    [[ ${#one_cpu[@]} -gt 0 ]] || echo "note: taskset not found; TBB worker threads may be reported at exit"
    run_test "$build/valgrind.log" "${one_cpu[@]}" valgrind --quiet --error-exitcode=1 \
        --leak-check=full --suppressions="$here/valgrind.supp" "$build/test_topoloc"
else
    echo "SKIPPED: valgrind is not installed"
fi

section "system libraries for a static link"
echo "pinned: $PINNED_STATIC_LIBS"
cmake_libs="$(sed -n 's/^set(TOPOLOC_NATIVE_STATIC_LIBS "\(.*\)")$/\1/p' "$repo/CMakeLists.txt")"
[[ "$cmake_libs" == "$PINNED_STATIC_LIBS" ]] ||
    fail "CMakeLists.txt's TOPOLOC_NATIVE_STATIC_LIBS ('$cmake_libs') differs from PINNED_STATIC_LIBS here"
if [[ "${TOPOLOC_CHECK_STATIC_LIBS:-0}" == "1" ]]; then
    cargo_env=()
    # Use the cargo target dir that holds TOPOLOC_TARGET_DIR (<target-dir>/release).
    if [[ "$(basename "$target")" == "release" ]]; then
        cargo_env=(CARGO_TARGET_DIR="$(dirname "$target")")
    fi
    cargo_log="$build/native-static-libs.log"
    if ! (cd "$repo" && env "${cargo_env[@]}" cargo rustc --release --lib --crate-type staticlib \
        -- --print native-static-libs) >"$cargo_log" 2>&1; then
        cat "$cargo_log" >&2
        fail "cargo rustc --print native-static-libs failed"
    fi
    printed="$(sed -n 's/^.*native-static-libs: //p' "$cargo_log" | tail -n1)"
    echo "cargo:  ${printed:-<nothing printed>}"
    if [[ "$printed" != "$PINNED_STATIC_LIBS" ]]; then
        fail "the system libraries a static link needs changed: cargo prints '$printed'," \
            "tests/c/run.sh pins '$PINNED_STATIC_LIBS'. Update PINNED_STATIC_LIBS here and" \
            "TOPOLOC_NATIVE_STATIC_LIBS in CMakeLists.txt (it feeds TopolocConfig.cmake and topoloc.pc)."
    fi
    echo "unchanged"
else
    echo "(not re-checked; set TOPOLOC_CHECK_STATIC_LIBS=1 to compare with cargo's list)"
fi

section "test_topoloc: linked statically against libtopoloc.a"
# shellcheck disable=SC2086 # the pinned list is a word list on purpose
"$CC" "${CFLAGS_STRICT[@]}" -g -O1 -I"$repo/include" "${TEST_SOURCES[@]}" \
    -o "$build/test_topoloc_static" "$target/libtopoloc.a" $PINNED_STATIC_LIBS -pthread
if readelf -d "$build/test_topoloc_static" | grep -q 'libtopoloc'; then
    fail "the static test program depends on a shared libtopoloc"
fi
run_test "$build/static.log" "$build/test_topoloc_static"

section "all C ABI checks passed"
