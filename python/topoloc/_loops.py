"""Loop closure (ABI 1.5; mirrors ``src/ffi/loops.rs``, image keyframes ``src/ffi/loop_images.rs``):
:class:`LoopDetector`, its options, :class:`LoopHint`, :class:`LoopCandidate`, :class:`Gate`
and :class:`Translation`.
"""

from __future__ import annotations

import ctypes
import enum
from ctypes import byref, c_size_t, c_uint64
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Type, TypeVar, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import (
    PathLike,
    _descriptor,
    _f32_ptr,
    _f64_ptr,
    _from_struct,
    _image,
    _keypoint_array,
    _matrix,
    _out_call,
    _path,
    _pose,
    _real,
    _text,
    _u8_ptr,
    _u32,
    _u64,
)
from ._errors import InvalidArgumentError, InvalidOptionError, check
from ._handles import _SingleThreaded
from ._keyframes import KeyframeDescriber, LoopCandidateCheck, _depth_image, _describer_handle
from ._lib import lib
from ._map import Map, _map_handle
from ._options import OptionTable, choice, defaults, flag, real, unsigned, unsigned64

__all__ = [
    "Gate",
    "LoopCandidate",
    "LoopDetector",
    "LoopHint",
    "Translation",
    "loop_options_default",
]


class Gate(enum.IntEnum):
    """Which gate decided a :class:`LoopHint` (``TOPOLOC_GATE_*``): why a candidate was
    refused, for logs."""

    #: Every gate passed: the hint is a loop closure.
    ACCEPTED = _lib.GATE_ACCEPTED
    #: No keyframe outside the exclusion window had features to verify.
    NO_CANDIDATE = _lib.GATE_NO_CANDIDATE
    #: The best candidate had fewer inliers than ``min_inliers``.
    TOO_FEW_INLIERS = _lib.GATE_TOO_FEW_INLIERS
    #: Too few consecutive keyframes agreed on the place (``consistent_keyframes``).
    INCONSISTENT = _lib.GATE_INCONSISTENT
    #: Intrinsics were given but no relative pose could be fitted (too few matches, no
    #: consensus, or a pure rotation).
    NO_POSE = _lib.GATE_NO_POSE
    #: The pose disagrees with the host's odometry beyond the bounds.
    ODOMETRY = _lib.GATE_ODOMETRY
    #: The candidate is the query's own image (every keypoint matched, no motion): the
    #: detector was started from a map of this run's own images instead of an earlier run's
    #: (ABI 1.17; the library also logs a warning).
    SELF_MATCH = _lib.GATE_SELF_MATCH


class Translation(enum.IntEnum):
    """What the translation of :attr:`LoopHint.matched_T_query` holds
    (``TOPOLOC_TRANSLATION_*``, ABI 1.17): which factor a pose graph adds."""

    #: No pose, or a rotation only: the translation is exactly zero (a rotation factor alone).
    NONE = _lib.TRANSLATION_NONE
    #: A unit direction: the scale is unknown (a direction factor).
    DIRECTION = _lib.TRANSLATION_DIRECTION
    #: Metres: the matched keyframe had scene points (a full between-factor).
    METRIC = _lib.TRANSLATION_METRIC


