"""Trajectory metrics (ABI 1.11; mirrors ``src/ffi/trajectory.rs``): :func:`evaluate_trajectory`,
:func:`evaluate_trajectory_files`, :class:`TrajectoryReport` and :class:`ErrorStats`.
"""

from __future__ import annotations

from ctypes import byref
from dataclasses import dataclass
from typing import Any, Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import PathLike, _f64_ptr, _from_struct, _matrix, _path
from ._errors import InvalidArgumentError, InvalidOptionError, check
from ._lib import lib
from ._options import OptionTable, choice, defaults, real, unsigned

__all__ = ["ErrorStats", "TrajectoryReport", "evaluate_trajectory", "evaluate_trajectory_files"]

#: ``alignment`` names -> ``TOPOLOC_ALIGN_*``.
_ALIGNMENTS = {"none": _lib.ALIGN_NONE, "se3": _lib.ALIGN_SE3, "sim3": _lib.ALIGN_SIM3}
#: ``format`` names of :func:`evaluate_trajectory_files` -> ``TOPOLOC_TRAJECTORY_*``.
_TRAJECTORY_FORMATS = {
    None: _lib.TRAJECTORY_DETECT,
    "tum": _lib.TRAJECTORY_TUM,
    "kitti": _lib.TRAJECTORY_KITTI,
    "euroc": _lib.TRAJECTORY_EUROC,
}

#: The options of :func:`evaluate_trajectory`: the fields of ``topoloc_trajectory_options``.
TRAJECTORY_OPTIONS = OptionTable(
    "trajectory",
    _lib.topoloc_trajectory_options,
    lib.topoloc_trajectory_options_init,
    InvalidOptionError,
    [
        choice("alignment", _ALIGNMENTS),
        real("max_diff_s"),
        real("offset_s"),
        unsigned("rpe_delta"),
    ],
)


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
    alignment: NDArray[np.float64]
    ate_m: ErrorStats
    are_deg: ErrorStats
    rpe_m: ErrorStats
    rpe_deg: ErrorStats
    estimate_length_m: float
    reference_length_m: float
    length_ratio: float


def _trajectory_report(r: Any) -> TrajectoryReport:
    errors = ("ate_m", "are_deg", "rpe_m", "rpe_deg")
    stats = {name: _from_struct(ErrorStats, getattr(r, name)) for name in errors}
    return _from_struct(TrajectoryReport, r, alignment=_matrix(r.alignment, 4), **stats)


def _tum_rows(values: Any, name: str) -> NDArray[np.float64]:
    rows = np.ascontiguousarray(values, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 8:
        raise InvalidArgumentError(
            f"{name} must be an (N, 8) array of timestamp tx ty tz qx qy qz qw, "
            f"got shape {rows.shape}"
        )
    return rows


def evaluate_trajectory(
    reference: ArrayLike,
    estimate: ArrayLike,
    *,
    alignment: Optional[Union[str, int]] = None,
    max_diff_s: Optional[float] = None,
    offset_s: Optional[float] = None,
    rpe_delta: Optional[int] = None,
) -> TrajectoryReport:
    """Judges ``estimate`` against ``reference`` as ``evo_ape`` / ``evo_rpe`` do
    (``topoloc_trajectory_evaluate``): pairs poses by timestamps, aligns the estimate and
    returns ATE, ARE, RPE and R_traj.

    Each trajectory is an (N, 8) array, TUM's rows ``timestamp tx ty tz qx qy qz qw``
    (``world_T_body``; timestamps not decreasing). Options are keyword-only, named as the
    fields of ``topoloc_trajectory_options`` in ``topoloc.h``, which documents each one's
    default and range; left out or ``None``: the library's default. ``alignment``:
    ``"none"``, ``"se3"`` or ``"sim3"`` (Umeyama with scale); ``max_diff_s``: the largest
    timestamp difference of a pair; ``offset_s``: added to the estimate's timestamps;
    ``rpe_delta``: the pose step of the RPE.

    Raises :class:`InvalidArgumentError` (shapes, decreasing timestamps, a quaternion not of
    norm 1, no associated pair, too few, degenerate positions), :class:`NonFiniteError`,
    :class:`InvalidOptionError`. Thread-safe.
    """
    options = TRAJECTORY_OPTIONS.fill(TRAJECTORY_OPTIONS.pick(locals()))
    ref = _tum_rows(reference, "reference")
    est = _tum_rows(estimate, "estimate")
    ref_t, ref_p = np.ascontiguousarray(ref[:, 0]), np.ascontiguousarray(ref[:, 1:])
    est_t, est_p = np.ascontiguousarray(est[:, 0]), np.ascontiguousarray(est[:, 1:])
    report = defaults(_lib.topoloc_trajectory_report, lib.topoloc_trajectory_report_init)
    check(
        lib.topoloc_trajectory_evaluate(
            _f64_ptr(ref_t),
            _f64_ptr(ref_p),
            ref.shape[0],
            _f64_ptr(est_t),
            _f64_ptr(est_p),
            est.shape[0],
            byref(options),
            byref(report),
        )
    )
    return _trajectory_report(report)


def evaluate_trajectory_files(
    reference_path: PathLike,
    estimate_path: PathLike,
    format: Optional[str] = None,
    *,
    alignment: Optional[Union[str, int]] = None,
    max_diff_s: Optional[float] = None,
    offset_s: Optional[float] = None,
    rpe_delta: Optional[int] = None,
) -> TrajectoryReport:
    """:func:`evaluate_trajectory` of two files (``topoloc_trajectory_evaluate_files``) in
    ``format`` ``"tum"``, ``"kitti"`` (frame index as timestamp) or ``"euroc"``; ``None``
    detects each file's format from its first data line. Options as for
    :func:`evaluate_trajectory`. Raises :class:`MapIOError` (an unreadable file) and
    :class:`InvalidArgumentError` (a malformed line, named in the message) besides those of
    :func:`evaluate_trajectory`."""
    options = TRAJECTORY_OPTIONS.fill(TRAJECTORY_OPTIONS.pick(locals()))
    if format not in _TRAJECTORY_FORMATS:
        raise InvalidArgumentError(
            f"format must be one of tum, kitti, euroc or None, not {format!r}"
        )
    report = defaults(_lib.topoloc_trajectory_report, lib.topoloc_trajectory_report_init)
    check(
        lib.topoloc_trajectory_evaluate_files(
            _path(reference_path, "reference_path"),
            _path(estimate_path, "estimate_path"),
            _TRAJECTORY_FORMATS[format],
            byref(options),
            byref(report),
        )
    )
    return _trajectory_report(report)
