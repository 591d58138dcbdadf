"""Localization (mirrors ``src/ffi/localizer.rs``): :class:`Localizer`, its options, and the
result types :class:`Result`, :class:`Candidate` and :class:`PoseFix`.
"""

from __future__ import annotations

import ctypes
import os
from ctypes import byref
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Union

import numpy as np
from numpy.typing import ArrayLike

from . import _lib
from ._errors import (
    InvalidOptionError,
)
from ._errors import check
from ._lib import lib
from ._options import defaults
from ._convert import PathLike, _IMAGE_BACKENDS, _backend_code, _backend_name, _descriptor, _f32_ptr, _f64_ptr, _image, _matrix, _path, _pose, _text, _u32
from ._handles import _SingleThreaded
from ._map import Map

__all__ = ['Candidate', 'PoseFix', 'Result', 'localizer_options_default', 'Localizer']


@dataclass(frozen=True)
class Candidate:
    """One ranked hypothesis: ``place``, its best-matching ``view``, the posterior
    ``probability`` of the place, and the cosine ``similarity`` of the frame to ``view``."""

    place: int
    view: int
    probability: float
    similarity: float


@dataclass(frozen=True, eq=False)
class PoseFix:
    """A metric pose of the camera for one frame (:attr:`Result.pose_fix`, ABI 1.6): the frame's
    keypoints matched to the scene points of a map view's keypoints
    (:meth:`Map.with_keypoint_points`) and placed by a perspective-n-point fit with RANSAC.

    Attributes:
        view: the view the camera was placed against.
        inliers: PnP RANSAC inliers of the fit (at least the localizer's ``pose_min_inliers``).
        world_T_camera: (4, 4) float64, the camera in the map frame (row-major ``[R t; 0 0 0 1]``,
            metres), camera axes optical (z forward, x right, y down). A pose graph adds it as a
            prior or loop constraint on the frame's pose.
    """

    view: int
    inliers: int
    world_T_camera: np.ndarray

    def __eq__(self, other: object) -> bool:
        """Equal view, inliers and pose (the arrays compared element by element)."""
        if not isinstance(other, PoseFix):
            return NotImplemented
        return (self.view, self.inliers) == (other.view, other.inliers) and bool(
            np.array_equal(self.world_T_camera, other.world_T_camera)
        )

    __hash__ = None  # type: ignore[assignment]  # holds an array


@dataclass(frozen=True)
class Result:
    """The answer for one frame (see :meth:`Localizer.process`).

    Attributes:
        frame_index: 0-based frame count since creation or :meth:`Localizer.reset`.
        place: most probable place.
        view: best-matching view of that place.
        confidence: posterior probability of being at ``place`` (place belief x on-map
            probability).
        similarity: cosine similarity of the frame to ``view``.
        off_map: whether the robot is more likely off the map than on it.
        off_map_probability: posterior probability of the off-map state.
        candidates: the top-k places, best first (``candidates[0].place == place``).
        verified: whether ``place`` was verified geometrically in this frame (localizers made
            with ``verify_candidates`` > 0).
        inliers: RANSAC inliers between the frame and ``view`` (0 unless ``verified``): with
            ``place`` and ``view``, the evidence for a loop closure.
        pose_fix: the camera's metric pose against the best-verified view (a :class:`PoseFix`),
            or ``None``: localizers made with camera intrinsics and verification on a map whose
            keypoints carry scene points report one when at least ``pose_min_inliers``
            keypoints agree (ABI 1.6).
    """

    frame_index: int
    place: int
    view: int
    confidence: float
    similarity: float
    off_map: bool
    off_map_probability: float
    candidates: List[Candidate] = field(default_factory=list)
    verified: bool = False
    inliers: int = 0
    pose_fix: Optional[PoseFix] = None


_MODES = {"filter": _lib.MODE_FILTER, "single_frame": _lib.MODE_SINGLE_FRAME, "metric": _lib.MODE_METRIC}


_OPTION_FIELDS = (
    "temperature",
    "stay_probability",
    "jump_probability",
    "off_map_probability",
    "off_map_similarity",
    "off_map_margin",
)


