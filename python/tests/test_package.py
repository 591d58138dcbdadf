"""Packaging: the version is Cargo.toml's, ``py.typed`` ships, the public API is annotated, the
build glue (``python/setup.py``) fails clearly; and, when the suite runs against an installed
wheel (``TOPOLOC_TEST_INSTALLED=1``, see ``run_installed.sh``), that the wheel is the one
imported, carries its own library and has a platform tag."""

from __future__ import annotations

import ast
import importlib.metadata
import importlib.util
import inspect
import os
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import List, Optional

import pytest

import topoloc

from conftest import INSTALLED, PYTHON_DIR, REPO_ROOT

SETUP_PY = PYTHON_DIR / "setup.py"
PACKAGE_DIR = Path(topoloc.__file__).resolve().parent
needs_checkout = pytest.mark.skipif(REPO_ROOT is None, reason="not a source checkout")
installed_only = pytest.mark.skipif(
    not INSTALLED, reason="only against an installed wheel (run_installed.sh)"
)


def cargo_package_version(text: str) -> Optional[str]:
    """The ``[package] version`` of a Cargo.toml (tomllib when there is one)."""
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        m = re.search(r'^\[package\][^\[]*?^version\s*=\s*"([^"]+)"', text, re.M | re.S)
        return m.group(1) if m else None
    return tomllib.loads(text).get("package", {}).get("version")


@pytest.fixture(scope="module")
def setup_py() -> ModuleType:
    """``python/setup.py`` imported as a module (its ``setup()`` only runs as ``__main__``)."""
    if not SETUP_PY.is_file():
        pytest.skip("no python/setup.py")
    spec = importlib.util.spec_from_file_location("topoloc_setup_under_test", SETUP_PY)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ---------------------------------------------------------------------------------------------
# Both in-tree and installed
# ---------------------------------------------------------------------------------------------


@needs_checkout
def test_version_is_cargo_toml_version():
    expected = cargo_package_version((REPO_ROOT / "Cargo.toml").read_text())
    assert expected and re.fullmatch(r"\d+\.\d+\.\d+\S*", expected)
    assert topoloc.__version__ == expected
    assert isinstance(topoloc.__version__, str)


def test_py_typed_ships():
    marker = PACKAGE_DIR / "py.typed"
    assert marker.is_file(), f"no py.typed in {PACKAGE_DIR}"


def _unannotated(qualname: str, fn: object) -> List[str]:
    sig = inspect.signature(fn)  # type: ignore[arg-type]
    missing = [
        f"{qualname}({name})"
        for name, p in sig.parameters.items()
        if name not in ("self", "cls") and p.annotation is inspect.Parameter.empty
    ]
    if sig.return_annotation is inspect.Signature.empty and not qualname.endswith("__init__"):
        missing.append(f"{qualname} -> ?")
    return missing


def test_public_api_is_annotated():
    # What py.typed promises: every public function, method and property of the package has
    # its parameters and return annotated (generated dataclass/enum members aside).
    missing: List[str] = []
    for name in topoloc.__all__:
        obj = getattr(topoloc, name)
        if inspect.isfunction(obj):
            missing += _unannotated(name, obj)
        elif inspect.isclass(obj) and obj.__module__.startswith("topoloc"):
            for klass in obj.__mro__:
                if not klass.__module__.startswith("topoloc"):
                    continue
                for member_name, member in vars(klass).items():
                    if member_name.startswith("_") and member_name not in (
                        "__init__",
                        "__enter__",
                        "__exit__",
                        "__len__",
                    ):
                        continue
                    target = (
                        member.__func__
                        if isinstance(member, (classmethod, staticmethod))
                        else member
                    )
                    if isinstance(target, property):
                        target = target.fget
                    if inspect.isfunction(target) and target.__module__.startswith("topoloc"):
                        if getattr(target, "__qualname__", "").startswith(klass.__qualname__ + "."):
                            missing += _unannotated(f"{name}.{member_name}", target)
    assert sorted(set(missing)) == []


#: The package's modules in import order: each imports only from the layers before its own
#: (one way, no cycles), as src/ffi/'s modules do.
MODULE_LAYERS = [
    {"_lib"},
    {"_version"},
    {"_errors"},
    {"_convert"},
    {"_options", "_handles", "_logging"},
    {"_map", "_skeleton", "_trajectory"},
    {"_localizer", "_describer", "_keyframes"},
    {"_loops"},
    {"__init__"},
]


