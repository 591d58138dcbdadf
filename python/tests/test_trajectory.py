"""Trajectory metrics from Python, and their agreement with the evo package (its API is the
independent judge): ATE, ARE and RPE within 1e-6 on generated sequences and on the real
trajectories of ../shared/data/slam-trajectories (skipped, with a message, when absent)."""

from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np
import pytest

import topoloc

evo_trajectory = pytest.importorskip(
    "evo.core.trajectory", reason="evo is installed by scripts/install-deps.sh"
)
from evo.core import metrics, sync  # noqa: E402
from evo.tools import file_interface  # noqa: E402

DATA = Path(
    os.environ.get("TOPOLOC_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data")
)
TRAJECTORIES = DATA / "slam-trajectories"


def rows(traj) -> np.ndarray:
    """TUM rows of an evo trajectory (its quaternions are w first)."""
    q = traj.orientations_quat_wxyz
    return np.column_stack([traj.timestamps, traj.positions_xyz, q[:, 1:], q[:, :1]])


def evo_figures(ref, est, alignment: str, max_diff: float = 0.01, delta: int = 1):
    """ATE RMSE, ARE RMSE (deg), RPE RMSE (m) and the scale, as evo computes them."""
    ref, est = sync.associate_trajectories(ref, est, max_diff=max_diff)
    est = copy.deepcopy(est)
    scale = 1.0
    if alignment != "none":
        scale = est.align(ref, correct_scale=alignment == "sim3")[2]
    out = {"scale": scale}
    for name, relation in [
        ("ate", metrics.PoseRelation.translation_part),
        ("are", metrics.PoseRelation.rotation_angle_deg),
    ]:
        ape = metrics.APE(relation)
        ape.process_data((ref, est))
        out[name] = ape.get_statistic(metrics.StatisticsType.rmse)
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta, metrics.Unit.frames)
    rpe.process_data((ref, est))
    out["rpe"] = rpe.get_statistic(metrics.StatisticsType.rmse)
    return out


def assert_agrees(report: topoloc.TrajectoryReport, figures, pairs=None):
    assert report.ate_m.rmse == pytest.approx(figures["ate"], abs=1e-6)
    assert report.are_deg.rmse == pytest.approx(figures["are"], abs=1e-6)
    assert report.rpe_m.rmse == pytest.approx(figures["rpe"], abs=1e-6)
    assert report.scale == pytest.approx(figures["scale"], abs=1e-9)
    if pairs is not None:
        assert report.pairs == pairs


