#!/usr/bin/env bash
# Installs what python/train/ needs, idempotently: Debian's CPU PyTorch (python3-torch), ONNX
# (python3-onnx, for export.py) and OpenCV (python3-opencv, for dataset.py's images). They are
# used with /usr/bin/python3, Debian's interpreter, whatever python3 is first on PATH.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$root/scripts/lib.sh"
apt_install_missing train-setup python3-torch python3-onnx python3-opencv python3-numpy
