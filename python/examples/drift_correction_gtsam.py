#!/usr/bin/env python3
"""Drift correction with topoloc loop-closure hints and a GTSAM pose graph.

A ``topoloc simulate --depth`` sequence (``images/``, ``depth/``, ``odometry.txt``,
``groundtruth.txt``, ``intrinsics.json``) is run through a :class:`topoloc.LoopDetector`,
every frame a keyframe: the global descriptor comes from a :class:`topoloc.Describer` of a
map of *another* world (``--describer``; never fit the describer on the sequence you report),
the keypoints from OpenCV ORB with their scene points from the depth image. The accepted
hints become loop factors of a pose graph over the drifting odometry, which GTSAM optimises.

Ground truth is used only to judge the result, never to build it: loops whose own covariance
is too wide to vouch for them are left out, and inconsistent loop factors are rejected by a
chi-square test on their whitened error after a robust (Cauchy) optimisation.

Usage::

    TOPOLOC_LIBRARY=target/release/libtopoloc.so PYTHONPATH=python \\
        python3 python/examples/drift_correction_gtsam.py \\
        --sequence /tmp/drift/test_0_dim/traj-000 --describer /tmp/drift/train_0/map.topoloc \\
        --out drift.png

Exit codes: 0 done, 2 missing files or bad data (the message says which).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import cv2
import gtsam
import numpy as np

import topoloc

#: The camera's optical frame (x right, y down, z forward) in the body frame (x forward,
#: y left, z up): camera x = body -y, camera y = body -z, camera z = body x; no offset.
BODY_T_CAMERA = np.array(
    [
        [0.0, 0.0, 1.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0],
        [0.0, -1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
)

#: Depth image units per metre (16-bit PNG in millimetres).
DEPTH_SCALE = 1000.0
#: ORB keypoints per keyframe.
ORB_FEATURES = 1000
#: Contrast-limited adaptive histogram equalisation of the grey image before ORB (clip limit,
#: tiles): dim and night frames otherwise give a few hundred corners, and few loops.
CLAHE_CLIP = 2.0
CLAHE_TILES = (8, 8)

#: Odometry noise per step, as standard deviations (GTSAM Pose3 tangent order: rotation
#: x y z in rad, translation x y z in m). The simulated odometry drifts by about 1 % of the
#: distance (scale), 0.1 deg/s of yaw bias and a random walk of 2 mrad/sqrt(s) in yaw and
#: 1 cm/sqrt(m) in translation. A step at 2 Hz covers about 0.3 m in 0.5 s: about 2 mrad of
#: yaw and 6-9 mm of translation. The sigmas are about twice that (the bias and the scale
#: error are correlated over many steps, which a per-step white model understates), with
#: roll and pitch tighter (the odometry stays level).
ODOMETRY_SIGMA_ROT_RAD_PER_SQRT_S = (0.001, 0.001, 0.005)
ODOMETRY_SIGMA_TRANS_M_PER_SQRT_M = (0.02, 0.02, 0.01)
#: Floors of the per-step sigmas (a robot standing still still drifts a little).
ODOMETRY_SIGMA_FLOOR = (2e-4, 2e-4, 5e-4, 2e-3, 2e-3, 2e-3)

#: Smallest variance of a loop hint's covariance (rad^2 or m^2): about 3 mrad or 3 mm of
#: sigma, so that a near-singular estimate cannot pin the graph.
MIN_LOOP_VARIANCE = 1e-5
#: Largest standard deviation of a loop constraint (along any rotation / translation
#: direction of its covariance) that enters the graph: a tenth of the 5 deg / 0.5 m a loop may
#: be off before it is wrong, so that a kept loop is certified by its own covariance even if
#: that is a few times optimistic. Wider hints (few inliers, far points) are statistically
#: consistent with the graph even when several degrees off, and no chi-square test catches
#: them; the precise ones left carry nearly all the information anyway.
MAX_LOOP_SIGMA_ROT_RAD = math.radians(0.5)
MAX_LOOP_SIGMA_TRANS_M = 0.05
#: Cauchy kernel scale of the loop factors (whitened units, i.e. sigmas).
CAUCHY_K = 3.0
#: 99.9 % quantile of the chi-square distribution with 6 degrees of freedom: a loop factor
#: whose squared Mahalanobis error after optimisation exceeds it is inconsistent.
CHI2_6DOF_999 = 22.458
#: Rejection rounds (optimise, drop inconsistent loops) at most.
MAX_REJECTION_ROUNDS = 10

#: Ground-truth judgement of a loop constraint: false beyond these errors.
FALSE_LOOP_DEG = 5.0
FALSE_LOOP_M = 0.5


class DemoError(Exception):
    """Missing files or bad data: reported on stderr with exit code 2."""


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of the sequence's camera (pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float


@dataclass(frozen=True, eq=False)
class Loop:
    """A loop constraint between the body poses of keyframes ``old`` and ``cur``:
    ``old_T_cur`` and its (6, 6) covariance in the body frame (GTSAM Pose3 tangent order)."""

    old: int
    cur: int
    old_T_cur: np.ndarray
    covariance: np.ndarray
    inliers: int


@dataclass
class FrontEnd:
    """What the loop detector gave over the sequence, and how long it took."""

    keyframes: int
    hints_accepted: int
    loops: List[Loop]
    seconds: float
    detector_seconds: float


@dataclass
class Solution:
    """The optimised trajectory and the loop constraints: ``imprecise`` (left out of the
    graph), ``dropped`` (inconsistent with the optimised graph), ``used``."""

    poses: List[np.ndarray]
    used: List[Loop]
    dropped: List[Loop]
    imprecise: List[Loop]
    seconds: float


# ---------------------------------------------------------------------------------------------
# Reading the sequence
# ---------------------------------------------------------------------------------------------


def require_file(path: Path) -> Path:
    """``path`` when it is a file; :class:`DemoError` otherwise."""
    if not path.is_file():
        raise DemoError(f"missing file: {path}")
    return path


def read_tum(path: Path) -> np.ndarray:
    """The (N, 8) rows ``t tx ty tz qx qy qz qw`` of a TUM trajectory file."""
    rows = []
    for number, line in enumerate(require_file(path).read_text().splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            values = []
        if len(values) != 8 or not all(math.isfinite(v) for v in values):
            raise DemoError(
                f"{path}:{number}: expected 8 numbers 't tx ty tz qx qy qz qw', got {line!r}"
            )
        if abs(np.linalg.norm(values[4:]) - 1.0) > 1e-3:
            raise DemoError(f"{path}:{number}: quaternion is not of unit norm")
        rows.append(values)
    if not rows:
        raise DemoError(f"{path}: no poses")
    return np.array(rows)


def read_intrinsics(path: Path) -> Intrinsics:
    """The camera of ``intrinsics.json`` (``width height fx fy cx cy``)."""
    try:
        data = json.loads(require_file(path).read_text())
        intrinsics = Intrinsics(
            int(data["width"]),
            int(data["height"]),
            float(data["fx"]),
            float(data["fy"]),
            float(data["cx"]),
            float(data["cy"]),
        )
    except (ValueError, KeyError, TypeError) as e:
        raise DemoError(
            f"{path}: not an intrinsics file with width height fx fy cx cy ({e})"
        ) from e
    if min(intrinsics.fx, intrinsics.fy, intrinsics.width, intrinsics.height) <= 0:
        raise DemoError(f"{path}: focal lengths and image size must be positive")
    return intrinsics


def read_image(path: Path, flags: int, what: str) -> np.ndarray:
    """The pixels of image file ``path`` read with OpenCV ``flags``."""
    image = cv2.imread(str(require_file(path)), flags)
    if image is None:
        raise DemoError(f"{path}: not a readable {what} image")
    return image


def read_depth(path: Path, intrinsics: Intrinsics) -> np.ndarray:
    """The depth image of ``path`` in metres (NaN where it has none)."""
    raw = read_image(path, cv2.IMREAD_UNCHANGED, "depth")
    if raw.dtype != np.uint16 or raw.shape != (intrinsics.height, intrinsics.width):
        raise DemoError(
            f"{path}: expected a 16-bit {intrinsics.width}x{intrinsics.height} depth PNG, "
            f"got {raw.dtype} {raw.shape}"
        )
    depth = raw.astype(np.float64) / DEPTH_SCALE
    depth[raw == 0] = np.nan
    return depth


def read_frame(sequence: Path, name: str, intrinsics: Intrinsics) -> Tuple[np.ndarray, np.ndarray]:
    """Frame ``name`` of ``sequence``: its BGR image and its depth in metres."""
    path = sequence / "images" / name
    image = read_image(path, cv2.IMREAD_COLOR, "colour")
    if image.shape[:2] != (intrinsics.height, intrinsics.width):
        raise DemoError(
            f"{path}: {image.shape[1]}x{image.shape[0]}, but intrinsics.json says "
            f"{intrinsics.width}x{intrinsics.height}"
        )
    return image, read_depth(sequence / "depth" / name, intrinsics)


def sequence_frames(sequence: Path, count: int) -> List[str]:
    """The file names of the first ``count`` images (one per odometry pose), each with its
    depth image."""
    images = sorted(p.name for p in (sequence / "images").glob("*.png"))
    if len(images) < count:
        raise DemoError(
            f"{sequence / 'images'}: {len(images)} PNG images for {count} odometry poses"
        )
    for name in images[:count]:
        require_file(sequence / "depth" / name)
    return images[:count]


# ---------------------------------------------------------------------------------------------
# Poses
# ---------------------------------------------------------------------------------------------


def tum_matrix(row: np.ndarray) -> np.ndarray:
    """The 4x4 ``world_T_body`` of a TUM row."""
    qx, qy, qz, qw = row[4:8]
    rotation = gtsam.Rot3.Quaternion(qw, qx, qy, qz).matrix()
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = row[1:4]
    return m


def tum_rows(timestamps: np.ndarray, poses: Sequence[np.ndarray]) -> np.ndarray:
    """TUM rows of 4x4 poses."""
    rows = []
    for t, m in zip(timestamps, poses):
        q = gtsam.Rot3(m[:3, :3]).toQuaternion()
        rows.append([t, *m[:3, 3], q.x(), q.y(), q.z(), q.w()])
    return np.array(rows)


def relative_error(estimate: np.ndarray, reference: np.ndarray) -> Tuple[float, float]:
    """(degrees, metres) between two relative poses: the rotation angle of
    ``reference^-1 estimate`` and the distance of their translations."""
    delta = np.linalg.inv(reference) @ estimate
    cos = np.clip((np.trace(delta[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return math.degrees(math.acos(cos)), float(np.linalg.norm(estimate[:3, 3] - reference[:3, 3]))


# ---------------------------------------------------------------------------------------------
# Front end: keyframes into the loop detector
# ---------------------------------------------------------------------------------------------


def keyframe_features(
    image: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics, orb: cv2.ORB
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ORB ``(keypoints (N, 2), descriptors (N, 32) uint8, camera points (N, 3))`` of a
    BGR image (its grey levels equalised: ``CLAHE_*``), each keypoint's scene point
    back-projected from ``depth`` (NaN rows where the depth image has none)."""
    grey = cv2.createCLAHE(CLAHE_CLIP, CLAHE_TILES).apply(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    found, descriptors = orb.detectAndCompute(grey, None)
    if descriptors is None or not found:
        return np.zeros((0, 2)), np.zeros((0, 32), np.uint8), np.zeros((0, 3))
    uv = np.array([k.pt for k in found], dtype=np.float64)
    cols = np.clip(np.rint(uv[:, 0]).astype(int), 0, intrinsics.width - 1)
    rows = np.clip(np.rint(uv[:, 1]).astype(int), 0, intrinsics.height - 1)
    z = depth[rows, cols]
    points = np.column_stack(
        [
            (uv[:, 0] - intrinsics.cx) * z / intrinsics.fx,
            (uv[:, 1] - intrinsics.cy) * z / intrinsics.fy,
            z,
        ]
    )
    return uv, descriptors, points


def loop_from_hint(hint: topoloc.LoopHint) -> Loop:
    """The body-frame loop constraint of an accepted, metric hint.

    ``old_T_cur = B M B^-1`` (B = body_T_camera, M = matched_T_query); a right perturbation
    ``M exp(xi)`` is ``old_T_cur exp(Ad_B xi)``, so the covariance turns with ``Ad_B``.
    """
    old_T_cur = BODY_T_CAMERA @ hint.matched_T_query @ np.linalg.inv(BODY_T_CAMERA)
    adjoint = gtsam.Pose3(BODY_T_CAMERA).AdjointMap()
    covariance = adjoint @ hint.covariance @ adjoint.T
    return Loop(hint.matched_id, hint.query_id, old_T_cur, covariance, hint.inliers)


def accepted_hints(
    detector: topoloc.LoopDetector, hint: topoloc.LoopHint
) -> List[topoloc.LoopHint]:
    """The hints accepted by the last ``add``: its own and the earlier keyframes' it
    confirmed."""
    hints = [hint] if hint.accepted else []
    return hints + [h for h in detector.confirmed() if h.accepted]


def run_front_end(
    sequence: Path, describer_map: Path, odometry: np.ndarray, intrinsics: Intrinsics
) -> FrontEnd:
    """Every frame of ``sequence`` (as many as ``odometry`` has rows) as a keyframe of a loop
    detector; the accepted hints with a metric pose as :class:`Loop` s."""
    frames = sequence_frames(sequence, len(odometry))
    orb = cv2.ORB_create(nfeatures=ORB_FEATURES)
    hints: Dict[int, topoloc.LoopHint] = {}
    detector_seconds = 0.0
    start = time.perf_counter()
    with topoloc.Map.load(require_file(describer_map)) as m:  # neither keeps the map
        describer = topoloc.Describer(m)
        detector = topoloc.LoopDetector(
            m.descriptor_kind,
            m.descriptor_model,
            m.dim,
            fx=intrinsics.fx,
            fy=intrinsics.fy,
            cx=intrinsics.cx,
            cy=intrinsics.cy,
        )
    with describer, detector:
        for kid, (name, row) in enumerate(zip(frames, odometry)):
            image, depth = read_frame(sequence, name, intrinsics)
            keypoints, descriptors, points = keyframe_features(image, depth, intrinsics, orb)
            t0 = time.perf_counter()
            hint = detector.add(
                kid,
                row[0],
                describer.describe(image, pixel_format="bgr"),
                keypoints=keypoints,
                keypoint_descriptors=descriptors,
                camera_points=points,
                world_T_body=tum_matrix(row),
                body_T_camera=BODY_T_CAMERA,
            )
            for h in accepted_hints(detector, hint):
                hints[h.query_id] = h
            detector_seconds += time.perf_counter() - t0
    seconds = time.perf_counter() - start
    metric = [h for h in hints.values() if h.has_pose and h.scale_known]
    loops = [loop_from_hint(h) for h in sorted(metric, key=lambda h: h.query_id)]
    return FrontEnd(len(frames), len(hints), loops, seconds, detector_seconds)


# ---------------------------------------------------------------------------------------------
# Back end: the pose graph
# ---------------------------------------------------------------------------------------------


def odometry_noise(step: np.ndarray, seconds: float) -> gtsam.noiseModel.Base:
    """Diagonal noise of one odometry step (``step``: its 4x4 relative pose, ``seconds``
    long): rotation sigmas grow with the square root of time, translation sigmas with the
    square root of the distance (see ``ODOMETRY_SIGMA_*``)."""
    metres = float(np.linalg.norm(step[:3, 3]))
    sigmas = np.concatenate(
        [
            np.array(ODOMETRY_SIGMA_ROT_RAD_PER_SQRT_S) * math.sqrt(max(seconds, 0.0)),
            np.array(ODOMETRY_SIGMA_TRANS_M_PER_SQRT_M) * math.sqrt(metres),
        ]
    )
    return gtsam.noiseModel.Diagonal.Sigmas(np.maximum(sigmas, ODOMETRY_SIGMA_FLOOR))


def loop_gaussian(loop: Loop) -> gtsam.noiseModel.Gaussian:
    """The Gaussian noise of a loop constraint: its covariance, symmetrised, checked positive
    definite, with eigenvalues floored at ``MIN_LOOP_VARIANCE``."""
    covariance = 0.5 * (loop.covariance + loop.covariance.T)
    if not np.all(np.isfinite(covariance)):
        raise DemoError(f"loop {loop.old}-{loop.cur}: covariance is not finite")
    values, vectors = np.linalg.eigh(covariance)
    if values.min() <= 0.0:
        raise DemoError(
            f"loop {loop.old}-{loop.cur}: covariance is not positive definite "
            f"(eigenvalues {values})"
        )
    floored = (vectors * np.maximum(values, MIN_LOOP_VARIANCE)) @ vectors.T
    return gtsam.noiseModel.Gaussian.Covariance(floored)


def is_precise(loop: Loop) -> bool:
    """Whether the loop's covariance is within ``MAX_LOOP_SIGMA_ROT_RAD`` and
    ``MAX_LOOP_SIGMA_TRANS_M`` in every direction."""
    rotation = np.linalg.eigvalsh(loop.covariance[:3, :3]).max()
    translation = np.linalg.eigvalsh(loop.covariance[3:, 3:]).max()
    return rotation <= MAX_LOOP_SIGMA_ROT_RAD**2 and translation <= MAX_LOOP_SIGMA_TRANS_M**2


def loop_factor(loop: Loop, robust: bool) -> gtsam.BetweenFactorPose3:
    """The loop's factor, with a Cauchy kernel when ``robust``."""
    noise = loop_gaussian(loop)
    if robust:
        noise = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(CAUCHY_K), noise
        )
    return gtsam.BetweenFactorPose3(loop.old, loop.cur, gtsam.Pose3(loop.old_T_cur), noise)


