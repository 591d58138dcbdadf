#!/usr/bin/env bash
# Runs the Python test-suite against the installed wheel rather than the source tree:
#   1. builds the wheel (`pip wheel ./python`: cargo build --release --lib -p topoloc, library copied in),
#   2. installs it into a fresh venv, target/py-venv, made with --system-site-packages (numpy,
#      pytest, gtsam... come from the system),
#   3. checks, with TOPOLOC_LIBRARY unset and from a folder where the source tree's python/topoloc
#      is not importable, that `import topoloc` is the venv's copy and loads its bundled library,
#      and that the library's run-time dependencies resolve (ldd),
#   4. runs `python -m pytest -q python/tests` there with TOPOLOC_TEST_INSTALLED=1 (conftest then
#      refuses a source-tree import).
# Usage: bash python/tests/run_installed.sh [extra pytest arguments]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
python="${PYTHON:-python3}"
venv="$root/target/py-venv"
wheels="$root/target/py-wheel"

command -v cargo >/dev/null 2>&1 || [[ -n "${CARGO:-}" ]] || {
  echo "run_installed: cargo (the Rust toolchain) is needed to build the wheel, and none is on PATH" >&2
  exit 1
}

echo "run_installed: fresh venv $venv (--system-site-packages)"
rm -rf "$venv" "$wheels"
"$python" -m venv --system-site-packages "$venv"
vpy="$venv/bin/python"

echo "run_installed: building the wheel"
"$vpy" -m pip wheel -q --no-deps -w "$wheels" "$root/python"
shopt -s nullglob
built=("$wheels"/topoloc-*.whl)
if ((${#built[@]} != 1)); then
  echo "run_installed: expected one topoloc wheel in $wheels, found ${#built[@]}" >&2
  exit 1
fi
wheel="${built[0]}"
case "$(basename "$wheel")" in
  *-none-any.whl) echo "run_installed: $wheel is a pure wheel; it must be platform-specific" >&2; exit 1 ;;
esac
echo "run_installed: installing $(basename "$wheel")"
# Dependencies (numpy) resolve against the system site-packages: nothing is downloaded when present.
"$vpy" -m pip install -q "$wheel"

unset TOPOLOC_LIBRARY
outside="$(mktemp -d)"
trap 'rm -rf "$outside"' EXIT
cd "$outside"

"$vpy" - "$venv" "$root" <<'PY'
import os, subprocess, sys
from pathlib import Path

venv, root = (Path(p).resolve() for p in sys.argv[1:3])
import topoloc

pkg = Path(topoloc.__file__).resolve().parent
if venv not in pkg.parents:
    sys.exit(f"run_installed: topoloc was imported from {pkg}, not from the venv {venv}")
if (root / "python") in pkg.parents:
    sys.exit(f"run_installed: topoloc was imported from the source tree ({pkg})")
lib = Path(topoloc.library_path).resolve()
if lib != pkg / "libtopoloc.so":
    sys.exit(f"run_installed: the loaded library is {lib}, not the bundled {pkg / 'libtopoloc.so'}")
ldd = subprocess.run(["ldd", str(lib)], capture_output=True, text=True)
missing = [line.strip() for line in ldd.stdout.splitlines() if "not found" in line]
if ldd.returncode != 0 or missing:
    sys.exit(f"run_installed: unresolved run-time dependencies of {lib}: {missing or ldd.stderr}")
print(f"run_installed: topoloc {topoloc.__version__} from {pkg}, library {lib.name} (bundled), "
      f"ABI {topoloc.abi_version()}.{topoloc.abi_version_minor()}")
PY

echo "run_installed: python -m pytest -q python/tests (against the installed wheel)"
TOPOLOC_TEST_INSTALLED=1 "$vpy" -m pytest -q -o cache_dir="$outside/.pytest_cache" "$root/python/tests" "$@"
