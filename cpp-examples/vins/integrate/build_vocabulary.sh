#!/usr/bin/env bash
# Compiles train_brief_vocabulary.cpp (beside this script) together with an unmodified
# VINS-Fusion checkout's DBoW2, DVision and VocabularyBinary sources, then trains a BRIEF
# vocabulary in loop_fusion's binary format (k 10, L 6, TF-IDF, L1: what stock loop_fusion loads
# as support_files/brief_k10L6.bin, which our mirror lacks). VINS-Fusion is GPL-3.0: its sources
# are compiled from the checkout; nothing of it enters topoloc's repository.
#
#   cpp-examples/vins/integrate/build_vocabulary.sh UPSTREAM IMAGES_DIR... OUT.bin
#
# UPSTREAM    a VINS-Fusion checkout (read only): loop_fusion/src/ThirdParty and the BRIEF
#             pattern support_files/brief_pattern.yml
# IMAGES_DIR  folders of training images (their .png .jpg .jpeg .pgm .bmp .tif .tiff files,
#             in name order)
# OUT.bin     the vocabulary to write; read back and checked by the trainer
#
# Environment:
# WORK_DIR    where the trainer is built (WORK_DIR/train_brief_vocabulary, kept and rebuilt only
#             when this script or the .cpp is newer); default a temporary directory, removed
#             at exit
# SEED        the k-means++ seed (default 1): the same seed and images give the same file
#
# Needs g++, pkg-config, OpenCV 4 and Boost headers (scripts/install-deps.sh). The compiler
# force-includes opencv2/imgproc/types_c.h: DVision/BRIEF.cpp (line 53) uses the OpenCV C
# constant CV_RGB2GRAY, which OpenCV 4 declares only there.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$ROOT/scripts/lib.sh"

usage() {
    sed -n '2,24p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit "${1:-0}"
}

# build_trainer UPSTREAM BINARY: compiles the trainer with UPSTREAM's sources into BINARY,
# unless BINARY is newer than the trainer's source and this script.
build_trainer() {
    local third_party="$1/loop_fusion/src/ThirdParty" binary="$2"
    local source="$HERE/train_brief_vocabulary.cpp"
    if [[ -x "$binary" && "$binary" -nt "$source" && "$binary" -nt "${BASH_SOURCE[0]}" ]]; then
        echo "build_vocabulary: $binary is up to date"
        return 0
    fi
    [[ -f "$third_party/VocabularyBinary.cpp" ]] || fail "$1 is not a VINS-Fusion checkout"
    local cflags libs
    cflags="$(pkg-config --cflags opencv4)" || fail "pkg-config finds no opencv4"
    libs="$(pkg-config --libs opencv4)"
    echo "build_vocabulary: compiling $binary"
    # shellcheck disable=SC2086 # pkg-config's flags are words
    g++ -std=c++17 -O2 -I"$third_party" $cflags -include opencv2/imgproc/types_c.h \
        "$source" \
        "$third_party"/DBoW/{BowVector,FBrief,FeatureVector,ScoringObject}.cpp \
        "$third_party"/DUtils/{Random,Timestamp}.cpp \
        "$third_party"/DVision/BRIEF.cpp \
        "$third_party"/VocabularyBinary.cpp \
        $libs -o "$binary"
}

# train_vocabulary UPSTREAM BINARY OUT.bin IMAGES_DIR...: trains with UPSTREAM's BRIEF pattern.
train_vocabulary() {
    local upstream="$1" binary="$2" out="$3"
    shift 3
    "$binary" --seed "${SEED:-1}" "$upstream/support_files/brief_pattern.yml" "$out" "$@"
}

main() {
    case "${1:-}" in -h | --help) usage 0 ;; esac
    [[ $# -ge 3 ]] || usage 1
    local upstream="$1" out="${!#}"
    local dirs=("${@:2:$#-2}") dir
    [[ -d "$upstream" ]] || fail "no directory $upstream"
    for dir in "${dirs[@]}"; do
        [[ -d "$dir" ]] || fail "no image directory $dir"
    done
    [[ ! -d "$out" ]] || fail "OUT.bin $out is a directory"
    mkdir -p "$(dirname "$out")"

    local work="${WORK_DIR:-}"
    if [[ -z "$work" ]]; then
        work="$(mktemp -d)"
        # shellcheck disable=SC2064 # expand now: $work is local
        trap "rm -rf '$work'" EXIT
    fi
    mkdir -p "$work"
    build_trainer "$upstream" "$work/train_brief_vocabulary"
    train_vocabulary "$upstream" "$work/train_brief_vocabulary" "$out" "${dirs[@]}"
}

main "$@"
