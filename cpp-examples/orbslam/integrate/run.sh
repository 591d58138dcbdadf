#!/usr/bin/env bash
# Runs the ORB-SLAM3 trees of integrate.sh on real sequences, stock against topoloc, and writes
# the table of judge.py.
#
#   cpp-examples/orbslam/integrate/run.sh WORK_DIR KITTI_SEQ TUM_SEQ GARDENS_POINT OUT_DIR [--runs "..."]
#
# WORK_DIR       integrate.sh's WORK_DIR (both variants built)
# KITTI_SEQ      KITTI 00 laid out by shared/data/real-seq/prepare.py (image_0/, times.txt,
#                groundtruth_tum.txt; frames 0-1699)
# TUM_SEQ        TUM fr1_xyz laid out by prepare.py (rgb/, depth/, associations.txt,
#                groundtruth.txt)
# GARDENS_POINT  shared/data/gardens-point: its 400 day images (day_left, day_right) train the
#                ORB vocabulary both variants track with (ORBvoc.txt is not obtainable here), and
#                day_left is the topoloc map's images (its describer: MobileNetV2 by default)
# OUT_DIR        gets the vocabulary, the map, the settings files, one folder per run (the
#                host's log, its trajectories, /usr/bin/time's report) and table.md / judged.json
# --runs         which runs, of kitti-stock kitti-noloop kitti-topoloc tum-stock tum-noloop
#                tum-topoloc (default all); noloop is stock with `loopClosing: 0`
# --tag T        run folders are named RUN-T (repeated runs: ORB-SLAM3's threads make each run
#                differ)
#
# The runs go one after another (ORB-SLAM3's examples pace themselves to the sequence's clock,
# so a run takes the sequence's duration at least: KITTI 00's 1,700 frames about 3 minutes).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$ROOT/scripts/lib.sh"

[[ $# -ge 5 ]] || {
    sed -n '2,23p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 2
}
WORK_DIR="$(cd "$1" && pwd)" KITTI="$(cd "$2" && pwd)" TUM="$(cd "$3" && pwd)" GP="$(cd "$4" && pwd)"
OUT="$5"
shift 5
RUNS="kitti-stock kitti-noloop kitti-topoloc tum-stock tum-noloop tum-topoloc"
TAG=""
while [[ $# -gt 0 ]]; do
    case "$1" in
        --runs)
            [[ $# -ge 2 ]] || fail "--runs needs a list"
            RUNS="$2"
            shift 2
            ;;
        --tag)
            [[ $# -ge 2 ]] || fail "--tag needs a name"
            TAG="-$2"
            shift 2
            ;;
        *) fail "unknown option '$1'" ;;
    esac
done
mkdir -p "$OUT"
OUT="$(cd "$OUT" && pwd)"
TOPOLOC="$ROOT/target/release/topoloc"
[[ -x "$TOPOLOC" ]] || fail "no topoloc CLI at $TOPOLOC (cargo build --release -p topoloc-cli)"
for f in times.txt groundtruth_tum.txt image_0; do
    [[ -e "$KITTI/$f" ]] || fail "$KITTI has no $f (lay it out with shared/data/real-seq/prepare.py)"
done
for f in associations.txt groundtruth.txt; do
    [[ -e "$TUM/$f" ]] || fail "$TUM has no $f (lay it out with shared/data/real-seq/prepare.py)"
done
[[ -x "$WORK_DIR/stock/train_vocabulary" ]] || fail "$WORK_DIR/stock is not built (run integrate.sh)"

VOC="$OUT/ORBvoc-gardens-point.txt"
if [[ ! -s "$VOC" ]]; then
    section "ORB vocabulary (k 10, L 6, 1000 ORB per image) from Gardens Point day_left + day_right"
    "$WORK_DIR/stock/train_vocabulary" "$VOC.tmp" 10 6 1000 "$GP/day_left" "$GP/day_right"
    mv "$VOC.tmp" "$VOC"
fi
MAP="$OUT/gardens-point.topoloc"
if [[ ! -s "$MAP" ]]; then
    section "topoloc map of Gardens Point day_left (default backend)"
    "$TOPOLOC" build-map --images "$GP/day_left" --out "$MAP"
fi

# settings SEQ VARIANT: writes OUT/SEQ-VARIANT.yaml from the stock example's settings.
settings() {
    local seq="$1" variant="$2" source
    case "$seq" in
        kitti) source="$WORK_DIR/stock/Examples/Monocular/KITTI00-02.yaml" ;;
        tum) source="$WORK_DIR/stock/Examples/RGB-D/TUM1.yaml" ;;
    esac
    local yaml="$OUT/$seq-$variant.yaml"
    cp "$source" "$yaml"
    {
        echo
        echo "# added by topoloc's cpp-examples/orbslam/integrate/run.sh"
        case "$variant" in
            noloop) echo "loopClosing: 0" ;;
            topoloc)
                echo "Topoloc.map: \"$MAP\""
                echo "Topoloc.trace: 1"
                [[ "$seq" == kitti ]] && echo "Topoloc.monocular: 1"
                ;;
        esac
    } >>"$yaml"
    echo "$yaml"
}

for run in $RUNS; do
    seq="${run%%-*}" variant="${run#*-}"
    tree="$WORK_DIR/stock"
    [[ "$variant" == topoloc ]] && tree="$WORK_DIR/topoloc"
    yaml="$(settings "$seq" "$variant")"
    dir="$OUT/$run$TAG"
    rm -rf "$dir"
    mkdir -p "$dir"
    section "$run$TAG"
    case "$seq" in
        kitti) command=("$tree/Examples/Monocular/mono_kitti" "$VOC" "$yaml" "$KITTI") ;;
        tum) command=("$tree/Examples/RGB-D/rgbd_tum" "$VOC" "$yaml" "$TUM" "$TUM/associations.txt") ;;
        *) fail "unknown run '$run'" ;;
    esac
    [[ -x "${command[0]}" ]] || fail "${command[0]} is not built (run integrate.sh)"
    # A tree built with integrate.sh --asan: ORB-SLAM3 leaks at exit by design, errors still abort.
    (cd "$dir" && ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=0}" /usr/bin/time -v -o time.txt "${command[@]}" >log.txt 2>err.txt) ||
        echo "$run: exit status $? (see $dir/err.txt)" | tee "$dir/failed.txt"
    grep -c "^\[topoloc-bench\] \(loop\|merge\)" "$dir/log.txt" || true
done

section "judged"
python3 "$HERE/judge.py" "$OUT" --kitti "$KITTI" --tum "$TUM" --topoloc "$TOPOLOC"
