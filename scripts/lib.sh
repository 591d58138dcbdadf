# shellcheck shell=bash
# Helpers shared by topoloc's shell scripts; sourced, not run:
#   source "$root/scripts/lib.sh"
# Used by scripts/install-deps.sh, scripts/setup-models.sh and the test runners tests/c/run.sh,
# tests/cpp/run.sh and tests/consumer/run.sh.

# section TEXT: a heading in a test runner's log.
section() { printf '\n==> %s\n' "$*"; }

# fail TEXT: reports a failed check and exits with status 1.
fail() {
    printf 'FAILED: %s\n' "$*" >&2
    exit 1
}

# apt_install_missing WHO PACKAGE...: installs those of the Debian packages that are not
# installed yet (apt-get update only then; through sudo unless root). WHO names the calling
# script in the message. Does nothing when every package is installed.
apt_install_missing() {
    local who="$1" p
    shift
    local to_install=()
    for p in "$@"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || to_install+=("$p")
    done
    if ((${#to_install[@]} == 0)); then
        return 0
    fi
    echo "$who: apt-get install ${to_install[*]}"
    local sudo=()
    [[ "$(id -u)" -eq 0 ]] || sudo=(sudo)
    "${sudo[@]}" apt-get update -qq
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${to_install[@]}" >/dev/null
}

# soname_of_version MAJOR MINOR: the SONAME of libtopoloc of that version, the rule of build.rs:
# libtopoloc.so.MAJOR, or libtopoloc.so.0.MINOR before 1.0.
soname_of_version() {
    if [[ "$1" == 0 ]]; then
        echo "libtopoloc.so.0.$2"
    else
        echo "libtopoloc.so.$1"
    fi
}

# library_soname FILE: the SONAME a shared library records ("" when none).
library_soname() {
    readelf -d "$1" | sed -n 's/.*(SONAME).*\[\(.*\)\]$/\1/p'
}

# link_library_dir LIBRARY SONAME DIR: gives test programs linked with
# `-L DIR -ltopoloc -Wl,-rpath,DIR` the installed layout of the shared LIBRARY: DIR/SONAME ->
# LIBRARY (the name the dynamic loader asks for, which cargo does not create) and
# DIR/libtopoloc.so -> SONAME. Creates DIR; fails when SONAME is empty.
link_library_dir() {
    local library="$1" soname="$2" dir="$3"
    [[ -n "$soname" ]] || fail "$library has no SONAME (build.rs sets one)"
    mkdir -p "$dir"
    ln -sfn "$library" "$dir/$soname"
    ln -sfn "$soname" "$dir/libtopoloc.so"
}

# release_library_dir REPO: prints the absolute directory holding the release library
# libtopoloc.so ($TOPOLOC_TARGET_DIR, default REPO/target/release); fails, naming the cargo
# command that builds it, when the library is not there.
release_library_dir() {
    local dir="${TOPOLOC_TARGET_DIR:-$1/target/release}"
    [[ -f "$dir/libtopoloc.so" ]] ||
        fail "$dir/libtopoloc.so not found; build it first: cargo build --release --lib"
    (cd "$dir" && pwd)
}
