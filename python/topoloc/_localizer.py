"""Localization (mirrors ``src/ffi/localizer.rs``): :class:`Localizer`, its options, and the
result types :class:`Result`, :class:`Candidate` and :class:`PoseFix`.
"""

from __future__ import annotations

import ctypes
from ctypes import byref
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import (
    _IMAGE_BACKENDS,
    PathLike,
    _descriptor,
    _f32_ptr,
    _f64_ptr,
    _from_struct,
    _image,
    _matrix,
    _pose,
    _real,
)
from ._errors import InvalidOptionError, check
from ._handles import _SingleThreaded
from ._lib import lib
from ._map import Map, _map_handle
from ._options import OptionTable, choice, defaults, file_path, real, text, unsigned, unsigned64

__all__ = ["Candidate", "Localizer", "PoseFix", "Result", "localizer_options_default"]


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
    world_T_camera: NDArray[np.float64]

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


#: ``mode`` names -> ``TOPOLOC_MODE_*``.
_MODES = {
    "filter": _lib.MODE_FILTER,
    "single_frame": _lib.MODE_SINGLE_FRAME,
    "metric": _lib.MODE_METRIC,
    "grnn": _lib.MODE_GRNN,
}

#: The :class:`Localizer` options: the fields of ``topoloc_localizer_options``.
LOCALIZER_OPTIONS = OptionTable(
    "localizer",
    _lib.topoloc_localizer_options,
    lib.topoloc_localizer_options_init,
    InvalidOptionError,
    [
        choice("mode", _MODES),
        real("temperature"),
        real("stay_probability"),
        real("jump_probability"),
        real("off_map_probability"),
        real("off_map_similarity"),
        real("off_map_margin"),
        unsigned("top_k"),
        text("expected_descriptor_kind", name="expected_kind"),
        text("expected_descriptor_model", name="expected_model"),
        choice("image_backend", _IMAGE_BACKENDS),
        file_path("onnx_model_path"),
        file_path("onnx_runtime_path"),
        unsigned("verify_candidates"),
        unsigned("verify_views_per_candidate"),
        real("verify_inlier_weight"),
        unsigned("metric_particles"),
        real("metric_temperature"),
        unsigned64("metric_seed"),
        real("camera_fx"),
        real("camera_fy"),
        real("camera_cx"),
        real("camera_cy"),
        unsigned("pose_min_inliers"),
        real("verify_off_map_inliers"),
        real("verify_off_map_inlier_scale"),
        file_path("grnn_model_path"),
    ],
)


def localizer_options_default() -> Dict[str, Any]:
    """The library's default :class:`Localizer` options (``topoloc_localizer_options_init``)
    as a dict keyed by the option names: enum codes by their names (``mode``,
    ``image_backend``), unset strings and paths as ``None``. ``topoloc.h`` documents each on
    its ``topoloc_localizer_options`` field."""
    return LOCALIZER_OPTIONS.default_values()