#: Pinhole intrinsics of the localizer's camera (ABI 1.6), pixels; ``camera_fx == 0``: none.
_CAMERA_FIELDS = ("camera_fx", "camera_fy", "camera_cx", "camera_cy")


def localizer_options_default() -> Dict[str, Any]:
    """The library's default localizer options (``topoloc_localizer_options_init``) as a dict
    with keys ``mode`` ("filter"/"single_frame"/"metric"), the float options, ``top_k``,
    ``expected_kind``, ``expected_model``, ``image_backend`` ("auto"), ``onnx_model_path`` and
    ``onnx_runtime_path`` (``None``: the library's search), ``verify_candidates`` (0: off),
    ``verify_views_per_candidate``, ``verify_inlier_weight``, ``metric_particles``,
    ``metric_temperature``, ``metric_seed``, the camera intrinsics ``camera_fx``,
    ``camera_fy``, ``camera_cx``, ``camera_cy`` (``camera_fx == 0``: no camera, no pose fixes)
    and ``pose_min_inliers`` (ABI 1.6), ``verify_off_map_inliers`` (negative: the map's feature
    kind's default) and ``verify_off_map_inlier_scale`` (ABI 1.9)."""
    o = defaults(_lib.topoloc_localizer_options, lib.topoloc_localizer_options_init)
    return _options_dict(o)


def _options_dict(o: _lib.topoloc_localizer_options) -> Dict[str, Any]:
    modes = {v: k for k, v in _MODES.items()}
    out: Dict[str, Any] = {"mode": modes.get(o.mode, o.mode)}
    out.update({name: float(getattr(o, name)) for name in _OPTION_FIELDS})
    out["top_k"] = int(o.top_k)
    out["expected_kind"] = (o.expected_descriptor_kind or b"").decode("utf-8") or None
    out["expected_model"] = (o.expected_descriptor_model or b"").decode("utf-8") or None
    out["image_backend"] = _backend_name(o.image_backend, _IMAGE_BACKENDS)
    out["onnx_model_path"] = os.fsdecode(o.onnx_model_path) if o.onnx_model_path else None
    out["onnx_runtime_path"] = os.fsdecode(o.onnx_runtime_path) if o.onnx_runtime_path else None
    out["verify_candidates"] = int(o.verify_candidates)
    out["verify_views_per_candidate"] = int(o.verify_views_per_candidate)
    out["verify_inlier_weight"] = float(o.verify_inlier_weight)
    out["metric_particles"] = int(o.metric_particles)
    out["metric_temperature"] = float(o.metric_temperature)
    out["metric_seed"] = int(o.metric_seed)
    out.update({name: float(getattr(o, name)) for name in _CAMERA_FIELDS})
    out["pose_min_inliers"] = int(o.pose_min_inliers)
    out["verify_off_map_inliers"] = float(o.verify_off_map_inliers)
    out["verify_off_map_inlier_scale"] = float(o.verify_off_map_inlier_scale)
    return out


