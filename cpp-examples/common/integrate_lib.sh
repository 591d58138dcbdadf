# shellcheck shell=bash
# Shell functions shared by the integration scripts (orbslam/integrate/integrate.sh,
# vins/integrate/integrate.sh). Source after scripts/lib.sh.

INTEGRATE_LIB_DIR="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"

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

# upstream_tree SOURCE NAME WORK_DIR: prints the folder of an upstream tree to build from.
# SOURCE is either a checkout (printed as is) or a git directory without a work tree (a bare
# clone, or a snapshot `fetch` brought): its HEAD, or the commit in $UPSTREAM_REV when set, is
# then laid out into WORK_DIR/upstream/NAME by checkout_mirror.py, which skips the blobs the
# snapshot lacks (data files: `git archive` would stop at the first) and lists them in
# WORK_DIR/upstream/NAME/.checkout-missing. Messages go to stderr.
upstream_tree() {
    local source="$1" name="$2" work="$3"
    if [[ -f "$source/HEAD" && -d "$source/objects" && ! -e "$source/.git" ]]; then
        local out="$work/upstream/$name"
        echo "laying out ${UPSTREAM_REV:-HEAD} of the git directory $source into $out" >&2
        python3 "$INTEGRATE_LIB_DIR/checkout_mirror.py" "$source" "${UPSTREAM_REV:-HEAD}" "$out" >&2 ||
            fail "could not lay out $source (see above)"
        echo "$out"
    else
        echo "$source"
    fi
}

# build_topoloc_cli ROOT: builds the topoloc CLI the run scripts call
# (ROOT/target/release/topoloc); the log is appended to stderr only on a failure.
build_topoloc_cli() {
    local root="$1" log
    section "topoloc CLI ($root/target/release/topoloc)"
    log="$(mktemp)"
    (cd "$root" && cargo build --release -p topoloc-cli --target-dir "$root/target") >"$log" 2>&1 || {
        cat "$log" >&2
        rm -f "$log"
        fail "cargo build --release -p topoloc-cli failed"
    }
    rm -f "$log"
    echo "ok"
}
