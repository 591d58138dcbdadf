"""Trajectory metrics (ABI 1.11; mirrors ``src/ffi/trajectory.rs``): :func:`evaluate_trajectory`,
:func:`evaluate_trajectory_files`, :class:`TrajectoryReport` and :class:`ErrorStats`.
"""

from __future__ import annotations

from ctypes import byref
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
from numpy.typing import ArrayLike

from . import _lib
from ._errors import (
    InvalidArgumentError,
    InvalidOptionError,
)
from ._errors import check
from ._lib import lib
from ._options import defaults
from ._convert import PathLike, _f64_ptr, _matrix, _path, _u32

__all__ = ['ErrorStats', 'TrajectoryReport', 'evaluate_trajectory', 'evaluate_trajectory_files']


#: ``alignment`` names of :func:`evaluate_trajectory` -> ``TOPOLOC_ALIGN_*``.
_ALIGNMENTS = {"none": _lib.ALIGN_NONE, "se3": _lib.ALIGN_SE3, "sim3": _lib.ALIGN_SIM3}


#: ``format`` names of :func:`evaluate_trajectory_files` -> ``TOPOLOC_TRAJECTORY_*``.
_TRAJECTORY_FORMATS = {
    None: _lib.TRAJECTORY_DETECT,
    "tum": _lib.TRAJECTORY_TUM,
    "kitti": _lib.TRAJECTORY_KITTI,
    "euroc": _lib.TRAJECTORY_EUROC,
}


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of one error over the associated poses (``topoloc_error_stats``)."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float


@dataclass(frozen=True)
class TrajectoryReport:
    """What :func:`evaluate_trajectory` measured (``topoloc_trajectory_report``).

    Attributes:
        pairs: associated pose pairs.
        scale: the alignment's scale (1 unless ``alignment="sim3"``).
        alignment: (4, 4) float64 rotation and translation of the alignment: an aligned
            estimate position is ``scale * R @ p + t``.
        ate_m, are_deg: position (metres) and rotation (degrees) errors of the aligned poses.
        rpe_m, rpe_deg: the same of the motion over ``rpe_delta`` poses.
        estimate_length_m, reference_length_m: path lengths (the estimate aligned).
        length_ratio: R_traj, ``estimate_length_m / reference_length_m``.
    """

    pairs: int
    scale: float
    alignment: np.ndarray
    ate_m: ErrorStats
    are_deg: ErrorStats
    rpe_m: ErrorStats
    rpe_deg: ErrorStats
    estimate_length_m: float
    reference_length_m: float
    length_ratio: float


def _trajectory_options(alignment: str, max_diff_s: float, offset_s: float, rpe_delta: int):
    if alignment not in _ALIGNMENTS:
        raise InvalidOptionError(f"alignment must be one of {sorted(_ALIGNMENTS)}, not {alignment!r}")
    o = defaults(_lib.topoloc_trajectory_options, lib.topoloc_trajectory_options_init)
    o.alignment = _ALIGNMENTS[alignment]
    o.max_diff_s = float(max_diff_s)
    o.offset_s = float(offset_s)
    o.rpe_delta = _u32(rpe_delta, "rpe_delta", InvalidOptionError)
    return o


def _trajectory_report(r: Any) -> TrajectoryReport:
    stats = lambda s: ErrorStats(s.rmse, s.mean, s.median, s.std, s.min, s.max)  # noqa: E731
    return TrajectoryReport(
        pairs=int(r.pairs),
        scale=float(r.scale),
        alignment=_matrix(r.alignment, 4),
        ate_m=stats(r.ate_m),
        are_deg=stats(r.are_deg),
        rpe_m=stats(r.rpe_m),
        rpe_deg=stats(r.rpe_deg),
        estimate_length_m=float(r.estimate_length_m),
        reference_length_m=float(r.reference_length_m),
        length_ratio=float(r.length_ratio),
    )


def _tum_rows(values: Any, name: str) -> np.ndarray:
    rows = np.ascontiguousarray(values, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 8:
        raise InvalidArgumentError(f"{name} must be an (N, 8) array of timestamp tx ty tz qx qy qz qw, got shape {rows.shape}")
    return rows


def evaluate_trajectory(
    reference: ArrayLike,
    estimate: ArrayLike,
    alignment: str = "sim3",
    max_diff_s: float = 0.01,
    offset_s: float = 0.0,
    rpe_delta: int = 1,
) -> TrajectoryReport:
    """Judges ``estimate`` against ``reference`` as ``evo_ape`` / ``evo_rpe`` do
    (``topoloc_trajectory_evaluate``): pairs by timestamps (within ``max_diff_s``, the
    estimate shifted by ``offset_s``), aligns (``"none"``, ``"se3"`` or ``"sim3"``, the
    default: Umeyama with scale) and returns ATE, ARE, RPE and R_traj.

    Each trajectory is an (N, 8) array, TUM's rows ``timestamp tx ty tz qx qy qz qw``
    (``world_T_body``; timestamps not decreasing). Raises :class:`InvalidArgumentError`
    (shapes, decreasing timestamps, a quaternion not of norm 1, no associated pair, too few,
    degenerate positions), :class:`NonFiniteError`, :class:`InvalidOptionError`. Thread-safe.
    """
    ref = _tum_rows(reference, "reference")
    est = _tum_rows(estimate, "estimate")
    o = _trajectory_options(alignment, max_diff_s, offset_s, rpe_delta)
    ref_t, ref_p = np.ascontiguousarray(ref[:, 0]), np.ascontiguousarray(ref[:, 1:])
    est_t, est_p = np.ascontiguousarray(est[:, 0]), np.ascontiguousarray(est[:, 1:])
    report = defaults(_lib.topoloc_trajectory_report, lib.topoloc_trajectory_report_init)
    check(
        lib.topoloc_trajectory_evaluate(
            _f64_ptr(ref_t), _f64_ptr(ref_p), ref.shape[0],
            _f64_ptr(est_t), _f64_ptr(est_p), est.shape[0],
            byref(o), byref(report),
        )
    )
    return _trajectory_report(report)


def evaluate_trajectory_files(
    reference_path: PathLike,
    estimate_path: PathLike,
    format: Optional[str] = None,
    alignment: str = "sim3",
    max_diff_s: float = 0.01,
    offset_s: float = 0.0,
    rpe_delta: int = 1,
) -> TrajectoryReport:
    """:func:`evaluate_trajectory` of two files (``topoloc_trajectory_evaluate_files``) in
    ``format`` ``"tum"``, ``"kitti"`` (frame index as timestamp) or ``"euroc"``; ``None``
    detects each file's format from its first data line. Raises :class:`MapIOError` (an
    unreadable file) and :class:`InvalidArgumentError` (a malformed line, named in the
    message) besides those of :func:`evaluate_trajectory`."""
    if format not in _TRAJECTORY_FORMATS:
        raise InvalidArgumentError(f"format must be one of tum, kitti, euroc or None, not {format!r}")
    o = _trajectory_options(alignment, max_diff_s, offset_s, rpe_delta)
    report = defaults(_lib.topoloc_trajectory_report, lib.topoloc_trajectory_report_init)
    check(
        lib.topoloc_trajectory_evaluate_files(
            _path(reference_path, "reference_path"), _path(estimate_path, "estimate_path"),
            _TRAJECTORY_FORMATS[format], byref(o), byref(report),
        )
    )
    return _trajectory_report(report)