def odometry_graph(
    timestamps: np.ndarray, odometry: Sequence[np.ndarray]
) -> gtsam.NonlinearFactorGraph:
    """The prior on keyframe 0 and the odometry factors between consecutive keyframes."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(
        gtsam.PriorFactorPose3(
            0, gtsam.Pose3(odometry[0]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)
        )
    )
    for k in range(1, len(odometry)):
        step = np.linalg.inv(odometry[k - 1]) @ odometry[k]
        noise = odometry_noise(step, float(timestamps[k] - timestamps[k - 1]))
        graph.add(gtsam.BetweenFactorPose3(k - 1, k, gtsam.Pose3(step), noise))
    return graph


def optimise(
    base: gtsam.NonlinearFactorGraph, loops: Sequence[Loop], initial: gtsam.Values
) -> gtsam.Values:
    """Levenberg-Marquardt on the odometry graph plus the robust loop factors."""
    graph = gtsam.NonlinearFactorGraph(base)
    for loop in loops:
        graph.add(loop_factor(loop, robust=True))
    return gtsam.LevenbergMarquardtOptimizer(
        graph, initial, gtsam.LevenbergMarquardtParams()
    ).optimize()


def mahalanobis_squared(loop: Loop, values: gtsam.Values) -> float:
    """The loop factor's squared whitened error (without kernel) at ``values``."""
    return 2.0 * loop_factor(loop, robust=False).error(values)


