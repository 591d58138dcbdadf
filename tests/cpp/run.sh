#!/usr/bin/env bash
# C++ layer tests: builds tests/cpp/test_raii.cpp, test_status.cpp (the status table against the
# library's), test_loops.cpp (loop closure), test_loop_images.cpp (image keyframes; its learned
# path needs the cache's models, required when CI is "true"), test_pose_fix.cpp (pose fixes) and
# test_trajectory.cpp (trajectory metrics) against include/topoloc.hpp and the release library,
# runs each normally and under ASan+UBSan (leak checking on); with OpenCV 4, builds and runs
# tests/cpp/test_opencv.cpp against include/topoloc_opencv.hpp; checks that topoloc.hpp and
# include/topoloc/*.hpp do not depend on include order and that each C++ header compiles alone;
# and compiles and runs the C++ examples so that they cannot rot.
#
#   TOPOLOC_TARGET_DIR   directory holding libtopoloc.so (default: <repo>/target/release;
#                        build it with `cargo build --release --lib`)
#   CXX                  C++ compiler (default: g++)
#
# Output goes to <repo>/build/cpp-tests.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$repo/scripts/lib.sh"
out="$repo/build/cpp-tests"
cxx="${CXX:-g++}"

# The library's SONAME (libtopoloc.so.MAJOR, or .so.0.MINOR before 1.0; see build.rs) is a name
# cargo does not create next to it: give the loader that name in a private directory, and point
# the binaries' rpath there.
libdir="$out/lib"
library="$(release_library_dir "$repo")/libtopoloc.so"
link_library_dir "$library" "$(library_soname "$library")" "$libdir"

cxxflags=(-std=c++17 -Wall -Wextra -Werror -pedantic -g -I"$repo/include")
# (The commas belong to the compiler flags.)
# shellcheck disable=SC2054
ldflags=(-L"$libdir" -ltopoloc -Wl,-rpath,"$libdir")
# shellcheck disable=SC2054
sanitize=(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all)


# OpenCV's headers are included as system headers, so -Werror judges only our code.
opencv_cflags=() opencv_libs=()
if pkg-config --exists opencv4 2>/dev/null; then
    read -r -a opencv_cflags <<<"$(pkg-config --cflags opencv4 | sed 's/\(^\| \)-I/\1-isystem /g')"
    read -r -a opencv_libs <<<"$(pkg-config --libs opencv4)"
fi

# topoloc.hpp and the headers it includes (include/topoloc/) must mean the same in every
# translation unit, whatever was included before them: nothing in them may test for OpenCV (or
# anything else a host may or may not have included). Their one conditional is the include guard.
section "topoloc.hpp and include/topoloc/*.hpp do not depend on include order"
for header in "$repo/include/topoloc.hpp" "$repo/include/topoloc/"*.hpp; do
    # (Code lines only: comments may mention OpenCV.)
    if sed -e 's://.*$::' -e 's:^ *\*.*$::' -e 's:/\*.*$::' "$header" |
        grep -nE '__has_include|CV_VERSION|cv::|opencv|^ *# *if(n?def)? ' |
        grep -vE ':#ifndef TOPOLOC_[A-Z_]*HPP$'; then
        echo "${header#"$repo/"} has the conditional or OpenCV code above; it belongs in topoloc_opencv.hpp" >&2
        exit 1
    fi
done
echo "ok"

# Each header first in its translation unit, as a host includes it: the umbrella topoloc.hpp
# (also by its old quoted name), and every concept header of include/topoloc/ on its own.
section "each C++ header compiles alone"
printf '#include "topoloc.hpp"\nint main() { return topoloc::abi_matches() ? 0 : 1; }\n' \
    >"$out/hpp_alone.cpp"
"$cxx" "${cxxflags[@]}" -fsyntax-only "$out/hpp_alone.cpp"
# By path and without -I (as `#include "../include/topoloc.hpp"` does): the headers find
# topoloc.h and each other relative to themselves.
printf '#include "%s"\nint main() { return topoloc::abi_matches() ? 0 : 1; }\n' \
    "$repo/include/topoloc.hpp" >"$out/hpp_by_path.cpp"
"$cxx" -std=c++17 -Wall -Wextra -Werror -pedantic -fsyntax-only "$out/hpp_by_path.cpp"
nheaders=0
for header in "$repo/include/topoloc/"*.hpp; do
    name="$(basename "$header" .hpp)"
    printf '#include <topoloc/%s.hpp>\nint main() { return 0; }\n' "$name" >"$out/hpp_alone_$name.cpp"
    "$cxx" "${cxxflags[@]}" -fsyntax-only "$out/hpp_alone_$name.cpp"
    nheaders=$((nheaders + 1))
done
if ((nheaders < 6)); then
    echo "found only $nheaders headers in include/topoloc/" >&2
    exit 1
fi
if ((${#opencv_cflags[@]})); then
    printf '#include "topoloc_opencv.hpp"\nint main() { return topoloc::abi_matches() ? 0 : 1; }\n' \
        >"$out/opencv_hpp_alone.cpp"
    "$cxx" "${cxxflags[@]}" "${opencv_cflags[@]}" -fsyntax-only "$out/opencv_hpp_alone.cpp"
fi
echo "ok"

for test in test_raii test_status test_loops test_loop_images test_pose_fix test_trajectory; do
    section "compile $test (plain)"
    "$cxx" "${cxxflags[@]}" -O1 "$here/$test.cpp" -o "$out/$test" "${ldflags[@]}"

    section "compile $test (ASan+UBSan)"
    "$cxx" "${cxxflags[@]}" -O1 "${sanitize[@]}" "$here/$test.cpp" -o "$out/${test}_asan" \
        "${ldflags[@]}"

    section "run $test (plain)"
    "$out/$test"

    # No LSan suppression file is needed: with this library LeakSanitizer reports nothing from
    # the Rust runtime (its one-time allocations, e.g. the per-thread error message, are freed at
    # thread exit or still reachable), so any leak it reports is a real one.
    section "run $test (ASan+UBSan, leak check)"
    ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:halt_on_error=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}" \
    UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}" \
        "$out/${test}_asan"
done

if ((${#opencv_cflags[@]})); then
    section "compile and run test_opencv (topoloc_opencv.hpp, ASan+UBSan)"
    "$cxx" "${cxxflags[@]}" -O1 "${sanitize[@]}" "${opencv_cflags[@]}" "$here/test_opencv.cpp" \
        -o "$out/test_opencv" "${ldflags[@]}" "${opencv_libs[@]}"
    ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:halt_on_error=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}" \
    UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}" \
        "$out/test_opencv"
else
    section "OpenCV (opencv4) not found: topoloc_opencv.hpp not tested"
fi

section "compile and run cpp-examples/localize_stream"
"$cxx" "${cxxflags[@]}" -O2 "$repo/cpp-examples/localize_stream.cpp" \
    -o "$out/localize_stream" "${ldflags[@]}"
"$out/localize_stream" >"$out/localize_stream.log"
tail -n 3 "$out/localize_stream.log"
# Its error path: a missing map file must end in a clean error, not a crash.
if "$out/localize_stream" "$out/no-such-map.topoloc" 2>"$out/localize_stream.err"; then
    echo "localize_stream accepted a missing map file" >&2
    exit 1
fi
grep -q "topoloc error 100" "$out/localize_stream.err"

section "C++ layer: all passed"
