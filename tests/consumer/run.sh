#!/usr/bin/env bash
# Installs topoloc with CMake into a temporary prefix and builds a separate consumer project
# against it with find_package(Topoloc): C (shared and static), C++ (when topoloc.hpp and the
# topoloc/ headers it includes are installed) and C++ with OpenCV (when topoloc_opencv.hpp is
# installed and OpenCV is found);
# then cpp-examples (the SLAM adapters, their tests and demos), shared and static.
# Also checks the installed layout, the SONAME, pkg-config, and that the installed tree still
# works after being moved elsewhere.
#
#   bash tests/consumer/run.sh
#
# Environment:
#   TOPOLOC_CARGO_TARGET_DIR    cargo target dir handed to CMake (default: <repo>/target, so an
#                               existing cargo build is reused)
#   TOPOLOC_CONSUMER_BUILD_DIR  scratch dir (default: <repo>/build/consumer-test; recreated)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$repo/scripts/lib.sh"
cargo_target="${TOPOLOC_CARGO_TARGET_DIR:-$repo/target}"
work="${TOPOLOC_CONSUMER_BUILD_DIR:-$repo/build/consumer-test}"
prefix="$work/install"
generator_args=()
if command -v ninja >/dev/null 2>&1; then
    generator_args=(-G Ninja)
fi

version="$(sed -n '/^\[package\]/,/^\[/ s/^version *= *"\([0-9.]*\)".*/\1/p' "$repo/Cargo.toml" | head -n1)"
[[ -n "$version" ]] || fail "no [package] version in Cargo.toml"
major="${version%%.*}"
minor="${version#*.}"; minor="${minor%%.*}"
expected_soname="$(soname_of_version "$major" "$minor")"
echo "topoloc $version; cargo target dir: $cargo_target; scratch dir: $work"

rm -rf "$work"
mkdir -p "$work"

section "configure, build (cargo) and install topoloc into $prefix"
cmake -S "$repo" -B "$work/topoloc-build" "${generator_args[@]}" \
    -DCMAKE_INSTALL_PREFIX="$prefix" \
    -DTOPOLOC_CARGO_TARGET_DIR="$cargo_target" \
    -DTOPOLOC_ENABLE_TESTS=OFF
cmake --build "$work/topoloc-build"
cmake --install "$work/topoloc-build"

section "the default cargo target dir of an out-of-tree build (configure only)"
# Without -DTOPOLOC_CARGO_TARGET_DIR cargo must write under the build dir, or into
# $CARGO_TARGET_DIR when set: never into the source tree.
cached_target() {
    sed -n 's/^TOPOLOC_CARGO_TARGET_DIR:PATH=//p' "$1/CMakeCache.txt"
}
env -u CARGO_TARGET_DIR cmake -S "$repo" -B "$work/default-build" "${generator_args[@]}" \
    -DTOPOLOC_ENABLE_TESTS=OFF >/dev/null
[[ "$(cached_target "$work/default-build")" == "$work/default-build/cargo-target" ]] ||
    fail "default cargo target dir is $(cached_target "$work/default-build"), expected $work/default-build/cargo-target"
CARGO_TARGET_DIR="$work/elsewhere" cmake -S "$repo" -B "$work/env-build" "${generator_args[@]}" \
    -DTOPOLOC_ENABLE_TESTS=OFF >/dev/null
[[ "$(cached_target "$work/env-build")" == "$work/elsewhere" ]] ||
    fail "with CARGO_TARGET_DIR the cargo target dir is $(cached_target "$work/env-build"), expected $work/elsewhere"
rm -rf "$work/default-build" "$work/env-build"
echo "ok: <build>/cargo-target by default, \$CARGO_TARGET_DIR when set"

libdir_rel="$(sed -n 's/^CMAKE_INSTALL_LIBDIR:PATH=//p' "$work/topoloc-build/CMakeCache.txt")"
includedir_rel="$(sed -n 's/^CMAKE_INSTALL_INCLUDEDIR:PATH=//p' "$work/topoloc-build/CMakeCache.txt")"
libdir="$prefix/${libdir_rel:-lib}"
includedir="$prefix/${includedir_rel:-include}"

section "installed layout"
( cd "$prefix" && find . \( -type f -o -type l \) | sort | sed 's/^/  /' )
real="$libdir/libtopoloc.so.$version"
[[ -f "$real" && ! -L "$real" ]] || fail "$real is missing or not a regular file"
[[ -L "$libdir/$expected_soname" ]] || fail "$expected_soname is not a symbolic link"
[[ "$(readlink "$libdir/$expected_soname")" == "libtopoloc.so.$version" ]] ||
    fail "$expected_soname -> $(readlink "$libdir/$expected_soname"), expected libtopoloc.so.$version"
[[ -L "$libdir/libtopoloc.so" ]] || fail "libtopoloc.so is not a symbolic link"
[[ "$(readlink "$libdir/libtopoloc.so")" == "$expected_soname" ]] ||
    fail "libtopoloc.so -> $(readlink "$libdir/libtopoloc.so"), expected $expected_soname"
[[ "$(readlink -f "$libdir/libtopoloc.so")" == "$(readlink -f "$real")" ]] || fail "symlink chain is broken"
[[ -x "$real" ]] || fail "$real is not executable (shared libraries are installed 0755)"
for f in "$libdir/libtopoloc.a" "$includedir/topoloc.h" \
    "$libdir/cmake/Topoloc/TopolocConfig.cmake" "$libdir/cmake/Topoloc/TopolocConfigVersion.cmake" \
    "$libdir/pkgconfig/topoloc.pc"; do
    [[ -f "$f" ]] || fail "$f is missing"