def solve(
    timestamps: np.ndarray, odometry: Sequence[np.ndarray], loops: Sequence[Loop]
) -> Solution:
    """Optimises the pose graph with the precise loops (:func:`is_precise`), then drops the
    loops inconsistent with the solution (squared whitened error above ``CHI2_6DOF_999``) and
    re-optimises, until every kept loop is consistent."""
    start = time.perf_counter()
    base = odometry_graph(timestamps, odometry)
    initial = gtsam.Values()
    for k, pose in enumerate(odometry):
        initial.insert(k, gtsam.Pose3(pose))
    used = [loop for loop in loops if is_precise(loop)]
    imprecise = [loop for loop in loops if not is_precise(loop)]
    dropped: List[Loop] = []
    values = optimise(base, used, initial)
    for _ in range(MAX_REJECTION_ROUNDS):
        bad = [loop for loop in used if mahalanobis_squared(loop, values) > CHI2_6DOF_999]
        if not bad:
            break
        dropped += bad
        used = [loop for loop in used if loop not in bad]
        values = optimise(base, used, initial)
    else:
        raise DemoError(f"loop rejection did not settle in {MAX_REJECTION_ROUNDS} rounds")
    poses = [values.atPose3(k).matrix() for k in range(len(odometry))]
    return Solution(poses, used, dropped, imprecise, time.perf_counter() - start)