class Localizer(_SingleThreaded):
    """Follows one camera through a :class:`Map`, one frame at a time.

    Options are keyword-only, named as the fields of ``topoloc_localizer_options`` in
    ``topoloc.h`` (``expected_kind`` and ``expected_model`` for ``expected_descriptor_kind``
    and ``expected_descriptor_model``), where each field documents its default and range. An
    option left out or ``None`` keeps the library's default (:func:`localizer_options_default`).
    A value out of range raises :class:`InvalidOptionError`, one of the wrong type
    ``TypeError``.

    - ``mode``: ``"filter"`` (a forward filter over the graph; timestamps must not decrease),
      ``"single_frame"`` (every frame judged on its own) or ``"metric"`` (Monte Carlo
      localization of the camera pose, moved by the frames' ``odometry`` and weighed by
      appearance, tuned by ``metric_particles``, ``metric_temperature`` and ``metric_seed``;
      it needs a map with every place's position and every view's pose, else
      :class:`InvalidOptionError`), ``"grnn"`` (ABI 1.16: the seed's learned graph recurrent
      network, run through ONNX Runtime on a window of the map's views; the model is
      ``grnn_model_path``'s, or the one built into the library; it needs ONNX Runtime, else
      :class:`BackendUnavailableError`, and a map with edges, else :class:`InvalidOptionError`;
      a model file that is not ONNX or breaks the contract raises :class:`ModelError`), or a
      ``TOPOLOC_MODE_*`` code. See ``topoloc_localizer_options.mode``.
    - The filter's ``temperature``, ``stay_probability``, ``jump_probability``,
      ``off_map_probability``, ``off_map_similarity`` and ``off_map_margin``, and ``top_k``,
      the candidates reported per frame: see the fields of the same names.
    - ``expected_kind`` / ``expected_model`` refuse maps built with another descriptor
      (:class:`DescriptorMismatchError`).
    - Images: a map built from images (:meth:`Map.build_from_images`) stores its describer.
      ``image_backend`` says how image frames are described: ``"auto"`` loads the map's
      describer when it has one (for ONNX maps: ONNX Runtime and the model, now); ``"none"``
      never (descriptor frames only, nothing loaded; image frames raise
      :class:`NoDescriberError`); ``"onnx"``, ``"vlad-orb"`` or ``"vlad-sift"`` require the
      map's describer to be that backend (:class:`DescriptorMismatchError` otherwise,
      :class:`NoDescriberError` for a map without describer). ``onnx_model_path`` /
      ``onnx_runtime_path`` override where the ONNX model (the very file the map was built
      with) and runtime are found. Loading fails with :class:`BackendUnavailableError` or
      :class:`ModelError`. See ``topoloc_localizer_options.image_backend``.
    - Geometric verification: ``verify_candidates`` selects how many of the most probable
      places are checked each frame against the frame's image: the local features the map
      stores for the place's ``verify_views_per_candidate`` most similar views (ORB, XFeat or
      dense cells, as the map was built) are matched to the frame's and a RANSAC geometric
      model is fitted; the inliers weigh the place's belief (``verify_inlier_weight``) and are
      reported (:attr:`Result.verified`, :attr:`Result.inliers`). It needs a map that stores
      keypoints (maps built from images do; otherwise :class:`InvalidOptionError`) and image
      frames (:class:`InvalidImageError` for a descriptor frame). With it, the off-map flag
      reads the inliers instead of appearance (ABI 1.9: ``verify_off_map_inliers``,
      ``verify_off_map_inlier_scale``). See ``topoloc_localizer_options.verify_candidates``
      and the fields after it.
    - Pose fixes (ABI 1.6): with verification on and the pinhole intrinsics of the frames'
      camera, ``camera_fx``, ``camera_fy``, ``camera_cx``, ``camera_cy`` (pixels of the
      images as passed, undistorted), on a map whose keypoints carry scene points
      (:meth:`Map.with_keypoint_points`; otherwise :class:`InvalidOptionError`), the
      best-verified view places the camera metrically: the result's ``pose_fix`` (a
      :class:`PoseFix`) when at least ``pose_min_inliers`` keypoints agree. See
      ``topoloc_localizer_options.camera_fx``.

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
        *,
        mode: Optional[Union[str, int]] = None,
        temperature: Optional[float] = None,
        stay_probability: Optional[float] = None,
        jump_probability: Optional[float] = None,
        off_map_probability: Optional[float] = None,
        off_map_similarity: Optional[float] = None,
        off_map_margin: Optional[float] = None,
        top_k: Optional[int] = None,
        expected_kind: Optional[str] = None,
        expected_model: Optional[str] = None,
        image_backend: Optional[Union[str, int]] = None,
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
        grnn_model_path: Optional[PathLike] = None,
    ) -> None:
        given = LOCALIZER_OPTIONS.pick(locals())
        handle = _map_handle(map)
        options = LOCALIZER_OPTIONS.fill(given)
        free, new = lib.topoloc_localizer_free, lib.topoloc_localizer_new
        self._open(free, _lib.LocalizerPtr, new, handle, byref(options))
        self._options = LOCALIZER_OPTIONS.read(options)
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
            img, _pixels = None, None
        else:
            if descriptor is not None:
                raise TypeError("give process() either a descriptor or an image, not both")
            q = None
            img, _pixels = _image(image, pixel_format, "image")
        odo = None if odometry is None else _pose(odometry, "odometry")
        ts = _real(timestamp, "timestamp")
        # q, odo and _pixels (locals, alive until the call returns) hold what the frame points to.
        with self._using("process") as h:
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
            candidates = [_from_struct(Candidate, c) for c in self._candidates[:n]]
            return _from_struct(Result, result, candidates=candidates, pose_fix=_pose_fix(result))

    def reset(self) -> None:
        """Forgets all history: the next frame is treated as the first (frame_index 0, any
        timestamp accepted)."""
        self._call("reset", lib.topoloc_localizer_reset)


def _pose_fix(result: _lib.topoloc_result) -> Optional[PoseFix]:
    """The :class:`PoseFix` of a filled ``topoloc_result``, or ``None`` without one."""
    if not result.has_pose_fix:
        return None
    return PoseFix(
        view=int(result.pose_fix_view),
        inliers=int(result.pose_fix_inliers),
        world_T_camera=_matrix(result.world_T_camera, 4),
    )
