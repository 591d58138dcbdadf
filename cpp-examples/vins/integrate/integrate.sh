#!/usr/bin/env bash
# Builds VINS-Fusion's loop_fusion with topoloc's loop detector, and the same tree stock for the
# baseline, from an upstream checkout this script never modifies (VINS-Fusion is GPL-3.0:
# nothing of it enters topoloc's repository).
#
#   cpp-examples/vins/integrate/integrate.sh VINS_FUSION_DIR WORK_DIR [--variants "stock topoloc"]
#
# VINS_FUSION_DIR  a checkout of github.com/HKUST-Aerial-Robotics/VINS-Fusion (master be55a93;
#                  support_files/brief_k10L6.bin is not needed: run.sh trains one), or its git
#                  directory without a work tree (a bare clone, or the snapshot `fetch` brings):
#                  its HEAD is laid out into WORK_DIR/upstream/vins-fusion, skipping missing blobs
# WORK_DIR         gets topoloc-install/ (topoloc installed with CMake from this checkout), the
#                  topoloc CLI that run.sh calls (<checkout>/target/release/topoloc) and one
#                  catkin workspace per variant, built: WORK_DIR/<variant>-ws/src (the tree of
#                  apply.py), WORK_DIR/<variant>-ws/devel/lib/loop_fusion/loop_fusion_node;
#                  and WORK_DIR/train_brief_vocabulary (the stock vocabulary's trainer)
# --variants       which trees to build (default both)
#
# The recipe, measured on Debian 12 (2 cores: about 5 minutes per variant):
# - Debian's ROS 1 packages: roscpp, roslib, cv_bridge, the message packages, catkin, rosmaster,
#   rospy (installed here when missing); Ceres 2.1 and OpenCV 4.6 from scripts/install-deps.sh;
# - catkin_make with only camera_models and loop_fusion (vins_estimator is not built: the
#   benchmark's driver.py publishes what it would), /usr/bin/python3 first on PATH (catkin's
#   Python modules are Debian's), C++17;
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
    sed -n '2,26p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit "${1:-0}"
}

[[ $# -ge 2 ]] || usage 2
VINS_DIR="$(cd "$1" && pwd)" WORK_DIR="$2"
shift 2
VARIANTS="stock topoloc"
while [[ $# -gt 0 ]]; do
    case "$1" in
        --variants)
            [[ $# -ge 2 ]] || fail "--variants needs a list"
            VARIANTS="$2"
            shift 2
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
VINS_DIR="$(upstream_tree "$VINS_DIR" vins-fusion "$WORK_DIR")"
[[ -f "$VINS_DIR/loop_fusion/src/pose_graph.cpp" ]] || fail "$VINS_DIR is not a VINS-Fusion checkout"
JOBS="$(nproc)"

apt_install_missing vins-integrate build-essential cmake pkg-config libopencv-dev libeigen3-dev \
    libceres-dev libboost-dev catkin python3-catkin-pkg python3-genmsg libroscpp-dev libroslib-dev \
    libcv-bridge-dev libstd-msgs-dev libnav-msgs-dev libgeometry-msgs-dev libsensor-msgs-dev \
    libvisualization-msgs-dev python3-rosmaster python3-rospy python3-opencv python3-numpy \
    python3-nav-msgs python3-sensor-msgs python3-geometry-msgs

if [[ " $VARIANTS " == *" topoloc "* ]]; then
    install_topoloc "$ROOT" "$WORK_DIR"
fi
build_topoloc_cli "$ROOT"

for variant in $VARIANTS; do
    ws="$WORK_DIR/$variant-ws"
    section "loop_fusion $variant in $ws"
    python3 "$HERE/apply.py" "$VINS_DIR" "$ws/src" --variant "$variant"
    log="$WORK_DIR/loop_fusion-$variant-build.log"
    (cd "$ws" && PATH="/usr/bin:$PATH" catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 \
        -DCMAKE_BUILD_TYPE=Release -DCATKIN_WHITELIST_PACKAGES='camera_models;loop_fusion' \
        -DTopoloc_DIR="$WORK_DIR/topoloc-install/lib/cmake/Topoloc" -j"$JOBS") >"$log" 2>&1 ||
        fail "loop_fusion $variant build failed (see $log)"
    echo "ok: $ws/devel/lib/loop_fusion/loop_fusion_node"
done