done
for hpp in topoloc.hpp topoloc_opencv.hpp; do
    if [[ -f "$repo/include/$hpp" ]]; then
        cmp -s "$repo/include/$hpp" "$includedir/$hpp" || fail "$hpp not installed"
    else
        echo "note: include/$hpp does not exist in the source tree; not installed"
    fi
done
if [[ -d "$repo/include/topoloc" ]]; then
    # The concept headers topoloc.hpp includes: each installed unchanged, and nothing else.
    diff -r "$repo/include/topoloc" "$includedir/topoloc" || fail "include/topoloc/ not installed as it is"
fi
cmp -s "$repo/include/topoloc.h" "$includedir/topoloc.h" || fail "installed topoloc.h differs"
# Relocatable: no absolute path of the prefix or the source/build trees in the package files.
if grep -rlF -e "$prefix" -e "$repo" "$libdir/cmake/Topoloc" "$libdir/pkgconfig"; then
    fail "the files above contain absolute paths: the install would not be relocatable"
fi
echo "ok"

section "SONAME"
soname="$(library_soname "$real")"
echo "SONAME of libtopoloc.so.$version: ${soname:-<none>}"
[[ "$soname" == "$expected_soname" ]] || fail "SONAME is '$soname', expected $expected_soname"

section "pkg-config"
export PKG_CONFIG_PATH="$libdir/pkgconfig"
pc_flags="$(pkg-config --cflags --libs topoloc)"
echo "pkg-config --cflags --libs topoloc: $pc_flags"
echo "pkg-config --static --libs topoloc: $(pkg-config --static --libs topoloc)"
[[ "$(pkg-config --modversion topoloc)" == "$version" ]] || fail "pkg-config --modversion is not $version"
[[ "$(readlink -f "$(pkg-config --variable=includedir topoloc)")" == "$(readlink -f "$includedir")" ]] ||
    fail "pkg-config includedir does not point at $includedir"
[[ "$(readlink -f "$(pkg-config --variable=libdir topoloc)")" == "$(readlink -f "$libdir")" ]] ||
    fail "pkg-config libdir does not point at $libdir"
for lib in -lgcc_s -lutil -lrt -lpthread -lm -ldl; do
    [[ " $(pkg-config --static --libs topoloc) " == *" $lib "* ]] || fail "pkg-config --static lacks $lib"
done
# Build and run the consumer with nothing but pkg-config's flags (plus an rpath).
# shellcheck disable=SC2046
cc -std=c11 -Wall -Wextra -Werror -pedantic $(pkg-config --cflags topoloc) "$here/main.c" \
    -o "$work/consumer_pkgconfig" $(pkg-config --libs topoloc) -Wl,-rpath,"$libdir"
"$work/consumer_pkgconfig"
# Each installed C++ header first in a translation unit, with nothing but pkg-config's flags:
# topoloc.hpp and every header of topoloc/ alone (`#include <topoloc/map.hpp>`).
for header in "$includedir/topoloc.hpp" "$includedir/topoloc/"*.hpp; do
    [[ -f "$header" ]] || continue
    printf '#include <%s>\nint main() { return 0; }\n' "${header#"$includedir/"}" >"$work/header_alone.cpp"
    # shellcheck disable=SC2046
    c++ -std=c++17 -Wall -Wextra -Werror -pedantic $(pkg-config --cflags topoloc) -fsyntax-only \
        "$work/header_alone.cpp" || fail "${header#"$includedir/"} does not compile alone"
done

# Configures, builds and runs the consumer project against an installed prefix.
build_consumer() {
    local against="$1" build="$2"
    cmake -S "$here" -B "$build" "${generator_args[@]}" -DCMAKE_PREFIX_PATH="$against"
    cmake --build "$build"
    ( cd "$build" && ctest --output-on-failure )
    if readelf -d "$build/consumer_c_static" | grep -q 'libtopoloc'; then
        fail "consumer_c_static depends on a shared libtopoloc"
    fi
    readelf -d "$build/consumer_c" | grep -q "NEEDED.*\[$expected_soname\]" ||
        fail "consumer_c does not record NEEDED $expected_soname"
}

section "consumer project: find_package(Topoloc) from $prefix"
build_consumer "$prefix" "$work/consumer-build"
if [[ ! -f "$includedir/topoloc.hpp" ]]; then
    echo "note: consumer_cpp not built (topoloc.hpp is not installed)"
fi

# The C++ examples (VINS and ORB-SLAM adapters, their tests and drift demos) as a host builds
# them: a separate project against the installed package, linked shared and static.
build_examples() {
    local link="$1" build="$work/examples-$1"
    cmake -S "$repo/cpp-examples" -B "$build" "${generator_args[@]}" \
        -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTOPOLOC_EXAMPLES_LINK="$link"
    cmake --build "$build"
    ( cd "$build" && ctest --output-on-failure )
    if [[ "$link" == static ]] && readelf -d "$build/vins_drift_demo" | grep -q 'libtopoloc'; then
        fail "the static vins_drift_demo depends on a shared libtopoloc"
    fi
}
section "cpp-examples against $prefix: shared"
build_examples shared
section "drift-correction demos (valgrind included)"
bash "$repo/tests/slam/run.sh" "$work/examples-shared"
section "cpp-examples against $prefix: static"
build_examples static

section "consumer project against the install moved elsewhere (relocatable package)"
mv "$prefix" "$work/moved-install"
build_consumer "$work/moved-install" "$work/consumer-build-moved"

section "all consumer checks passed"