@dataclass(frozen=True, eq=False)
class LoopHint:
    """The answer of :meth:`LoopDetector.add` for one keyframe: its best verified loop
    candidate and the gate that decided (``topoloc_loop_hint``).

    Attributes:
        query_id: the query keyframe's id (the added one; a confirmed hint's earlier one).
        query_place: the place the query keyframe joined.
        has_match: whether a candidate was verified (the fields below describe it).
        accepted: whether every gate passed: a loop closure for the pose graph.
        gate: the :class:`Gate` that decided.
        matched_id: the matched keyframe's id.
        place: the matched keyframe's place.
        inliers: fundamental-matrix inliers between the two keyframes.
        confidence: the candidate's share of the inliers of all verified candidates (0..1).
        has_pose: whether ``matched_T_query`` and ``covariance`` are set (intrinsics given,
            pose fitted).
        scale_known: whether the translation is metric (the matched keyframe had scene
            points); otherwise it is a unit direction or, for a rotation only, zero:
            ``translation`` says which.
        matched_T_query: (4, 4) float64, the query camera in the matched camera's optical
            frame (z forward, x right, y down); the identity without a pose.
        covariance: (6, 6) float64 covariance of ``matched_T_query`` for a right
            perturbation, in GTSAM Pose3 tangent order: rotation (rad) x y z, then
            translation (m) x y z; zeros without a pose.
        translation: the :class:`Translation` that ``matched_T_query`` holds (metres, a unit
            direction, or none).
    """

    query_id: int
    query_place: int
    has_match: bool
    accepted: bool
    gate: Union[Gate, int]
    matched_id: int
    place: int
    inliers: int
    confidence: float
    has_pose: bool
    scale_known: bool
    matched_T_query: NDArray[np.float64]
    covariance: NDArray[np.float64]
    translation: Union[Translation, int]


@dataclass(frozen=True)
class LoopCandidate:
    """One relocalization candidate of :meth:`LoopDetector.query`: keyframe ``keyframe_id``,
    its ``place``, and the cosine ``similarity`` of the query to it."""

    keyframe_id: int
    place: int
    similarity: float


#: ``TOPOLOC_PAIR_ESTIMATOR_*`` by name: the estimator of a keyframe pair's geometric check.
_PAIR_ESTIMATORS = {
    "ransac": _lib.PAIR_ESTIMATOR_RANSAC,
    "magsac": _lib.PAIR_ESTIMATOR_MAGSAC,
    "usac_fast": _lib.PAIR_ESTIMATOR_USAC_FAST,
}

#: The :class:`LoopDetector` options: the fields of ``topoloc_loop_options``, by their names.
LOOP_OPTIONS = OptionTable(
    "loop detector",
    _lib.topoloc_loop_options,
    lib.topoloc_loop_options_init,
    InvalidOptionError,
    [
        unsigned("candidates"),
        unsigned64("exclude_recent_ids"),
        real("exclude_recent_s"),
        unsigned("min_inliers"),
        unsigned("consistent_keyframes"),
        flag("odometry_gate"),
        real("odometry_max_rotation_deg"),
        real("odometry_max_translation_m"),
        real("fx"),
        real("fy"),
        real("cx"),
        real("cy"),
        real("novelty_similarity"),
        real("place_spacing_m"),
        real("neighbour_radius_m"),
        unsigned64("candidate_id_gap"),
        real("odometry_max_translation_per_m"),
        real("pose_reprojection_px"),
        real("odometry_search_m"),
        unsigned("odometry_candidates"),
        real("max_match_pace"),
        real("match_pace_slack_s"),
        unsigned("refine_keyframes"),
        unsigned("pose_min_inliers"),
        choice("pair_estimator", _PAIR_ESTIMATORS),
        unsigned("pair_iterations"),
        real("pair_min_cosine"),
        choice("cells_pair_estimator", _PAIR_ESTIMATORS),
        unsigned("cells_pair_iterations"),
        real("cells_pair_min_cosine"),
    ],
)


def loop_options_default() -> Dict[str, Any]:
    """The library's default :class:`LoopDetector` options (``topoloc_loop_options_init``) as
    a dict keyed by the C field names, which ``topoloc.h`` documents."""
    return LOOP_OPTIONS.default_values()


