#!/usr/bin/env bash
# topoloc and DBoW2 + DLoopDetector side by side on the same KITTI keyframes, in one run.
#
#   tools/dbow2/compare.sh SRC_DIR SEQUENCE OUT_DIR [--topoloc BIN] [--rates "3 all"]
#
# SRC_DIR   the unpacked upstream sources (DBoW2, DLib, DLoopDetector; see README.md)
# SEQUENCE  a KITTI odometry sequence folder laid out by shared/data/real-seq/prepare.py
#           (image_0/, times.txt, groundtruth_tum.txt, intrinsics.txt)
# OUT_DIR   gets one folder per rate (run.sh's CSVs with the alpha sweep, topoloc's hints and
#           report), judged.json per rate, and table.md: precision, recall, recall at 100%
#           precision and median ms per keyframe for both, judged by judge.py
# --topoloc the topoloc CLI (default: target/release/topoloc of this checkout)
# --rates   keyframe rates in Hz, "all" for every frame (default "3 all")
#
# At each rate the two detectors run at the same time, one core each (topoloc's loops are
# single-threaded, run.sh's OpenCV too), so their times are measured under the same load.
# topoloc runs at its defaults, with the sequence's intrinsics as a host gives them.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
# shellcheck source=tools/dbow2/common.sh
source "$HERE/common.sh"

[[ $# -ge 3 ]] || usage 18
SRC_DIR="$1" SEQUENCE="$2" OUT_DIR="$3"
shift 3
TOPOLOC="$ROOT/target/release/topoloc"
RATES="3 all"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --topoloc)
      [[ $# -ge 2 ]] || die "--topoloc needs a path"
      TOPOLOC="$2"; shift 2 ;;
    --rates)
      [[ $# -ge 2 ]] || die "--rates needs a list"
      RATES="$2"; shift 2 ;;
    -h|--help) usage 18 ;;
    *) die "unknown option '$1' (see --help)" ;;
  esac
done
[[ -x "$TOPOLOC" ]] || die "no topoloc CLI at '$TOPOLOC' (cargo build --release -p topoloc-cli, or pass --topoloc)"
for f in times.txt groundtruth_tum.txt intrinsics.txt; do
  [[ -f "$SEQUENCE/$f" ]] || die "SEQUENCE '$SEQUENCE' has no $f (lay it out with shared/data/real-seq/prepare.py)"
done
mkdir -p "$OUT_DIR"

# Build DBoW2 and train its vocabulary first (run.sh reuses both), so that neither is timed
# beside topoloc.
bash "$HERE/run.sh" "$SRC_DIR" "$SEQUENCE" "$OUT_DIR/warm-up" --max-frames 2 >/dev/null

table="$OUT_DIR/table.md"
{
  echo "| keyframes | detector | hints | precision | recall | R@100P | ms per keyframe (median) |"
  echo "|---|---|---|---|---|---|---|"
} >"$table"
for rate in $RATES; do
  dir="$OUT_DIR/$rate"
  mkdir -p "$dir"
  rate_args=()
  [[ "$rate" == all ]] || rate_args=(--keyframe-rate "$rate")
  echo "== keyframes: $rate (topoloc and DBoW2 at the same time)" >&2
  bash "$HERE/run.sh" "$SRC_DIR" "$SEQUENCE" "$dir" "${rate_args[@]}" --sweep 2>"$dir/dbow2.err" &
  dbow2=$!
  "$TOPOLOC" loops --images "$SEQUENCE" "${rate_args[@]}" --intrinsics "$SEQUENCE/intrinsics.txt" \
    --out "$dir/topoloc.csv" --json >"$dir/topoloc.json" 2>"$dir/topoloc.err" \
    || { cat "$dir/topoloc.err" >&2; die "topoloc loops failed"; }
  wait "$dbow2" || { cat "$dir/dbow2.err" >&2; die "run.sh failed"; }
  python3 "$HERE/judge.py" "$dir" "$SEQUENCE" --topoloc "$dir/topoloc.csv" \
    --topoloc-json "$dir/topoloc.json" >"$dir/judged.json"
  python3 - "$dir/judged.json" "$rate" >>"$table" <<'EOF'
import json, sys
j = json.load(open(sys.argv[1]))
rate = "every frame" if sys.argv[2] == "all" else f"{sys.argv[2]} per s"
fmt = lambda v: "-" if v is None else f"{v:.3f}"
for name, r, full in (("topoloc", j["topoloc"], j["topoloc"]["recall_at_full_precision"]),
                      ("DBoW2 + DLoopDetector (alpha 0.3)", j, j.get("recall_at_full_precision"))):
    print(f"| {rate} ({r['keyframes']}) | {name} | {r['hints']} | {fmt(r['precision'])} | "
          f"{fmt(r['recall'])} | {fmt(full)} | {r['median_ms']:.1f} |")
EOF
done
cat "$table"
