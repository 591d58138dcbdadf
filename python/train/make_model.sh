#!/usr/bin/env bash
# Reproduces models/grnn.onnx, the GRNN built into the library, with fixed seeds:
#   bash python/train/make_model.sh [DATA_DIR] [OUT]
# 1. python/train/setup.sh (Debian's torch, onnx, opencv), scripts/setup-models.sh (ONNX Runtime
#    and MobileNetV2, which describes the frames), and the release library and CLI;
# 2. dataset.py: Train and Tr-T worlds 0-2 under bright, dim and night light (training), Tr-A
#    world 3 under dim and night (validation: no world of the ablation), cached in DATA_DIR
#    (default target/grnn-data; about 30 minutes on 2 cores the first time);
# 3. train.py, one thread, seed 1 (about 50 minutes on one core); the schedule is below;
# 4. export.py with float16 weights to OUT (default models/grnn.onnx).
# The figures of the model this writes are in BENCHMARKS.md ("The learned GRNN").
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
data="${1:-$root/target/grnn-data}"
out="${2:-$root/models/grnn.onnx}"
bash python/train/setup.sh
bash scripts/setup-models.sh
cargo build --release --quiet --lib -p topoloc
cargo build --release --quiet -p topoloc-cli
export TOPOLOC_LIBRARY="$root/target/release/libtopoloc.so"
python=/usr/bin/python3
mkdir -p "$data"
for split in train tr-t; do
    "$python" python/train/dataset.py --split "$split" --worlds 0-2 \
        --conditions bright,dim,night --out "$data"
done
"$python" python/train/dataset.py --split tr-a --worlds 3 --conditions dim,night --out "$data"
checkpoint="$data/grnn.pt"
"$python" python/train/train.py --data "$data" --train 'train-*.npz,tr-t-*.npz' \
    --validate 'tr-a-w3-*.npz' --out "$checkpoint" --seed 1 --threads 1 \
    --epochs 60 --batches 10 --batch 32 --frames 10-20 --lr 1e-3 --lr-step 10 \
    --hidden 64 --neighbour 32 --state 64
"$python" python/train/export.py "$checkpoint" "$out" --f16