def _binary_descriptors(values: Any, count: int) -> NDArray[np.uint8]:
    """The keypoints' 32-byte descriptors as a C-contiguous uint8 (N, 32) array."""
    if isinstance(values, (bytes, bytearray, memoryview)):
        flat = np.frombuffer(values, dtype=np.uint8)
        if flat.size % 32:
            raise InvalidArgumentError(
                f"keypoint_descriptors has {flat.size} bytes, not a multiple of 32"
            )
        arr = flat.reshape(-1, 32)
    else:
        arr = np.asarray(values)
        if arr.size and arr.dtype.kind not in "biu":
            raise TypeError(f"keypoint_descriptors must be uint8 bytes, got dtype {arr.dtype}")
        if arr.size and arr.dtype != np.uint8 and (arr.min() < 0 or arr.max() > 255):
            raise InvalidArgumentError("keypoint_descriptors values must be bytes in [0, 255]")
        if arr.ndim != 2 or arr.shape[1] != 32:
            raise InvalidArgumentError(
                f"keypoint_descriptors must be an (N, 32) array of bytes, got shape {arr.shape}"
            )
    if arr.shape[0] != count:
        raise InvalidArgumentError(
            f"keypoint_descriptors has {arr.shape[0]} rows but keypoints has {count}: "
            "one per keypoint"
        )
    return np.ascontiguousarray(arr, dtype=np.uint8)