# ---------------------------------------------------------------------------------------------
# Judging with ground truth, reporting, plotting
# ---------------------------------------------------------------------------------------------


def is_false(loop: Loop, truth: Sequence[np.ndarray]) -> bool:
    """Whether the loop's relative pose is off the ground truth's by more than
    ``FALSE_LOOP_DEG`` or ``FALSE_LOOP_M``."""
    degrees, metres = relative_error(
        loop.old_T_cur, np.linalg.inv(truth[loop.old]) @ truth[loop.cur]
    )
    return degrees > FALSE_LOOP_DEG or metres > FALSE_LOOP_M


def ate(reference: np.ndarray, estimate: np.ndarray) -> topoloc.TrajectoryReport:
    """Sim3-aligned trajectory report of ``estimate`` against ``reference`` (TUM rows)."""
    return topoloc.evaluate_trajectory(reference=reference, estimate=estimate, alignment="sim3")


def aligned_xy(report: topoloc.TrajectoryReport, rows: np.ndarray) -> np.ndarray:
    """The x-y positions of TUM ``rows`` under the report's Sim3 alignment."""
    r, t = report.alignment[:3, :3], report.alignment[:3, 3]
    return (report.scale * rows[:, 1:4] @ r.T + t)[:, :2]


def plot(
    path: Path,
    truth: np.ndarray,
    raw: np.ndarray,
    corrected: np.ndarray,
    reports: Tuple[topoloc.TrajectoryReport, topoloc.TrajectoryReport],
    solution: Solution,
) -> None:
    """Top view of ground truth, raw odometry and corrected trajectory (both Sim3-aligned to
    the ground truth), with the loops used (thin green), dropped (red) and left out (grey)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 8))
    ax.plot(truth[:, 1], truth[:, 2], "k-", lw=1.5, label="ground truth")
    raw_xy, corrected_xy = aligned_xy(reports[0], raw), aligned_xy(reports[1], corrected)
    ax.plot(raw_xy[:, 0], raw_xy[:, 1], "-", color="tab:orange", lw=1, label="raw odometry")
    ax.plot(corrected_xy[:, 0], corrected_xy[:, 1], "-", color="tab:blue", lw=1, label="corrected")
    loop_sets = (
        (solution.used, "tab:green", "loop used"),
        (solution.dropped, "tab:red", "loop dropped (inconsistent)"),
        (solution.imprecise, "tab:grey", "loop left out (imprecise)"),
    )
    for loops, colour, label in loop_sets:
        for i, loop in enumerate(loops):
            ends = corrected_xy[[loop.old, loop.cur]]
            ax.plot(
                ends[:, 0], ends[:, 1], "-", color=colour, lw=0.4, label=label if i == 0 else None
            )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        f"ATE RMSE: raw {reports[0].ate_m.rmse:.2f} m, corrected {reports[1].ate_m.rmse:.2f} m"
    )
    ax.legend(loc="best")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def summary(
    front: FrontEnd,
    solution: Solution,
    truth: Sequence[np.ndarray],
    reports: Tuple[topoloc.TrajectoryReport, topoloc.TrajectoryReport],
) -> Dict[str, float]:
    """The figures of the run (the keys of ``--json``)."""
    raw, corrected = reports[0].ate_m.rmse, reports[1].ate_m.rmse
    return {
        "keyframes": front.keyframes,
        "hints_accepted": front.hints_accepted,
        "loop_constraints": len(front.loops),
        "loop_factors_used": len(solution.used),
        "loop_factors_dropped": len(solution.dropped),
        "loops_imprecise": len(solution.imprecise),
        "false_used": sum(is_false(loop, truth) for loop in solution.used),
        "false_dropped": sum(is_false(loop, truth) for loop in solution.dropped),
        "false_imprecise": sum(is_false(loop, truth) for loop in solution.imprecise),
        "ate_raw_m": raw,
        "ate_corrected_m": corrected,
        "ate_ratio": corrected / raw if raw > 0 else float("nan"),
        "ms_per_keyframe": 1000.0 * front.seconds / front.keyframes,
        "detector_ms_per_keyframe": 1000.0 * front.detector_seconds / front.keyframes,
        "optimisation_ms": 1000.0 * solution.seconds,
    }


def print_text(figures: Dict[str, float]) -> None:
    """The figures as aligned text lines."""
    labels = {
        "keyframes": "keyframes",
        "hints_accepted": "hints accepted by topoloc",
        "loop_constraints": "loop constraints (metric hints)",
        "loop_factors_used": "loop factors used",
        "loop_factors_dropped": "loop factors dropped (inconsistent)",
        "loops_imprecise": "loops left out (covariance too wide)",
        "false_used": "false among used",
        "false_dropped": "false among dropped",
        "false_imprecise": "false among left out",
        "ate_raw_m": "ATE RMSE raw odometry (m, Sim3)",
        "ate_corrected_m": "ATE RMSE corrected (m, Sim3)",
        "ate_ratio": "corrected / raw",
        "ms_per_keyframe": "time per keyframe (ms, all front end)",
        "detector_ms_per_keyframe": "  of which topoloc describe + add (ms)",
        "optimisation_ms": "pose graph with rejection (ms)",
    }
    for key, label in labels.items():
        value = figures[key]
        print(f"{label:<40} {value:.3f}" if isinstance(value, float) else f"{label:<40} {value}")


def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    """Command-line options."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--sequence", type=Path, required=True, help="a `topoloc simulate --depth` traj-00i folder"
    )
    p.add_argument(
        "--describer", type=Path, required=True, help="a map built from images of another world"
    )
    p.add_argument("--out", type=Path, help="write a top-view PNG here")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--max-keyframes", type=int, help="use only the first N frames")
    return p.parse_args(argv)


