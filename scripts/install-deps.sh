#!/usr/bin/env bash
# Installs what topoloc's builds and tests need on a Debian machine (bookworm), idempotently
# (the ONNX model and runtime are set up by scripts/setup-models.sh):
# Debian packages only when missing (apt-get update only then), Python packages only when their
# import fails. The Rust toolchain is expected (rustup); this script does not install it.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/lib.sh
source "$root/scripts/lib.sh"

# OpenCV 4.6 (image work) needs clang + libclang for the opencv crate's binding generator.
# fonts-dejavu-core: the TrueType font the CLI's evaluation plots (tools/cli/src/plot.rs) draw text with.
# libclang-rt-14-dev: libFuzzer and the sanitizer runtimes of clang 14 (fuzz/run.sh).
# clang-format, shellcheck: the C/C++ and shell lints (scripts/lint.sh).
packages=(build-essential cmake pkg-config valgrind libopencv-dev clang libclang-dev libclang-rt-14-dev fonts-dejavu-core libceres-dev libeigen3-dev clang-format shellcheck)
apt_install_missing install-deps "${packages[@]}"

if ! command -v cargo >/dev/null 2>&1; then
  echo "install-deps: cargo not found; install Rust with rustup (https://rustup.rs) first" >&2
  exit 1
fi

if ! cargo nextest --version >/dev/null 2>&1; then
  echo "install-deps: cargo install cargo-nextest (the test runner of scripts/test.sh)"
  cargo install --locked --quiet cargo-nextest
fi

if ! python3 -c "import numpy, pytest, ruff, mypy" >/dev/null 2>&1; then
  echo "install-deps: pip install -r python/requirements-dev.txt"
  python3 -m pip install -q -r "$root/python/requirements-dev.txt"
fi