class Localizer(_SingleThreaded):
    """Follows one camera through a :class:`Map`, one frame at a time.

    ``mode``: ``"filter"`` (forward filter over the graph; timestamps must not decrease),
    ``"single_frame"`` (every frame judged on its own) or ``"metric"`` (Monte Carlo
    localization of the camera pose, moved by the frames' ``odometry`` and weighed by
    appearance; needs a map with every place's position and every view's pose, else
    :class:`InvalidOptionError`; ``metric_particles``, ``metric_temperature`` and
    ``metric_seed`` tune it). Every other option left as ``None``
    takes the library default (:func:`localizer_options_default`): ``temperature`` (> 0),
    ``stay_probability`` (persistence of the off-map state), ``jump_probability``,
    ``off_map_probability`` (0 disables off-map),
    ``off_map_similarity``, ``off_map_margin``, ``top_k`` (candidates per frame, >= 1).
    ``expected_kind`` / ``expected_model`` refuse maps built with another descriptor
    (:class:`DescriptorMismatchError`). Invalid options raise :class:`InvalidOptionError`.

    Images: a map built from images (:meth:`Map.build_from_images`) stores its describer.
    ``image_backend`` says how image frames are described: ``"auto"`` (default) loads the
    map's describer when it has one (for ONNX maps: ONNX Runtime and the model, now); ``"none"``
    never (descriptor frames only, nothing loaded; image frames raise
    :class:`NoDescriberError`); ``"onnx"``, ``"vlad-orb"`` or ``"vlad-sift"`` require the map's
    describer to be that backend (:class:`DescriptorMismatchError` otherwise,
    :class:`NoDescriberError` for a map without describer). ``onnx_model_path`` /
    ``onnx_runtime_path`` override where the ONNX model (which must be the very file the map
    was built with) and runtime are found. Loading fails with
    :class:`BackendUnavailableError` or :class:`ModelError`.

    Geometric verification (off by default): ``verify_candidates`` (0..64) most probable places
    are checked each frame against the frame's image (ORB matches and RANSAC on each place's
    ``verify_views_per_candidate`` most similar views; the belief of a place with n inliers is
    multiplied by ``exp(verify_inlier_weight * n)``); the result reports ``verified`` and
    ``inliers``. It needs a map built from images (they store keypoints; otherwise
    :class:`InvalidOptionError`) and image frames (:class:`InvalidImageError` for a descriptor
    frame). With verification on, the off-map flag (ABI 1.9) reads the inliers instead of
    appearance: a frame whose best checked place has ``verify_off_map_inliers`` inliers is as
    likely off the map as on it, each ``verify_off_map_inlier_scale`` fewer (or more) multiply
    the odds by e. ``verify_off_map_inliers`` negative (default): the map's feature kind's
    threshold (XFeat and cells 26, ORB 0); 0: appearance decides.

    Pose fixes (ABI 1.6, off by default): with verification on and the pinhole intrinsics of
    the frames' camera, ``camera_fx``, ``camera_fy``, ``camera_cx``, ``camera_cy`` (pixels of
    the images as passed, undistorted; ``camera_fx == 0``: none; focal lengths finite and > 0,
    principal point finite), on a map whose keypoints carry scene points
    (:meth:`Map.with_keypoint_points`; otherwise :class:`InvalidOptionError`), the
    best-verified view places the camera metrically: the result's ``pose_fix`` (a
    :class:`PoseFix`) when at least ``pose_min_inliers`` (6..10000) keypoints agree.

    Ownership: owns a C ``topoloc_localizer`` handle, released by :meth:`close`, the ``with``
    statement or garbage collection. The localizer keeps its own reference to the map data, so
    the :class:`Map` may be closed while the localizer is in use.

    Thread safety: single-threaded state (one camera); use from one thread at a time
    (concurrent calls raise ``RuntimeError``). Many localizers may share one map, each in its
    own thread; :meth:`process` releases the GIL while it runs.
    """

    def __init__(
        self,
        map: Map,
        mode: Union[str, int] = "filter",
        temperature: Optional[float] = None,
        stay_probability: Optional[float] = None,
        jump_probability: Optional[float] = None,
        off_map_probability: Optional[float] = None,
        off_map_similarity: Optional[float] = None,
        off_map_margin: Optional[float] = None,
        top_k: Optional[int] = None,
        expected_kind: Optional[str] = None,
        expected_model: Optional[str] = None,
        image_backend: Union[str, int] = "auto",
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        verify_candidates: Optional[int] = None,
        verify_views_per_candidate: Optional[int] = None,
        verify_inlier_weight: Optional[float] = None,
        metric_particles: Optional[int] = None,
        metric_temperature: Optional[float] = None,
        metric_seed: Optional[int] = None,
        camera_fx: Optional[float] = None,
        camera_fy: Optional[float] = None,
        camera_cx: Optional[float] = None,
        camera_cy: Optional[float] = None,
        pose_min_inliers: Optional[int] = None,
        verify_off_map_inliers: Optional[float] = None,
        verify_off_map_inlier_scale: Optional[float] = None,
    ) -> None:
        self._init_guard()
        self._free = lib.topoloc_localizer_free
        if not isinstance(map, Map):
            raise TypeError(f"map must be a topoloc.Map, got {type(map).__name__}")
        options = defaults(_lib.topoloc_localizer_options, lib.topoloc_localizer_options_init)
        if isinstance(mode, str):
            if mode not in _MODES:
                raise InvalidOptionError(f"mode must be 'filter', 'single_frame' or 'metric', got {mode!r}")
            options.mode = _MODES[mode]
        else:
            options.mode = _u32(mode, "mode", InvalidOptionError)
        given = {
            "temperature": temperature,
            "stay_probability": stay_probability,
            "jump_probability": jump_probability,
            "off_map_probability": off_map_probability,
            "off_map_similarity": off_map_similarity,
            "off_map_margin": off_map_margin,
            "camera_fx": camera_fx,
            "camera_fy": camera_fy,
            "camera_cx": camera_cx,
            "camera_cy": camera_cy,
            "verify_off_map_inliers": verify_off_map_inliers,
            "verify_off_map_inlier_scale": verify_off_map_inlier_scale,
        }
        for name, value in given.items():
            if value is not None:
                setattr(options, name, float(value))
        if top_k is not None:
            options.top_k = _u32(top_k, "top_k", InvalidOptionError)
        options.expected_descriptor_kind = _text(expected_kind, "expected_kind")
        options.expected_descriptor_model = _text(expected_model, "expected_model")
        options.image_backend = _backend_code(image_backend, _IMAGE_BACKENDS, "image_backend", InvalidOptionError)
        if onnx_model_path is not None:
            options.onnx_model_path = _path(onnx_model_path, "onnx_model_path")
        if onnx_runtime_path is not None:
            options.onnx_runtime_path = _path(onnx_runtime_path, "onnx_runtime_path")
        if verify_candidates is not None:
            options.verify_candidates = _u32(verify_candidates, "verify_candidates", InvalidOptionError)
        if verify_views_per_candidate is not None:
            options.verify_views_per_candidate = _u32(
                verify_views_per_candidate, "verify_views_per_candidate", InvalidOptionError
            )
        if verify_inlier_weight is not None:
            options.verify_inlier_weight = float(verify_inlier_weight)
        if metric_particles is not None:
            options.metric_particles = _u32(metric_particles, "metric_particles", InvalidOptionError)
        if metric_temperature is not None:
            options.metric_temperature = float(metric_temperature)
        if metric_seed is not None:
            if not isinstance(metric_seed, int) or not 0 <= metric_seed < 2**64:
                raise InvalidOptionError(f"metric_seed must be an integer in [0, 2**64), got {metric_seed!r}")
            options.metric_seed = metric_seed
        if pose_min_inliers is not None:
            options.pose_min_inliers = _u32(pose_min_inliers, "pose_min_inliers", InvalidOptionError)

        out = _lib.LocalizerPtr()
        check(lib.topoloc_localizer_new(map._h, byref(options), byref(out)))
        self._ptr = out
        self._options = _options_dict(options)
        self._map = map

        # Reused per frame: the candidate buffer, the frame and the result.
        capacity = max(1, min(int(options.top_k), map.place_count))
        self._candidates = (_lib.topoloc_candidate * capacity)()
        self._result = defaults(_lib.topoloc_result, lib.topoloc_result_init)
        self._frame = defaults(_lib.topoloc_frame, lib.topoloc_frame_init)

    @property
    def options(self) -> Dict[str, Any]:
        """The options this localizer was created with (floats as the library stores them, in
        single precision)."""
        return dict(self._options)

    @property
    def map(self) -> Map:
        """The :class:`Map` given at creation (possibly closed since; the localizer does not
        need it)."""
        return self._map

    def process(
        self,
        descriptor: Optional[ArrayLike] = None,
        timestamp: Optional[float] = None,
        odometry: Optional[ArrayLike] = None,
        *,
        image: Optional[ArrayLike] = None,
        pixel_format: Optional[str] = None,
    ) -> Result:
        """Localizes one frame, given either its descriptor or its camera image.

        ``descriptor``: the frame's global descriptor, D floats (any 1-D array-like; normalised
        by the library). ``image`` (keyword, instead of ``descriptor``): the camera image as a
        uint8 array, (H, W) grey or (H, W, 3) / (H, W, 4) colour, described with the map's
        describer (the localizer needs one: see the class documentation). ``pixel_format``:
        ``"rgb"`` (default for 3 channels), ``"bgr"`` (OpenCV), ``"rgba"`` (default for 4) or
        ``"bgra"``. Arrays with contiguous rows (e.g. crops) are read in place with their row
        stride, others are copied; the pixels are only read during the call.

        ``timestamp``: seconds (required); must not decrease in filter mode (call :meth:`reset`
        to start a new sequence). ``odometry``: optional motion since the previous frame,
        ``previous_T_current``, a 4x4 rigid transform.

        The whole frame is validated first: on any error the localizer state is unchanged (the
        next successful frame continues the sequence). Raises :class:`DimensionMismatchError`,
        :class:`NonFiniteError`, :class:`ZeroDescriptorError`, :class:`TimestampError`,
        :class:`InvalidArgumentError` (odometry not a rigid transform); for images
        ``TypeError`` (not uint8), :class:`InvalidImageError` (shape, size: the library accepts
        1..8192 pixels a side), :class:`UninformativeImageError` (blank or featureless image),
        :class:`NoDescriberError`, :class:`ModelError`.
        """
        if timestamp is None:
            raise TypeError("process() needs a timestamp")
        if image is None:
            if descriptor is None:
                raise TypeError("process() needs a descriptor or an image")
            if pixel_format is not None:
                raise TypeError("pixel_format is only meaningful with an image")
            q = _descriptor(descriptor)
            img, pixels = None, None
        else:
            if descriptor is not None:
                raise TypeError("give process() either a descriptor or an image, not both")
            q = None
            img, pixels = _image(image, pixel_format, "image")
        odo = None if odometry is None else _pose(odometry, "odometry")
        ts = float(timestamp)
        h = self._enter("process")
        try:
            frame, result = self._frame, self._result
            frame.struct_size = ctypes.sizeof(_lib.topoloc_frame)
            frame.timestamp = ts
            if q is not None:
                frame.descriptor = _f32_ptr(q)
                frame.descriptor_len = q.size
            if img is not None:
                frame.image = img
            frame.odometry = None if odo is None else _f64_ptr(odo)
            result.struct_size = ctypes.sizeof(_lib.topoloc_result)
            result.candidates = self._candidates
            result.candidates_capacity = len(self._candidates)
            try:
                check(lib.topoloc_localizer_process(h, byref(frame), byref(result)))
            finally:
                frame.descriptor = None
                frame.descriptor_len = 0
                frame.odometry = None
                frame.image = _lib.topoloc_image()
            n = min(int(result.candidates_len), len(self._candidates))
            candidates = [
                Candidate(int(c.place), int(c.view), float(c.probability), float(c.similarity))
                for c in self._candidates[:n]
            ]
            return Result(
                frame_index=int(result.frame_index),
                place=int(result.place),
                view=int(result.view),
                confidence=float(result.confidence),
                similarity=float(result.similarity),
                off_map=bool(result.off_map),
                off_map_probability=float(result.off_map_probability),
                candidates=candidates,
                verified=bool(result.verified),
                inliers=int(result.inliers),
                pose_fix=_pose_fix(result),
            )
        finally:
            self._leave()
            del q, odo, pixels

    def reset(self) -> None:
        """Forgets all history: the next frame is treated as the first (frame_index 0, any
        timestamp accepted)."""
        h = self._enter("reset")
        try:
            check(lib.topoloc_localizer_reset(h))
        finally:
            self._leave()


def _pose_fix(result: _lib.topoloc_result) -> Optional[PoseFix]:
    """The :class:`PoseFix` of a filled ``topoloc_result``, or ``None`` without one."""
    if not result.has_pose_fix:
        return None
    return PoseFix(
        view=int(result.pose_fix_view),
        inliers=int(result.pose_fix_inliers),
        world_T_camera=_matrix(result.world_T_camera, 4),
    )