class LoopDetector(_SingleThreaded):
    """Loop-closure hints for a SLAM run: keyframes in, at most one gated hint per keyframe out.

    ``LoopDetector(kind, model, dim, **options)`` starts an empty detector for global
    descriptors of ``kind`` / ``model`` (non-empty strings) and dimension ``dim``;
    :meth:`from_map` starts one whose first session is a saved map (a second session closes
    loops against it). Each :meth:`add` verifies the keyframe's loop candidates (keyframes
    outside the exclusion window) against its keypoints and gates the best one; the keyframe
    then joins the detector's place graph.

    Options are keyword arguments named as the fields of ``topoloc_loop_options`` in
    ``topoloc.h``, which documents each one's default and range; left out or ``None``: the
    library's default (:func:`loop_options_default`). They select how many candidates are
    verified per keyframe (``candidates``) outside the exclusion window (``exclude_recent_ids``,
    ``exclude_recent_s``, ``candidate_id_gap``), the gates (``min_inliers``,
    ``consistent_keyframes`` with its pace rule ``max_match_pace``, ``match_pace_slack_s``,
    the odometry gate ``odometry_gate``,
    ``odometry_max_rotation_deg``, ``odometry_max_translation_m``,
    ``odometry_max_translation_per_m``), the camera's pinhole intrinsics for relative poses
    (``fx``, ``fy``, ``cx``, ``cy``; without them hints carry no pose;
    ``pose_reprojection_px``), the place graph (``novelty_similarity``, ``place_spacing_m``,
    ``neighbour_radius_m``), the candidates the odometry adds (``odometry_candidates``,
    ``odometry_search_m``) and the verification itself (``refine_keyframes``,
    ``pose_min_inliers``, ``pair_estimator`` and ``cells_pair_estimator`` as ``"ransac"``,
    ``"magsac"`` or ``"usac_fast"``, ``pair_iterations``, ``pair_min_cosine``,
    ``cells_pair_iterations``, ``cells_pair_min_cosine``). A value out of range raises
    :class:`InvalidOptionError`, a value of the wrong type (a string for a flag) or an unknown
    name ``TypeError``.

    Keyframe ids count keyframes (0, 1, 2, ... or any increasing numbers), not camera frames:
    ``exclude_recent_ids`` and ``candidate_id_gap`` are in these units.

    Which constructor: a live run's first session starts empty (this constructor, or
    :meth:`for_descriptors_of` for the descriptors of an image map); to close loops against
    an earlier run, :meth:`save` that run's detector and start the next with :meth:`from_map`
    of the loaded map. A map built from this run's own images is not a session: each keyframe
    would match itself (refused as :attr:`Gate.SELF_MATCH`).

    Ownership: owns a C ``topoloc_loop_detector`` handle, released by :meth:`close`, the
    ``with`` statement or garbage collection. A map given to :meth:`from_map` is not kept.

    Thread safety: single-threaded state; use from one thread at a time (concurrent calls raise
    ``RuntimeError``).
    """

    def __init__(self, kind: str, model: str, dim: int, **options: Any) -> None:
        opts = LOOP_OPTIONS.fill(options)
        names = _text(kind, "kind"), _text(model, "model")
        d = _u32(dim, "dim")
        self._open_with(opts, d, lib.topoloc_loop_detector_new, *names, d)

    @classmethod
    def for_descriptors_of(cls, map: Map, **options: Any) -> LoopDetector:
        """An empty detector for the global descriptors of ``map`` (its kind, model and
        dimension): for a host that describes its keyframe images with a
        :class:`KeyframeDescriber` of the same map. The map is not kept. Options and errors as
        for the constructor."""
        return cls(map.descriptor_kind, map.descriptor_model, map.dim, **options)

    @classmethod
    def from_map(cls, map: Map, **options: Any) -> LoopDetector:
        """A detector whose first session is ``map``'s views (with their stored keypoints and,
        where known, scene points; e.g. a map written by :meth:`save` and read with
        :meth:`Map.load`): new keyframes, with ids above the map's, close loops against it.
        Options as for the constructor. Raises :class:`InvalidOptionError` (also a view
        without keyframe id), :class:`InvalidArgumentError` (keyframe ids not increasing)."""
        handle = _map_handle(map)
        self = cls.__new__(cls)
        opts = LOOP_OPTIONS.fill(options)
        self._open_with(opts, map.dim, lib.topoloc_loop_detector_from_map, handle)
        return self

    def _open_with(
        self, options: _lib.topoloc_loop_options, dim: int, new: Callable[..., int], *args: Any
    ) -> None:
        """Creates the detector with ``new(*args, &options, &detector)``."""
        free = lib.topoloc_loop_detector_free
        self._open(free, _lib.LoopDetectorPtr, new, *args, byref(options))
        self._options = LOOP_OPTIONS.read(options)
        self._dim = dim
        # Reused per keyframe.
        self._keyframe = defaults(_lib.topoloc_loop_keyframe, lib.topoloc_loop_keyframe_init)
        self._hint = defaults(_lib.topoloc_loop_hint, lib.topoloc_loop_hint_init)

    @property
    def options(self) -> Dict[str, Any]:
        """The options this detector was created with (as the library stores them)."""
        return dict(self._options)

    @property
    def dim(self) -> int:
        """Global descriptor dimension D."""
        return self._dim

    def __len__(self) -> int:
        """Number of keyframes held."""
        with self._using("__len__") as h:
            return int(_out_call(c_size_t, lib.topoloc_loop_detector_len, h).value)

    @property
    def next_id(self) -> int:
        """The smallest id the next keyframe may have (ABI 1.17): one above the largest id
        ever added or reloaded, 0 for an empty new detector. A host whose keyframe ids restart
        at 0 in a new run adds it to them after :meth:`from_map`. Raises
        :class:`InvalidArgumentError` once id ``2**64 - 1`` was added."""
        with self._using("next_id") as h:
            return int(_out_call(c_uint64, lib.topoloc_loop_detector_next_id, h).value)

    def __repr__(self) -> str:
        if self.closed:
            return "<topoloc.LoopDetector (closed)>"
        return f"<topoloc.LoopDetector dim={self._dim} keyframes={len(self)}>"

    def add(
        self,
        id: int,
        timestamp: float,
        descriptor: ArrayLike,
        keypoints: Optional[ArrayLike] = None,
        keypoint_descriptors: Optional[ArrayLike] = None,
        camera_points: Optional[ArrayLike] = None,
        world_T_body: Optional[ArrayLike] = None,
        body_T_camera: Optional[ArrayLike] = None,
    ) -> LoopHint:
        """Adds keyframe ``id`` and returns its :class:`LoopHint` (``has_match`` False when no
        candidate was verified; ``accepted`` True for a loop closure).

        ``id``: the host's keyframe id, increasing from one keyframe to the next.
        ``timestamp``: seconds, not decreasing. ``descriptor``: the global descriptor, D floats.
        ``keypoints``: (N, 2) pixel positions (x right, y down; N <= 5000) with
        ``keypoint_descriptors``, their (N, 32) uint8 binary descriptors (ORB, BRIEF; ``bytes``
        of 32 * N also work); both or neither. ``camera_points``: optional (N, 3) scene point
        of each keypoint in this camera's frame (metres, NaN rows when unknown): with
        intrinsics, a later hint matched to this keyframe is metric. ``world_T_body``: the
        odometry pose, a 4x4 rigid transform (every keyframe has one or none has);
        ``body_T_camera``: the camera in the body frame (``None``: identity).

        The whole keyframe is validated first: on any error the detector is unchanged. Arrays
        of inconsistent lengths raise :class:`InvalidArgumentError` before the library is
        called. Raises :class:`DimensionMismatchError`, :class:`NonFiniteError`,
        :class:`ZeroDescriptorError`, :class:`InvalidArgumentError` (duplicate or decreasing
        id, earlier timestamp, poses on some keyframes only, bad keypoints, non-rigid poses).
        """
        kid = _u64(id, "id")
        ts = _real(timestamp, "timestamp")
        q = _descriptor(descriptor)
        if (keypoints is None) != (keypoint_descriptors is None):
            raise InvalidArgumentError(
                "give keypoints and keypoint_descriptors together (or neither)"
            )
        points = descriptors = scene = None
        n = 0
        if keypoints is not None:
            points = _keypoint_array(keypoints, "keypoints", 2, None)
            n = int(points.shape[0])
            descriptors = _binary_descriptors(keypoint_descriptors, n)
        if camera_points is not None:
            if points is None:
                raise InvalidArgumentError(
                    "camera_points needs keypoints (one scene point per keypoint)"
                )
            scene = _keypoint_array(camera_points, "camera_points", 3, n)
        body = None if world_T_body is None else _pose(world_T_body, "world_T_body")
        camera = None if body_T_camera is None else _pose(body_T_camera, "body_T_camera")

        # The arrays (locals, alive until the call returns) hold what the keyframe points to.
        fields = {
            "id": kid,
            "timestamp": ts,
            "descriptor": _f32_ptr(q),
            "descriptor_len": q.size,
            "world_T_body": None if body is None else _f64_ptr(body),
            "body_T_camera": None if camera is None else _f64_ptr(camera),
            "keypoint_count": n,
            "keypoints": None if points is None else _f32_ptr(points),
            "keypoint_descriptors": None if descriptors is None else _u8_ptr(descriptors),
            "camera_points": None if scene is None else _f32_ptr(scene),
        }
        with self._using("add") as h:
            return self._submit(fields, lambda kf, hint: lib.topoloc_loop_detector_add(h, kf, hint))

    def add_image(
        self,
        describer: KeyframeDescriber,
        id: int,
        timestamp: float,
        image: ArrayLike,
        *,
        pixel_format: Optional[str] = None,
        depth: Optional[ArrayLike] = None,
        depth_units_per_metre: Optional[float] = None,
        world_T_body: Optional[ArrayLike] = None,
        body_T_camera: Optional[ArrayLike] = None,
    ) -> LoopHint:
        """Adds keyframe ``id`` given as a camera image (ABI 1.15) and returns its
        :class:`LoopHint`, as :meth:`add` does: ``describer`` (a :class:`KeyframeDescriber` of
        this detector's map or descriptors) gives its global descriptor and local features in
        one pass.

        ``image``: a uint8 array, (H, W) grey or (H, W, 3) / (H, W, 4) colour
        (``pixel_format`` as for :meth:`Describer.describe`). ``depth``: an optional (H, W)
        depth image registered to it, either uint16 with ``depth_units_per_metre`` values per
        metre (1000 for millimetres, 5000 for TUM RGB-D; required), 0 where unknown, or floats
        in metres, passed as uint16 at ``depth_units_per_metre`` (default 1000: millimetres)
        with values not finite, not above 0 or beyond 65535 units taken as unknown. It needs
        the detector's intrinsics (``fx`` ...), and makes later hints matched to this keyframe
        metric (``scale_known``). ``id``, ``timestamp``, ``world_T_body`` and
        ``body_T_camera`` as for :meth:`add`.

        On any error the detector and the describer are unchanged. Raises ``TypeError`` (an
        image not uint8, depth neither uint16 nor float, not a :class:`KeyframeDescriber`),
        :class:`InvalidImageError`, :class:`InvalidArgumentError` (a depth image of another
        size, uint16 depth without ``depth_units_per_metre``, local features of another kind
        than earlier keyframes', and the errors of :meth:`add`), :class:`InvalidOptionError`
        (depth without intrinsics), :class:`DimensionMismatchError` (a describer of another
        map), :class:`UninformativeImageError`, :class:`ModelError`.
        """
        keyframes = _describer_handle(describer)
        kid = _u64(id, "id")
        ts = _real(timestamp, "timestamp")
        img, pixels = _image(image, pixel_format, "image")
        depth_struct = None
        if depth is not None:
            depth_struct, depth_values = _depth_image(depth, depth_units_per_metre, pixels.shape)
        body = None if world_T_body is None else _pose(world_T_body, "world_T_body")
        camera = None if body_T_camera is None else _pose(body_T_camera, "body_T_camera")
        fields = {
            "id": kid,
            "timestamp": ts,
            "world_T_body": None if body is None else _f64_ptr(body),
            "body_T_camera": None if camera is None else _f64_ptr(camera),
        }
        depth_ref = None if depth_struct is None else byref(depth_struct)
        add = lib.topoloc_loop_detector_add_image
        with self._using("add_image") as h, keyframes._using("add_image") as d:
            hint = self._submit(fields, lambda kf, out: add(h, d, kf, byref(img), depth_ref, out))
        del pixels  # the image (and depth) arrays are kept alive until here
        if depth_struct is not None:
            del depth_values
        return hint

    def _submit(self, fields: Dict[str, Any], call: Callable[[Any, Any], int]) -> LoopHint:
        """Fills the reused keyframe struct with ``fields`` (the rest stays empty), runs
        ``call(keyframe, hint)`` (by reference), then clears the pointers it borrowed; the
        hint of a failed call is not read."""
        kf, hint = self._keyframe, self._hint
        kf.struct_size = ctypes.sizeof(_lib.topoloc_loop_keyframe)
        for name, value in fields.items():
            setattr(kf, name, value)
        hint.struct_size = ctypes.sizeof(_lib.topoloc_loop_hint)
        try:
            check(call(byref(kf), byref(hint)))
        finally:
            kf.descriptor = None
            kf.descriptor_len = 0
            kf.world_T_body = kf.body_T_camera = None
            kf.keypoint_count = 0
            kf.keypoints = kf.keypoint_descriptors = kf.camera_points = None
        return _loop_hint(hint)

    def candidates(self, max_results: Optional[int] = None) -> List[LoopCandidateCheck]:
        """The loop candidates the last successful :meth:`add` or :meth:`add_image` verified
        (ABI 1.15), most inliers first, accepted or not (keyframes erased since are left out),
        at most ``max_results`` (``None``: all): for hosts that run their own check on several
        candidates, as ORB-SLAM3 takes 3 loop and 3 merge candidates."""
        with self._using("candidates") as h:
            # Never more than the keyframes held: a large max_results must not allocate.
            capacity = int(_out_call(c_size_t, lib.topoloc_loop_detector_len, h).value)
            if max_results is not None:
                capacity = min(capacity, _u32(max_results, "max_results"))
            found = (_lib.topoloc_loop_candidate_check * max(capacity, 1))()
            read = lib.topoloc_loop_detector_candidates
            count = _out_call(c_size_t, read, h, found, capacity)
        n = min(int(count.value), capacity)
        return [_from_struct(LoopCandidateCheck, c) for c in found[:n]]

    def confirmed(self) -> List[LoopHint]:
        """The hints of earlier keyframes that the last :meth:`add` confirmed (ABI 1.10),
        oldest first: when an added keyframe's hint is accepted because it completes a
        consistency streak, the streak's earlier keyframes, refused as
        :attr:`Gate.INCONSISTENT` while it was short, are accepted too (each with its own
        ``query_id``; at most one accepted hint per keyframe in all). Empty after an
        :meth:`add` whose hint was not accepted; replaced by the next :meth:`add`, kept by a
        failed one and by :meth:`erase`."""
        with self._using("confirmed") as h:
            count = _out_call(c_size_t, lib.topoloc_loop_detector_confirmed_count, h)
            hints = []
            for i in range(int(count.value)):
                raw = defaults(_lib.topoloc_loop_hint, lib.topoloc_loop_hint_init)
                check(lib.topoloc_loop_detector_confirmed(h, i, byref(raw)))
                hints.append(_loop_hint(raw))
            return hints

    def query(self, descriptor: ArrayLike, max_results: int) -> List[LoopCandidate]:
        """Relocalization: the (at most ``max_results``) keyframes most similar to
        ``descriptor`` (D floats; not added, and every keyframe may match), most similar
        first. Raises :class:`DimensionMismatchError`, :class:`NonFiniteError`,
        :class:`ZeroDescriptorError`."""
        q = _descriptor(descriptor)
        wanted = _u32(max_results, "max_results")
        with self._using("query") as h:
            # Room for what can be found, not for what is asked: 2**32 - 1 must not allocate.
            held = int(_out_call(c_size_t, lib.topoloc_loop_detector_len, h).value)
            capacity = min(wanted, held)
            found = (_lib.topoloc_loop_candidate * max(capacity, 1))()
            query = lib.topoloc_loop_detector_query
            count = _out_call(c_size_t, query, h, _f32_ptr(q), q.size, found, capacity)
        n = min(int(count.value), capacity)
        return [_from_struct(LoopCandidate, c) for c in found[:n]]

    def erase(self, id: int) -> None:
        """Removes keyframe ``id`` and its features (e.g. when SLAM culls it).
        Raises :class:`InvalidArgumentError` (no keyframe with that id)."""
        kid = _u64(id, "id")
        self._call("erase", lib.topoloc_loop_detector_erase, kid)

    def begin_session(self) -> None:
        """Starts a new session whose odometry is in a new world frame (a SLAM system's new
        map or sequence; see the C ``topoloc_loop_detector_begin_session``): the keyframes held
        become an earlier session's, never inside the exclusion window and not compared by
        time or odometry; the next timestamp may be earlier than the last (ids must still
        increase). The consistency streak ends."""
        self._call("begin_session", lib.topoloc_loop_detector_begin_session)

    def save(self, path: PathLike) -> None:
        """Saves the keyframes, their place graph and their keypoints as a topoloc map file
        (see the C ``topoloc_loop_detector_save``), atomically, for a later session:
        :meth:`Map.load`, then :meth:`from_map`. Raises :class:`MapIOError`,
        :class:`EmptyMapError`."""
        encoded = _path(path)
        self._call("save", lib.topoloc_loop_detector_save, encoded)


def _loop_hint(hint: Any) -> LoopHint:
    """The :class:`LoopHint` of a C ``topoloc_loop_hint``."""
    return _from_struct(
        LoopHint,
        hint,
        gate=_known(Gate, int(hint.gate)),
        matched_T_query=_matrix(hint.matched_T_query, 4),
        covariance=_matrix(hint.covariance, 6),
        translation=_known(Translation, int(hint.translation)),
    )


_E = TypeVar("_E", bound=enum.IntEnum)


def _known(kind: Type[_E], code: int) -> Union[_E, int]:
    """The ``kind`` member of a code (a code from a newer library stays an int)."""
    try:
        return kind(code)
    except ValueError:
        return code
