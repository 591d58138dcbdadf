#!/usr/bin/env bash
# Builds ORB-SLAM3 v1.0 with topoloc's keyframe database, and the same tree stock for the
# baseline, from upstream checkouts this script never modifies (ORB-SLAM3 is GPL-3.0: nothing
# of it enters topoloc's repository).
#
#   cpp-examples/orbslam/integrate/integrate.sh ORB_SLAM3_DIR PANGOLIN_DIR WORK_DIR [--variants "stock topoloc"]
#       [--orbslam-rev REV] [--pangolin-rev REV]
#
# ORB_SLAM3_DIR  a checkout of github.com/UZ-SLAMLab/ORB_SLAM3 at v1.0 (the vocabulary file
#                ORBvoc.txt is not needed: run.sh trains one), or its git directory without a
#                work tree (a bare clone, or the snapshot `fetch` brings): its HEAD
#                (--orbslam-rev REV another commit) is laid out into WORK_DIR/upstream/orbslam3,
#                skipping the blobs the snapshot lacks (the vocabulary tarball, IMU timestamps)
# PANGOLIN_DIR   a checkout of github.com/stevenlovegrove/Pangolin at v0.8 (Debian 12 has none),
#                or its git directory, laid out the same way (--pangolin-rev REV, default HEAD)
# WORK_DIR       gets pangolin/ (its install), topoloc-install/ (topoloc installed with CMake from this
#                checkout), the topoloc CLI that run.sh calls (<checkout>/target/release/topoloc),
#                and one ORB-SLAM3 tree per variant, built: WORK_DIR/<variant>/lib/
#                libORB_SLAM3.so, Examples/Monocular/mono_kitti, Examples/RGB-D/rgbd_tum,
#                and WORK_DIR/<variant>/train_vocabulary
# --variants     which trees to build (default both)
# --asan         the topoloc tree's KeyFrameDatabase.cc (C++17 in a C++14 build) under
#                AddressSanitizer, and ASan linked in (CMake rebuilds the whole tree, about 12
#                minutes; without --asan the next run goes back)
#
# The recipe, measured on Debian 12 (2 cores: about 1 minute for Pangolin, 15 per variant):
# - Debian packages: those of scripts/install-deps.sh plus libglew-dev, libepoxy-dev,
#   libboost-serialization-dev, libssl-dev (installed here when missing);
# - ORB-SLAM3 at -std=c++14 (Pangolin 0.8's headers need C++14; v1.0's LoopClosing.cc does not
#   compile as C++17), its DBoW2 and g2o with the same standard (g2o built with another one gives
#   "double free or corruption" on the first frame), topoloc's KeyFrameDatabase.cc at C++17;
# - the edits of apply.py (recipe, bench log lines, and for topoloc the integration).
# Reruns rebuild only what changed.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$ROOT/scripts/lib.sh"
# shellcheck source=cpp-examples/common/integrate_lib.sh
source "$ROOT/cpp-examples/common/integrate_lib.sh"

usage() {
    sed -n '2,33p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit "${1:-0}"
}

