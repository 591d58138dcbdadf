"""Build glue for ``pip install ./python``: the wheel carries ``libtopoloc.so`` inside the
``topoloc`` package, so that ``import topoloc`` works without a checkout or ``TOPOLOC_LIBRARY``.

The metadata lives in ``pyproject.toml``; this file adds what it cannot say:

- the version, read from the ``[package] version`` of the repository's ``Cargo.toml`` (the
  crate whose library the wheel carries), never written here;
- a ``build_py`` step that runs ``cargo build --release --lib -p topoloc`` at the repository
  root and copies ``<target>/release/libtopoloc.so`` into the built package (the target
  directory is cargo's own answer: ``CARGO_TARGET_DIR`` or ``.cargo/config`` are honoured);
- a platform wheel tag, ``py3-none-<platform>``: the package holds a native library (so it is
  not ``py3-none-any``), loaded through ctypes rather than the CPython C API (so one wheel serves
  every Python 3 of that platform).

Build outputs go to ``py-build`` in cargo's target directory (``$CARGO_TARGET_DIR``, else
``<repository>/target``), not into the source tree. Errors are typed:
:class:`CargoNotFoundError` when there is no ``cargo``, :class:`CargoBuildError` when the build
fails or produces no library, :class:`CargoManifestError` when ``Cargo.toml`` has no version.

Importing this module (as the tests do) defines the helpers without running ``setup()``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Dict, List, Mapping, Optional

PYTHON_DIR = Path(__file__).resolve().parent
REPO_ROOT = PYTHON_DIR.parent
CARGO_TOML = REPO_ROOT / "Cargo.toml"
#: The cargo package whose cdylib the wheel carries.
CRATE = "topoloc"


class CargoManifestError(RuntimeError):
    """The repository's Cargo.toml is missing or has no ``[package] version``."""


class CargoNotFoundError(RuntimeError):
    """``cargo`` (the Rust toolchain) is not installed or not on PATH."""


class CargoBuildError(RuntimeError):
    """``cargo build`` failed, or did not produce the shared library."""


def library_file_name(platform: str = sys.platform) -> str:
    """The file name cargo gives the cdylib (``python/topoloc/_lib.py`` looks for the same)."""
    if platform == "darwin":
        return "libtopoloc.dylib"
    if platform == "win32":
        return "topoloc.dll"
    return "libtopoloc.so"


def cargo_version(cargo_toml: Path = CARGO_TOML) -> str:
    """The ``[package] version`` of ``cargo_toml``."""
    if not cargo_toml.is_file():
        raise CargoManifestError(
            f"{cargo_toml} not found: the topoloc Python package is built from the topoloc "
            "repository (pip install ./python at its root), whose Cargo.toml gives the version"
        )
    text = cargo_toml.read_text(encoding="utf-8")
    try:
        import tomllib  # Python >= 3.11
    except ImportError:
        tomllib = None
    version: Optional[str] = None
    if tomllib is not None:
        package = tomllib.loads(text).get("package", {})
        value = package.get("version")
        version = value if isinstance(value, str) else None
    else:  # the [package] table's own `version = "..."` line
        table = re.search(r"^\[package\]\s*$(.*?)(?=^\[)", text + "\n[", re.M | re.S)
        if table:
            line = re.search(r'^version\s*=\s*"([^"]+)"\s*$', table.group(1), re.M)
            version = line.group(1) if line else None
    if not version:
        raise CargoManifestError(
            f'{cargo_toml} has no [package] version = "..." (a literal string)'
        )
    return version


def find_cargo(environ: Optional[Mapping[str, str]] = None) -> str:
    """``$CARGO`` if set, else ``cargo`` on ``PATH``; raises :class:`CargoNotFoundError`."""
    environ = os.environ if environ is None else environ
    explicit = environ.get("CARGO")
    if explicit:
        if shutil.which(explicit, path=environ.get("PATH")) is None:
            raise CargoNotFoundError(
                f"CARGO={explicit!r} is not an executable cargo; building the topoloc wheel needs "
                "cargo to compile libtopoloc (unset CARGO to use the one on PATH)"
            )
        return explicit
    found = shutil.which("cargo", path=environ.get("PATH"))
    if found is None:
        raise CargoNotFoundError(
            "building the topoloc wheel needs `cargo` (the Rust toolchain) to compile libtopoloc, "
            "but no cargo was found on PATH. Install Rust (https://rustup.rs, or Debian's cargo "
            "package), put ~/.cargo/bin on PATH, or set CARGO=/path/to/cargo"
        )
    return found


