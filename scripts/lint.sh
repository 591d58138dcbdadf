#!/usr/bin/env bash
# Lints beside Rust's (scripts/test.sh runs rustfmt, clippy and rustdoc itself):
#   clang-format --dry-run -Werror   every tracked C and C++ file (.clang-format), but the
#                                    cbindgen-generated include/topoloc.h
#   ruff check, ruff format --check  python/ and cpp-examples/ (python/pyproject.toml)
#   mypy --strict                    python/topoloc, the package that ships py.typed
#   shell: shellcheck                every tracked shell script
# scripts/install-deps.sh installs the tools (clang-format and shellcheck from Debian, ruff and
# mypy from python/requirements-dev.txt).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

mapfile -t c_files < <(git ls-files '*.c' '*.h' '*.cpp' '*.hpp' | grep -v '^include/topoloc\.h$')
echo "lint: clang-format on ${#c_files[@]} C/C++ files"
clang-format --dry-run -Werror "${c_files[@]}"

echo "lint: ruff and mypy --strict on python/"
python3 -m ruff check --quiet python
python3 -m ruff format --check --quiet python
python3 -m mypy --strict --no-error-summary --config-file python/pyproject.toml python/topoloc
echo "lint: ruff on the integration scripts (cpp-examples/; their C++ snippets may exceed 100 columns)"
python3 -m ruff check --quiet --config python/pyproject.toml --ignore E501 cpp-examples
python3 -m ruff format --check --quiet --config python/pyproject.toml cpp-examples

mapfile -t shell_files < <(git ls-files '*.sh' .ci/run)
echo "lint: shellcheck on ${#shell_files[@]} scripts"
shellcheck "${shell_files[@]}"
echo "lint: clean"
