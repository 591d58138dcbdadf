#!/usr/bin/env bash
# DBoW2 + DLoopDetector (ORB) on a KITTI sequence, keyframed as `topoloc loops` keeps them.
#
#   tools/dbow2/run.sh SRC_DIR SEQUENCE OUT_DIR [--keyframe-rate HZ] [--max-frames N]
#                      [--alpha A] [--sweep] [--sweep-alphas 0.0,0.1,...]
#
# SRC_DIR   the unpacked upstream sources, in subfolders DBoW2, DLib and DLoopDetector
#           (see README.md; they are never copied into this repository)
# SEQUENCE  a KITTI odometry sequence folder: image_0/*.png and times.txt
# OUT_DIR   gets dloop.csv (alpha A, default 0.3) and dloop.log; with --sweep also
#           dloop-alpha-A.csv for each alpha of the sweep (default 0.0,0.1,...,0.9)
#
# Builds under $DBOW2_BUILD_DIR (default ~/.cache/topoloc/dbow2-build), reusing what is there;
# trains the vocabulary once there (gp_orb_k10L6.yml.gz) on $DBOW2_TRAIN_DIRS (colon-separated,
# default: the Gardens Point day_left and day_right images). JOBS (default 2) caps make -j.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=tools/dbow2/common.sh
source "$HERE/common.sh"