def _run_cargo(cmd: List[str], env: Dict[str, str], capture: bool) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(cmd, cwd=REPO_ROOT, env=env, capture_output=capture, text=True)
    except OSError as e:  # e.g. CARGO points at something that cannot be executed
        raise CargoNotFoundError(f"could not run cargo ({cmd[0]}): {e}") from e


def build_directory(env: Dict[str, str]) -> Path:
    """Where setuptools builds: ``py-build`` in ``$CARGO_TARGET_DIR`` (relative to the
    working directory, as cargo reads it) when set, else in ``<repository>/target``. Known
    before cargo runs, so that no build file lands in a checkout a caller moved away from."""
    target = env.get("CARGO_TARGET_DIR")
    return (Path(target).resolve() if target else REPO_ROOT / "target") / "py-build"


def target_directory(cargo: str, env: Dict[str, str]) -> Path:
    """Cargo's target directory for the workspace (``cargo metadata``)."""
    cmd = [
        cargo,
        "metadata",
        "--format-version",
        "1",
        "--no-deps",
        "--manifest-path",
        str(CARGO_TOML),
    ]
    proc = _run_cargo(cmd, env, capture=True)
    if proc.returncode != 0:
        raise CargoBuildError(f"`{' '.join(cmd)}` failed (exit {proc.returncode}):\n{proc.stderr}")
    return Path(json.loads(proc.stdout)["target_directory"])


def build_library(environ: Optional[Mapping[str, str]] = None) -> Path:
    """Runs ``cargo build --release --lib -p topoloc`` at the repository root and returns the
    built shared library."""
    env = dict(os.environ if environ is None else environ)
    cargo_version(CARGO_TOML)  # a clear error before cargo's when this is not the repository
    cargo = find_cargo(env)
    cmd = [cargo, "build", "--release", "--lib", "-p", CRATE, "--manifest-path", str(CARGO_TOML)]
    print(f"topoloc: {' '.join(cmd)}", file=sys.stderr, flush=True)
    proc = _run_cargo(cmd, env, capture=False)
    if proc.returncode != 0:
        raise CargoBuildError(
            f"`{' '.join(cmd)}` failed with exit code {proc.returncode} (its output is above)"
        )
    built = target_directory(cargo, env) / "release" / library_file_name()
    if not built.is_file():
        raise CargoBuildError(f"`{' '.join(cmd)}` succeeded but {built} does not exist")
    return built


def _setup() -> None:
    from setuptools import setup
    from setuptools.command.bdist_wheel import bdist_wheel
    from setuptools.command.build_py import build_py
    from setuptools.dist import Distribution

    class BuildPyWithLibrary(build_py):
        """``build_py``, then the freshly built ``libtopoloc`` copied into the package."""

        def run(self) -> None:
            # The build folder outlives builds: drop the last one's package so that a module
            # removed from the source tree does not ship again.
            shutil.rmtree(Path(self.build_lib) / "topoloc", ignore_errors=True)
            super().run()
            if self.dry_run:
                return
            built = build_library()
            dest = Path(self.build_lib) / "topoloc" / library_file_name()
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(built, dest)  # a copy, not the SONAME symlink chain
            os.chmod(dest, 0o755)

        def get_outputs(self, include_bytecode: bool = True) -> List[str]:
            outputs = super().get_outputs(include_bytecode)
            return [*outputs, str(Path(self.build_lib) / "topoloc" / library_file_name())]

    class PlatformWheel(bdist_wheel):
        """Tag ``py3-none-<platform>``: native content, no dependence on the CPython ABI."""

        def finalize_options(self) -> None:
            super().finalize_options()
            self.root_is_pure = False

        def get_tag(self):  # type: ignore[no-untyped-def]
            _, _, plat = super().get_tag()
            return "py3", "none", plat

    class BinaryDistribution(Distribution):
        """Marks the distribution as holding native code (platlib, platform wheel)."""

        def has_ext_modules(self) -> bool:
            return True

    build_base = build_directory(dict(os.environ))
    setup(
        version=cargo_version(),
        distclass=BinaryDistribution,
        cmdclass={"build_py": BuildPyWithLibrary, "bdist_wheel": PlatformWheel},
        options={
            "build": {"build_base": str(build_base)},
            "egg_info": {"egg_base": str(build_base)},
        },
    )


if __name__ == "__main__":
    build_directory(dict(os.environ)).mkdir(parents=True, exist_ok=True)
    _setup()
