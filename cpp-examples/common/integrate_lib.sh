# shellcheck shell=bash
# Shell functions shared by the integration scripts (orbslam/integrate/integrate.sh,
# vins/integrate/integrate.sh). Source after scripts/lib.sh.

# install_topoloc ROOT WORK_DIR: builds topoloc from the checkout ROOT (cargo target dir
# ROOT/target) and installs it with CMake into WORK_DIR/topoloc-install, for the upstream
# trees' find_package(Topoloc); the log is WORK_DIR/topoloc-build.log.
install_topoloc() {
    local root="$1" work="$2"
    section "topoloc (this checkout) into $work/topoloc-install"
    cmake -S "$root" -B "$work/topoloc-build" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_INSTALL_PREFIX="$work/topoloc-install" -DTOPOLOC_CARGO_TARGET_DIR="$root/target" \
        -DTOPOLOC_ENABLE_TESTS=OFF >"$work/topoloc-build.log" 2>&1 ||
        fail "topoloc configure failed (see $work/topoloc-build.log)"
    cmake --build "$work/topoloc-build" >>"$work/topoloc-build.log" 2>&1 ||
        fail "topoloc build failed (see $work/topoloc-build.log)"
    cmake --install "$work/topoloc-build" >>"$work/topoloc-build.log" 2>&1
    echo "ok"
}