[[ $# -ge 3 ]] || usage 15
SRC_DIR="$1" SEQUENCE="$2" OUT_DIR="$3"
shift 3
RUNNER_ARGS=()
ALPHA=0.3
SWEEP=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --keyframe-rate|--max-frames)
      [[ $# -ge 2 ]] || die "$1 needs a value"
      RUNNER_ARGS+=("$1" "$2"); shift 2 ;;
    --alpha)
      [[ $# -ge 2 ]] || die "--alpha needs a value"
      ALPHA="$2"; shift 2 ;;
    --sweep) SWEEP="0.0,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9"; shift ;;
    --sweep-alphas)
      [[ $# -ge 2 ]] || die "--sweep-alphas needs a comma-separated list"
      SWEEP="$2"; shift 2 ;;
    -h|--help) usage 15 ;;
    *) die "unknown option '$1' (see --help)" ;;
  esac
done

# Inputs, with clear messages.
[[ -d "$SRC_DIR" ]] || die "SRC_DIR '$SRC_DIR' is not a folder"
SRC_DIR="$(cd "$SRC_DIR" && pwd)"
for name in DLib DBoW2 DLoopDetector; do
  [[ -f "$SRC_DIR/$name/CMakeLists.txt" ]] || die "missing source folder $SRC_DIR/$name \
(no CMakeLists.txt there): unpack github:dorian3d/$name into it, see $HERE/README.md"
done
[[ -f "$SRC_DIR/DLoopDetector/include/DLoopDetector/TemplatedLoopDetector.h" ]] \
  || die "$SRC_DIR/DLoopDetector has no include/DLoopDetector/TemplatedLoopDetector.h"
[[ -d "$SEQUENCE/image_0" ]] || die "SEQUENCE '$SEQUENCE' has no image_0/ folder"
[[ -f "$SEQUENCE/times.txt" ]] || die "SEQUENCE '$SEQUENCE' has no times.txt"
mkdir -p "$OUT_DIR"

BUILD="${DBOW2_BUILD_DIR:-$HOME/.cache/topoloc/dbow2-build}"
PREFIX="$BUILD/install"
JOBS="${JOBS:-2}"
mkdir -p "$BUILD"

# Configure a CMake project in $BUILD/$2 from source $1, starting afresh when the build folder
# was made from another source folder.
configure() {
  local src="$1" dir="$BUILD/$2"
  shift 2
  if [[ -f "$dir/CMakeCache.txt" ]] \
    && ! grep -qx "CMAKE_HOME_DIRECTORY:INTERNAL=$src" "$dir/CMakeCache.txt"; then
    echo "run.sh: $dir was built from another source, rebuilding" >&2
    rm -rf "$dir"
  fi
  cmake -S "$src" -B "$dir" -DCMAKE_BUILD_TYPE=Release "$@" >"$dir.cmake.log" 2>&1 \
    || die "cmake failed for $src, see $dir.cmake.log"
}
build_install() {
  local dir="$BUILD/$1"
  make -C "$dir" -j"$JOBS" install >"$dir.make.log" 2>&1 \
    || die "build failed in $dir, see $dir.make.log"
}

echo "== build in $BUILD" >&2
configure "$SRC_DIR/DLib" DLib -DCMAKE_INSTALL_PREFIX="$PREFIX"
build_install DLib
configure "$SRC_DIR/DBoW2" DBoW2 -DCMAKE_INSTALL_PREFIX="$PREFIX" -DBUILD_Demo=OFF
build_install DBoW2
# DLoopDetector is header-only; its CMake finds DLib and DBoW2 in $PREFIX (so its
# ExternalProject download is never used) and installs the headers there.
configure "$SRC_DIR/DLoopDetector" DLoopDetector -DCMAKE_INSTALL_PREFIX="$PREFIX" \
  -DCMAKE_PREFIX_PATH="$PREFIX" -DBUILD_DemoBRIEF=OFF
if ! grep -q "DLib library found" "$BUILD/DLoopDetector.cmake.log" ||
  ! grep -q "DBoW2 library found" "$BUILD/DLoopDetector.cmake.log"; then
  die "DLoopDetector's CMake did not find DLib/DBoW2 in $PREFIX (it would download them)"
fi
build_install DLoopDetector
configure "$HERE" runner -DDBOW2_DEPS_PREFIX="$PREFIX"
make -C "$BUILD/runner" -j"$JOBS" >"$BUILD/runner.make.log" 2>&1 \
  || die "build of loop_runner/train_vocabulary failed, see $BUILD/runner.make.log"

VOC="$BUILD/gp_orb_k10L6.yml.gz"
if [[ ! -s "$VOC" ]]; then
  IFS=: read -r -a TRAIN_DIRS <<<"${DBOW2_TRAIN_DIRS:-/work/shared/data/gardens-point/day_left:/work/shared/data/gardens-point/day_right}"
  for d in "${TRAIN_DIRS[@]}"; do
    [[ -d "$d" ]] || die "vocabulary training folder '$d' is missing (set DBOW2_TRAIN_DIRS)"
  done
  echo "== training the vocabulary on ${TRAIN_DIRS[*]}" >&2
  "$BUILD/runner/train_vocabulary" "$BUILD/gp_orb_k10L6.tmp.yml.gz" "${TRAIN_DIRS[@]}" \
    2>&1 | tee "$BUILD/gp_orb_k10L6.log" >&2
  mv "$BUILD/gp_orb_k10L6.tmp.yml.gz" "$VOC"
fi

run() {  # run ALPHA OUT_CSV
  echo "== loop_runner alpha $1 -> $2" >&2
  "$BUILD/runner/loop_runner" --voc "$VOC" --sequence "$SEQUENCE" --out "$2" --alpha "$1" \
    "${RUNNER_ARGS[@]}" >"${2%.csv}.log" 2>&1 || { cat "${2%.csv}.log" >&2; die "loop_runner failed"; }
  grep -E '^(keyframes|loops_detected|median_ms) ' "${2%.csv}.log" >&2
}

run "$ALPHA" "$OUT_DIR/dloop.csv"
if [[ -n "$SWEEP" ]]; then
  IFS=, read -r -a ALPHAS <<<"$SWEEP"
  for a in "${ALPHAS[@]}"; do
    run "$a" "$OUT_DIR/dloop-alpha-$a.csv"
  done
fi
echo "run.sh: wrote $OUT_DIR/dloop.csv${SWEEP:+ and the alpha sweep}" >&2
