"""Shared fixtures: the package is imported from the source tree (or, with
``TOPOLOC_TEST_INSTALLED=1``, as installed: see ``run_installed.sh``), and small synthetic maps
are built with known descriptors so that tests can compute the expected answers with numpy."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import List, NoReturn, Optional, Union

import numpy as np
import pytest

PYTHON_DIR = Path(__file__).resolve().parents[1]
#: Whether the suite tests an installed package (a wheel in a venv) rather than the source tree.
INSTALLED = os.environ.get("TOPOLOC_TEST_INSTALLED", "") not in ("", "0")
if not INSTALLED and str(PYTHON_DIR) not in sys.path:
    sys.path.insert(0, str(PYTHON_DIR))

import topoloc  # noqa: E402

#: The directory holding the imported ``topoloc`` package: what a child interpreter needs on
#: ``PYTHONPATH`` to import the same package (the source tree's ``python/``, or site-packages).
PACKAGE_PARENT = Path(topoloc.__file__).resolve().parents[1]
if INSTALLED and PACKAGE_PARENT == PYTHON_DIR:
    raise ImportError(
        f"TOPOLOC_TEST_INSTALLED is set but topoloc was imported from the source tree "
        f"({topoloc.__file__}): run the tests from a directory where {PYTHON_DIR} is not on "
        "sys.path"
    )


#: Whether this is a CI run (``CI=true``, as ``.ci/run`` is run): there, a test that needs a
#: model fails instead of skipping when the model is missing.
IN_CI = os.environ.get("CI", "").strip().lower() == "true"


def skip_or_fail(reason: str) -> NoReturn:
    """Skips the test, or fails it under CI, where what it needs must be installed
    (``scripts/setup-models.sh``)."""
    if IN_CI:
        pytest.fail(
            f"{reason} (CI=true: scripts/setup-models.sh must have installed it)", pytrace=False
        )
    pytest.skip(reason)


def require_models(*paths: Union[str, Path]) -> None:
    """Returns when every model file in ``paths`` exists; else skips the test, or fails it
    under CI."""
    missing = [str(p) for p in paths if not Path(p).is_file()]
    if missing:
        skip_or_fail(f"model file(s) missing: {', '.join(missing)}")


def find_repo_root() -> Optional[Path]:
    for d in [PYTHON_DIR, *PYTHON_DIR.parents]:
        if (d / "Cargo.toml").is_file():
            return d
    return None


REPO_ROOT = find_repo_root()
HEADER = REPO_ROOT / "include" / "topoloc.h" if REPO_ROOT else None

KIND = "netvlad"
MODEL = "pitts30k-v1"


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rot_z(angle: float, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = t
    return m


@dataclass
class Corridor:
    """A chain of places along the x axis, ``views_per_place`` views each."""

    map: topoloc.Map
    dim: int
    places: int
    views_per_place: int
    base: np.ndarray  # (P, D) unit place descriptors
    views: np.ndarray  # (V, D) unit view descriptors, view v of place v // views_per_place
    poses: List[np.ndarray]
    rng: np.random.Generator

    def query(self, place: int, noise: float = 0.03, view: int = 0) -> np.ndarray:
        """A noisy (unnormalised) copy of a view of ``place``."""
        v = self.views[place * self.views_per_place + view]
        return (v + noise * self.rng.standard_normal(self.dim)).astype(np.float32) * 3.0

    def expected_single_frame(self, q: np.ndarray):
        """(place, view, similarity) that a single-frame localizer must report: best view
        similarity pooled per place."""
        sims = unit(self.views.astype(np.float64)) @ unit(q.astype(np.float64))
        view = int(np.argmax(sims))
        return view // self.views_per_place, view, float(sims[view])


def build_corridor(
    places: int = 12, views_per_place: int = 2, dim: int = 64, seed: int = 7
) -> Corridor:
    rng = np.random.default_rng(seed)
    base = unit(rng.standard_normal((places, dim)))
    views = []
    poses = []
    with topoloc.MapBuilder(KIND, MODEL, dim) as b:
        for p in range(places):
            pid = b.add_place(position=[2.0 * p, 0.5, 0.0])
            assert pid == p
            for k in range(views_per_place):
                d = unit(base[p] + 0.3 * rng.standard_normal(dim) / np.sqrt(dim))
                pose = rot_z(k * np.pi / 2, (2.0 * p, 0.5, 1.2))
                vid = b.add_view(
                    pid,
                    d * (1.0 + p),  # not unit: the library normalises
                    keyframe_id=1000 + len(views),
                    world_T_camera=pose,
                    image=f"images/place{p:03d}_view{k}.png",
                )
                assert vid == len(views)
                views.append(d)
                poses.append(pose)
        for p in range(places - 1):
            b.add_edge(p, p + 1, 1.0 + 0.5 * p)
        m = b.build()
    return Corridor(m, dim, places, views_per_place, base, np.array(views), poses, rng)


@pytest.fixture
def corridor():
    c = build_corridor()
    yield c
    c.map.close()


@pytest.fixture
def small_map():
    """Three places, one view each, dimension 4, no attributes."""
    with topoloc.MapBuilder("toy", None, 4) as b:
        for i in range(3):
            b.add_place()
            b.add_view(i, np.eye(4)[i] + 0.1)
        b.add_edge(0, 1)
        b.add_edge(1, 2)
        m = b.build()
    yield m
    m.close()


@pytest.fixture
def map_file(tmp_path, corridor) -> Path:
    path = tmp_path / "corridor.topomap"
    corridor.map.save(path)
    return path