def generated(seed: int, n: int = 400):
    """A ground-truth loop at 20 Hz and a drifting, scaled, moved, jittered estimate of it
    sampled at other times (every third pose, 3 ms late)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.05
    a = t / t[-1] * 2 * np.pi
    xyz = np.column_stack([6 * np.cos(a), 4 * np.sin(a), 0.5 * np.sin(3 * a)])
    yaw = a + np.pi / 2
    q_gt = np.column_stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)])
    gt = evo_trajectory.PoseTrajectory3D(
        positions_xyz=xyz, orientations_quat_wxyz=q_gt, timestamps=t
    )
    drift = np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0)
    c, s = np.cos(0.4), np.sin(0.4)
    r = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    est_xyz = 0.7 * (xyz + drift) @ r.T + [1.0, -2.0, 0.3]
    tilt = rng.normal(0, 0.02, n)
    q_est = np.column_stack(
        [np.cos((yaw + 0.4 + tilt) / 2), np.zeros(n), np.zeros(n), np.sin((yaw + 0.4 + tilt) / 2)]
    )
    keep = np.arange(0, n, 3)
    est = evo_trajectory.PoseTrajectory3D(
        positions_xyz=est_xyz[keep], orientations_quat_wxyz=q_est[keep], timestamps=t[keep] + 0.003
    )
    return gt, est


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("alignment", ["none", "se3", "sim3"])
def test_generated_sequences_agree_with_evo(seed, alignment):
    gt, est = generated(seed)
    report = topoloc.evaluate_trajectory(rows(gt), rows(est), alignment=alignment)
    assert_agrees(report, evo_figures(gt, est, alignment), pairs=est.num_poses)
    if alignment == "sim3":
        assert report.scale == pytest.approx(1 / 0.7, rel=0.05)
        assert 0.9 < report.length_ratio < 1.2


def test_rpe_steps_and_time_offset_agree_with_evo():
    gt, est = generated(3)
    shifted = copy.deepcopy(est)
    shifted.timestamps = shifted.timestamps + 0.525
    report = topoloc.evaluate_trajectory(
        rows(gt), rows(shifted), alignment="se3", offset_s=-0.525, rpe_delta=4
    )
    figures = evo_figures(gt, est, "se3", delta=4)
    assert_agrees(report, figures, pairs=est.num_poses)
    with pytest.raises(topoloc.InvalidArgumentError, match="no estimated pose"):
        topoloc.evaluate_trajectory(rows(gt), rows(shifted))


def test_bad_input_is_refused():
    gt, _est = generated(4, n=30)
    good = rows(gt)
    with pytest.raises(topoloc.InvalidArgumentError):
        topoloc.evaluate_trajectory(good[:, :7], good)
    bad = good.copy()
    bad[3, 1] = np.nan
    with pytest.raises(topoloc.NonFiniteError):
        topoloc.evaluate_trajectory(good, bad)
    bad = good.copy()
    bad[3, 7] = 3.0
    with pytest.raises(topoloc.InvalidArgumentError, match="norm"):
        topoloc.evaluate_trajectory(good, bad)
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.evaluate_trajectory(good, good, alignment="affine")
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.evaluate_trajectory(good, good, rpe_delta=0)
    with pytest.raises(topoloc.MapIOError):
        topoloc.evaluate_trajectory_files("/nonexistent/a.txt", "/nonexistent/b.txt")


needs_data = pytest.mark.skipif(
    not TRAJECTORIES.is_dir(),
    reason=f"{TRAJECTORIES} is absent: the real-trajectory agreement is not checked",
)

REAL = [
    # (reference, estimate, reader, format, alignment)
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt", "tum", "se3"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-ORB_kf_mono.txt", "tum", "sim3"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", "tum", "se3"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB_kf_mono.txt", "tum", "sim3"),
    ("KITTI_00_gt.txt", "KITTI_00_ORB.txt", "kitti", "se3"),
    ("KITTI_00_gt.txt", "KITTI_00_SPTAM.txt", "kitti", "sim3"),
]


@needs_data
@pytest.mark.parametrize("reference, estimate, fmt, alignment", REAL)
def test_real_trajectories_agree_with_evo(reference, estimate, fmt, alignment):
    ref_path, est_path = TRAJECTORIES / reference, TRAJECTORIES / estimate
    if fmt == "tum":
        ref, est = (
            file_interface.read_tum_trajectory_file(ref_path),
            file_interface.read_tum_trajectory_file(est_path),
        )
    else:
        # KITTI files are frame-indexed: evo pairs them by index, as frame-index timestamps do.
        stamps = lambda p: np.arange(p.num_poses, dtype=float)  # noqa: E731
        ref_path_, est_path_ = (
            file_interface.read_kitti_poses_file(ref_path),
            file_interface.read_kitti_poses_file(est_path),
        )
        ref = evo_trajectory.PoseTrajectory3D(
            poses_se3=ref_path_.poses_se3, timestamps=stamps(ref_path_)
        )
        est = evo_trajectory.PoseTrajectory3D(
            poses_se3=est_path_.poses_se3, timestamps=stamps(est_path_)
        )
    report = topoloc.evaluate_trajectory_files(ref_path, est_path, format=fmt, alignment=alignment)
    assert_agrees(report, evo_figures(ref, est, alignment))
    # The TUM rows of evo's own reading give the same figures through the array entry point.
    if fmt == "tum":
        again = topoloc.evaluate_trajectory(rows(ref), rows(est), alignment=alignment)
        assert again.ate_m.rmse == pytest.approx(report.ate_m.rmse, abs=1e-9)


@needs_data
def test_euroc_ground_truth_agrees_with_evo():
    ref_path, est_path = TRAJECTORIES / "V102_groundtruth.csv", TRAJECTORIES / "V102.txt"
    ref = file_interface.read_euroc_csv_trajectory(ref_path)
    est = file_interface.read_tum_trajectory_file(est_path)
    # Each file's format is detected: EuRoC CSV and TUM.
    report = topoloc.evaluate_trajectory_files(ref_path, est_path, alignment="se3")
    assert_agrees(report, evo_figures(ref, est, "se3"))