def _package_imports(module: Path) -> set:
    """The package modules that ``module`` imports (``from .x import ...``, ``from . import x``)."""
    found = set()
    for node in ast.walk(ast.parse(module.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                found.add(node.module)
            else:
                found.update(alias.name for alias in node.names)
    return found


def test_modules_import_one_way():
    modules = {p.stem: p for p in PACKAGE_DIR.glob("*.py")}
    assert set(modules) == set().union(*MODULE_LAYERS), "a module is missing from MODULE_LAYERS"
    assert "_core" not in modules
    layer = {name: i for i, names in enumerate(MODULE_LAYERS) for name in names}
    for name, path in modules.items():
        for imported in _package_imports(path):
            assert layer[imported] < layer[name], f"{name} imports {imported}"


def test_every_module_names_its_concern():
    for path in PACKAGE_DIR.glob("*.py"):
        doc = ast.get_docstring(ast.parse(path.read_text()))
        assert doc and len(doc.split()) >= 8, f"{path.name} has no docstring naming its concern"


def test_context_managers_return_their_own_type():
    hints = inspect.signature(topoloc.Map.__enter__)
    assert hints.return_annotation != inspect.Signature.empty
    with topoloc.MapBuilder("toy", None, 2) as b:
        assert type(b) is topoloc.MapBuilder


def test_setup_reads_the_cargo_version(setup_py, monkeypatch, tmp_path):
    if REPO_ROOT is None:
        pytest.skip("not a source checkout")
    expected = cargo_package_version((REPO_ROOT / "Cargo.toml").read_text())
    assert setup_py.cargo_version() == expected
    # The [package] table's version, not [workspace.package]'s or a dependency's.
    tricky = tmp_path / "Cargo.toml"
    tricky.write_text(
        '[workspace.package]\nversion = "9.9.9"\n\n[package]\nname = "topoloc"\n'
        'version = "1.2.3-rc.1"\n\n[dependencies]\nfoo = { version = "4.5.6" }\n'
    )
    assert setup_py.cargo_version(tricky) == "1.2.3-rc.1"
    # The regex fallback of Pythons without tomllib agrees.
    monkeypatch.setitem(sys.modules, "tomllib", None)
    assert setup_py.cargo_version(tricky) == "1.2.3-rc.1"
    assert setup_py.cargo_version() == expected


def test_setup_builds_in_cargos_target_directory(setup_py, tmp_path):
    repo_target = setup_py.REPO_ROOT / "target" / "py-build"
    assert setup_py.build_directory({}) == repo_target
    assert setup_py.build_directory({"CARGO_TARGET_DIR": ""}) == repo_target
    elsewhere = tmp_path / "cargo-target"
    assert setup_py.build_directory({"CARGO_TARGET_DIR": str(elsewhere)}) == elsewhere / "py-build"


def test_setup_refuses_a_manifest_without_version(setup_py, tmp_path):
    bad = tmp_path / "Cargo.toml"
    bad.write_text('[package]\nname = "topoloc"\nversion.workspace = true\n')
    with pytest.raises(setup_py.CargoManifestError, match=r"\[package\] version"):
        setup_py.cargo_version(bad)
    with pytest.raises(setup_py.CargoManifestError, match="not found"):
        setup_py.cargo_version(tmp_path / "missing" / "Cargo.toml")


def test_setup_names_cargo_when_it_is_missing(setup_py, tmp_path):
    empty_path = {"PATH": str(tmp_path)}  # no cargo in an empty folder
    with pytest.raises(setup_py.CargoNotFoundError) as info:
        setup_py.find_cargo(empty_path)
    assert "cargo" in str(info.value) and "PATH" in str(info.value)
    with pytest.raises(setup_py.CargoNotFoundError, match="cargo"):
        setup_py.build_library(empty_path)
    with pytest.raises(setup_py.CargoNotFoundError, match="CARGO="):
        setup_py.find_cargo({"PATH": str(tmp_path), "CARGO": str(tmp_path / "no-such-cargo")})


def test_setup_reports_a_failed_cargo_build(setup_py, tmp_path):
    fake = tmp_path / "cargo"
    fake.write_text("#!/bin/sh\necho 'error: could not compile' >&2\nexit 101\n")
    fake.chmod(0o755)
    env = {"PATH": os.environ.get("PATH", ""), "CARGO": str(fake)}
    with pytest.raises(setup_py.CargoBuildError, match="exit code 101"):
        setup_py.build_library(env)


# ---------------------------------------------------------------------------------------------
# In-tree only / installed only
# ---------------------------------------------------------------------------------------------


@pytest.mark.skipif(INSTALLED, reason="tests an installed wheel")
def test_in_tree_run_imports_the_source_tree():
    assert PACKAGE_DIR == PYTHON_DIR / "topoloc"


@installed_only
def test_installed_package_is_imported_not_the_source_tree():
    assert PYTHON_DIR not in PACKAGE_DIR.parents
    assert Path(sys.prefix).resolve() in PACKAGE_DIR.parents, (PACKAGE_DIR, sys.prefix)


@installed_only
def test_installed_package_loads_its_bundled_library():
    assert "TOPOLOC_LIBRARY" not in os.environ
    assert Path(topoloc.library_path).resolve() == PACKAGE_DIR / "libtopoloc.so"
    assert topoloc.abi_version() == topoloc.ABI_VERSION


@installed_only
def test_installed_distribution_metadata():
    dist = importlib.metadata.distribution("topoloc")
    assert dist.version == topoloc.__version__
    files = {str(f) for f in dist.files or []}
    assert {"topoloc/py.typed", "topoloc/libtopoloc.so", "topoloc/__init__.py"} <= files
    assert not any(f.startswith(("tests/", "examples/")) for f in files)
    wheel = dist.read_text("WHEEL") or ""
    tags = re.findall(r"^Tag: (\S+)$", wheel, re.M)
    assert tags and all(t.startswith("py3-none-") and not t.endswith("-any") for t in tags), tags
    assert "Root-Is-Purelib: false" in wheel
    requires = dist.requires or []
    assert any(r.replace(" ", "").startswith("numpy>=") for r in requires), requires
