"""The GTSAM drift-correction example (python/examples/drift_correction_gtsam.py) end to end on
a short simulated sequence: its JSON figures, no false loop factor in the graph, a corrected
trajectory better than the odometry, the PNG, and exit code 2 on a missing sequence."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import PACKAGE_PARENT, PYTHON_DIR, REPO_ROOT

pytest.importorskip("gtsam", reason="the drift demo needs gtsam (python/requirements-dev.txt)")
pytest.importorskip(
    "cv2", reason="the drift demo needs opencv-python-headless (python/requirements-dev.txt)"
)

DEMO = PYTHON_DIR / "examples" / "drift_correction_gtsam.py"
CLI = REPO_ROOT / "target" / "release" / "topoloc" if REPO_ROOT else None
#: Every key of the demo's --json object.
KEYS = {
    "keyframes",
    "hints_accepted",
    "loop_constraints",
    "loop_factors_used",
    "loop_factors_dropped",
    "loops_imprecise",
    "false_used",
    "false_dropped",
    "false_imprecise",
    "ate_raw_m",
    "ate_corrected_m",
    "ate_ratio",
    "ms_per_keyframe",
    "detector_ms_per_keyframe",
    "optimisation_ms",
}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def simulate(out: Path, *args: str) -> None:
    """``topoloc simulate ... --out out`` (the built CLI)."""
    subprocess.run(
        [str(CLI), "simulate", *args, "--out", str(out)],
        check=True,
        capture_output=True,
        timeout=120,
    )


def run_demo(*args: str) -> subprocess.CompletedProcess:
    """The demo in a child Python on the package under test (this checkout's, or the installed
    one)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(PACKAGE_PARENT), env.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, str(DEMO), *args], env=env, capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    """``(sequence folder, describer map)``: three legs of a test world at 1 Hz with depth (67
    frames), and a small map of a training world (another world: its describer was not fit on
    the sequence)."""
    if CLI is None or not CLI.is_file():
        pytest.skip(
            "the topoloc CLI is not built: run `cargo build --release` (target/release/topoloc)"
        )
    root = tmp_path_factory.mktemp("drift")
    simulate(
        root / "map",
        "--split",
        "train",
        "--world",
        "0",
        "--legs",
        "1",
        "--rate-hz",
        "1",
        "--rooms",
        "2",
        "--views-per-place",
        "4",
    )
    simulate(
        root / "seq",
        "--split",
        "test",
        "--world",
        "0",
        "--legs",
        "3",
        "--rate-hz",
        "1",
        "--views-per-place",
        "1",
        "--depth",
    )
    return root / "seq" / "traj-000", root / "map" / "map.topoloc"


def test_demo_corrects_drift_without_false_loops(sequence, tmp_path):
    folder, describer = sequence
    png = tmp_path / "drift.png"
    done = run_demo(
        "--sequence", str(folder), "--describer", str(describer), "--out", str(png), "--json"
    )
    assert done.returncode == 0, done.stderr
    figures = json.loads(done.stdout)
    assert set(figures) == KEYS
    assert figures["keyframes"] == len(list((folder / "images").glob("*.png")))
    kept_or_not = (
        figures["loop_factors_used"] + figures["loop_factors_dropped"] + figures["loops_imprecise"]
    )
    assert kept_or_not == figures["loop_constraints"]
    assert figures["loop_constraints"] <= figures["hints_accepted"]
    assert figures["false_used"] == 0
    assert figures["loop_factors_used"] > 0, "the sequence revisits a goal: loops expected"
    assert figures["ate_corrected_m"] < figures["ate_raw_m"]
    assert figures["ate_ratio"] == pytest.approx(figures["ate_corrected_m"] / figures["ate_raw_m"])
    assert png.read_bytes()[:8] == PNG_MAGIC


def test_missing_sequence_exits_2(tmp_path):
    missing = tmp_path / "no-such-sequence"
    done = run_demo("--sequence", str(missing), "--describer", str(tmp_path / "map.topoloc"))
    assert done.returncode == 2
    assert "missing sequence folder" in done.stderr and str(missing) in done.stderr
    assert done.stdout == ""