def run(args: argparse.Namespace) -> Dict[str, float]:
    """The whole demo; returns the figures."""
    if not args.sequence.is_dir():
        raise DemoError(f"missing sequence folder: {args.sequence}")
    if args.max_keyframes is not None and args.max_keyframes < 2:
        raise DemoError("--max-keyframes must be at least 2")
    odometry_rows = read_tum(args.sequence / "odometry.txt")[: args.max_keyframes]
    truth_rows = read_tum(args.sequence / "groundtruth.txt")
    if len(truth_rows) < len(odometry_rows) or not np.allclose(
        truth_rows[: len(odometry_rows), 0], odometry_rows[:, 0]
    ):
        raise DemoError(f"{args.sequence}: groundtruth.txt and odometry.txt timestamps differ")
    truth_rows = truth_rows[: len(odometry_rows)]
    intrinsics = read_intrinsics(args.sequence / "intrinsics.json")

    front = run_front_end(args.sequence, args.describer, odometry_rows, intrinsics)
    odometry = [tum_matrix(r) for r in odometry_rows]
    truth = [tum_matrix(r) for r in truth_rows]
    solution = solve(odometry_rows[:, 0], odometry, front.loops)
    corrected_rows = tum_rows(odometry_rows[:, 0], solution.poses)
    reports = (ate(truth_rows, odometry_rows), ate(truth_rows, corrected_rows))
    if args.out is not None:
        plot(args.out, truth_rows, odometry_rows, corrected_rows, reports, solution)
    return summary(front, solution, truth, reports)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point: 0 on success, 2 on missing files or bad data."""
    args = parse_args(argv)
    try:
        figures = run(args)
    except (DemoError, topoloc.TopolocError) as e:
        print(f"drift_correction_gtsam: error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(figures))
    else:
        print_text(figures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