[[ $# -ge 3 ]] || usage 2
ORB_SLAM3_DIR="$(cd "$1" && pwd)" PANGOLIN_DIR="$(cd "$2" && pwd)" WORK_DIR="$3"
shift 3
VARIANTS="stock topoloc"
ASAN=OFF
ORBSLAM_REV=HEAD
PANGOLIN_REV=HEAD
while [[ $# -gt 0 ]]; do
    case "$1" in
        --orbslam-rev | --pangolin-rev)
            [[ $# -ge 2 ]] || fail "$1 needs a commit"
            if [[ "$1" == --orbslam-rev ]]; then ORBSLAM_REV="$2"; else PANGOLIN_REV="$2"; fi
            shift 2
            ;;
        --variants)
            [[ $# -ge 2 ]] || fail "--variants needs a list"
            VARIANTS="$2"
            shift 2
            ;;
        --asan)
            ASAN=ON
            shift
            ;;
        -h | --help) usage 0 ;;
        *) fail "unknown option '$1' (see --help)" ;;
    esac
done
for v in $VARIANTS; do
    [[ "$v" == stock || "$v" == topoloc ]] || fail "unknown variant '$v' (stock or topoloc)"
done
mkdir -p "$WORK_DIR"
WORK_DIR="$(cd "$WORK_DIR" && pwd)"
ORB_SLAM3_DIR="$(UPSTREAM_REV="$ORBSLAM_REV" upstream_tree "$ORB_SLAM3_DIR" orbslam3 "$WORK_DIR")"
PANGOLIN_DIR="$(UPSTREAM_REV="$PANGOLIN_REV" upstream_tree "$PANGOLIN_DIR" pangolin "$WORK_DIR")"
[[ -f "$PANGOLIN_DIR/components/pango_core/include/pangolin/pangolin.h" ]] ||
    fail "$PANGOLIN_DIR is not a Pangolin checkout (v0.8)"
JOBS="$(nproc)"

apt_install_missing orbslam3-integrate build-essential cmake pkg-config libopencv-dev libeigen3-dev \
    libglew-dev libepoxy-dev libboost-serialization-dev libssl-dev

section "Pangolin v0.8 into $WORK_DIR/pangolin"
# Its libraries find each other through their RPATH (the examples load libpango_display, which
# needs libpango_windowing and libpango_image).
pangolin_stamp="$WORK_DIR/pangolin/topoloc-integrate.stamp"
if [[ "$(cat "$pangolin_stamp" 2>/dev/null)" != "$PANGOLIN_DIR rpath" ]]; then
    cmake -S "$PANGOLIN_DIR" -B "$WORK_DIR/pangolin-build" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_INSTALL_PREFIX="$WORK_DIR/pangolin" -DCMAKE_INSTALL_RPATH="$WORK_DIR/pangolin/lib" \
        -DBUILD_EXAMPLES=OFF -DBUILD_TOOLS=OFF -DBUILD_PANGOLIN_PYTHON=OFF -DBUILD_TESTS=OFF \
        >"$WORK_DIR/pangolin-build.log" 2>&1 || fail "Pangolin configure failed (see $WORK_DIR/pangolin-build.log)"
    cmake --build "$WORK_DIR/pangolin-build" -j "$JOBS" >>"$WORK_DIR/pangolin-build.log" 2>&1 ||
        fail "Pangolin build failed (see $WORK_DIR/pangolin-build.log)"
    cmake --install "$WORK_DIR/pangolin-build" >>"$WORK_DIR/pangolin-build.log" 2>&1
    echo "$PANGOLIN_DIR rpath" >"$pangolin_stamp"
fi
echo "ok"

if [[ " $VARIANTS " == *" topoloc "* ]]; then
    install_topoloc "$ROOT" "$WORK_DIR"
fi
build_topoloc_cli "$ROOT"

for variant in $VARIANTS; do
    tree="$WORK_DIR/$variant"
    section "ORB-SLAM3 $variant in $tree"
    python3 "$HERE/apply.py" "$ORB_SLAM3_DIR" "$tree" --variant "$variant"
    log="$WORK_DIR/orbslam3-$variant-build.log"
    : >"$log"
    for third in DBoW2 g2o; do
        cmake -S "$tree/Thirdparty/$third" -B "$tree/Thirdparty/$third/build" -DCMAKE_BUILD_TYPE=Release \
            -DCMAKE_CXX_STANDARD=14 >>"$log" 2>&1 || fail "$third configure failed (see $log)"
        cmake --build "$tree/Thirdparty/$third/build" -j "$JOBS" >>"$log" 2>&1 || fail "$third build failed (see $log)"
    done
    cmake -S "$tree" -B "$tree/build" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_PREFIX_PATH="$WORK_DIR/pangolin;$WORK_DIR/topoloc-install" \
        -DTOPOLOC_ORBSLAM_DIR="$ROOT/cpp-examples/orbslam" -DTOPOLOC_ORBSLAM_ASAN="$ASAN" >>"$log" 2>&1 ||
        fail "ORB-SLAM3 $variant configure failed (see $log)"
    cmake --build "$tree/build" -j "$JOBS" --target ORB_SLAM3 mono_kitti rgbd_tum >>"$log" 2>&1 ||
        fail "ORB-SLAM3 $variant build failed (see $log)"
    # The vocabulary trainer (topoloc's, against this tree's ORBextractor and DBoW2).
    # shellcheck disable=SC2046 # pkg-config's flags are words
    g++ -std=c++14 -O2 -I"$tree" -I"$tree/include" -I"$tree/include/CameraModels" -I"$tree/Thirdparty/Sophus" \
        $(pkg-config --cflags opencv4 eigen3) "$HERE/train_vocabulary.cpp" \
        -L"$tree/lib" -lORB_SLAM3 -Wl,--disable-new-dtags -Wl,-rpath,"$tree/lib" "$tree/Thirdparty/DBoW2/lib/libDBoW2.so" \
        -Wl,-rpath,"$tree/Thirdparty/DBoW2/lib:$tree/Thirdparty/g2o/lib:$WORK_DIR/pangolin/lib" \
        $(pkg-config --libs opencv4) -o "$tree/train_vocabulary" >>"$log" 2>&1 ||
        fail "train_vocabulary failed to build (see $log)"
    echo "ok: $tree/lib/libORB_SLAM3.so, mono_kitti, rgbd_tum, train_vocabulary"
done
