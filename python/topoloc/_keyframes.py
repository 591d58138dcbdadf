"""Image keyframes (ABI 1.15; mirrors ``src/ffi/loop_images.rs``): :class:`KeyframeDescriber`,
which describes a keyframe image and extracts its local features in one pass for
:meth:`LoopDetector.add_image`, :class:`LocalFeatures` and :class:`LoopCandidateCheck`.
"""

from __future__ import annotations

import enum
from ctypes import POINTER, byref, c_uint16, c_uint32
from dataclasses import dataclass
from typing import Any, Optional, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import _IMAGE_BACKENDS, PathLike, _out_call
from ._errors import InvalidArgumentError, InvalidOptionError
from ._handles import _SingleThreaded
from ._lib import lib
from ._map import _LOCAL_FEATURES, Map, _map_handle
from ._options import OptionTable, choice, file_path, unsigned

__all__ = ["KeyframeDescriber", "LocalFeatures", "LoopCandidateCheck"]


class LocalFeatures(enum.IntEnum):
    """Local features (``TOPOLOC_LOCAL_FEATURES_*``): which keypoints a map built from images
    stores and a :class:`KeyframeDescriber` extracts."""

    #: ORB (OpenCV), 32-byte binary descriptors.
    ORB = _lib.LOCAL_FEATURES_ORB
    #: XFeat (a learned network run by ONNX Runtime), 64-byte descriptors; the default.
    XFEAT = _lib.LOCAL_FEATURES_XFEAT
    #: Dense cells of the describer's own CNN pass (ONNX backend); they give no pose.
    CELLS = _lib.LOCAL_FEATURES_CELLS


@dataclass(frozen=True)
class LoopCandidateCheck:
    """One verified loop candidate of the last keyframe added (``topoloc_loop_candidate_check``),
    from :meth:`LoopDetector.candidates`: for hosts that run their own check on several
    candidates."""

    #: The candidate keyframe's id.
    keyframe_id: int
    #: Its place in the detector's place graph.
    place: int
    #: Cosine similarity of the keyframe's global descriptor to the candidate's.
    similarity: float
    #: Fundamental-matrix inliers of the pair check.
    inliers: int
    #: Its share of the inliers of every verified candidate of the keyframe (0..1).
    confidence: float


#: The :class:`KeyframeDescriber` options: the fields of ``topoloc_keyframe_describer_options``.
KEYFRAME_DESCRIBER_OPTIONS = OptionTable(
    "keyframe describer",
    _lib.topoloc_keyframe_describer_options,
    lib.topoloc_keyframe_describer_options_init,
    InvalidOptionError,
    [
        choice("local_features", _LOCAL_FEATURES),
        choice("backend", _IMAGE_BACKENDS),
        file_path("onnx_model_path"),
        file_path("onnx_runtime_path"),
        file_path("xfeat_model_path"),
        unsigned("xfeat_max_pixels"),
        unsigned("threads"),
    ],
)


class KeyframeDescriber(_SingleThreaded):
    """A map's describer with local features (ABI 1.15): a keyframe image in, its global
    descriptor and its local features out, in one pass, for :meth:`LoopDetector.add_image`.

    ``map``: a :class:`Map` built from images (it stores its describer; otherwise
    :class:`NoDescriberError`). Options are keyword-only, named as the fields of
    ``topoloc_keyframe_describer_options`` in ``topoloc.h``, which documents each one's default
    and range; left out or ``None``: the library's default. ``local_features``: ``"xfeat"``
    (default), ``"orb"`` or ``"cells"`` (or a :class:`LocalFeatures`); a detector made from a
    map takes the map's kind, so give the same here. ``backend``, ``onnx_model_path``,
    ``onnx_runtime_path`` and ``threads`` as for :class:`Describer`; ``xfeat_model_path``: the
    XFeat network (``None``: the set-up cache's export); ``xfeat_max_pixels``: larger images are
    scaled down to this many pixels before XFeat (0: never). Loading fails with
    :class:`BackendUnavailableError` (a missing runtime or model, naming the paths tried),
    :class:`ModelError`, :class:`DescriptorMismatchError`; a bad option raises
    :class:`InvalidOptionError`.

    Ownership: owns a C ``topoloc_keyframe_describer`` handle, released by :meth:`close`, the
    ``with`` statement or garbage collection; the map is not kept.

    Thread safety: single-threaded state; use from one thread at a time (concurrent calls raise
    ``RuntimeError``); one describer per detector thread.
    """

    def __init__(
        self,
        map: Map,
        *,
        local_features: Optional[Union[str, int]] = None,
        backend: Optional[Union[str, int]] = None,
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        xfeat_model_path: Optional[PathLike] = None,
        xfeat_max_pixels: Optional[int] = None,
        threads: Optional[int] = None,
    ) -> None:
        given = KEYFRAME_DESCRIBER_OPTIONS.pick(locals())
        handle = _map_handle(map)
        options = KEYFRAME_DESCRIBER_OPTIONS.fill(given)
        free, new = lib.topoloc_keyframe_describer_free, lib.topoloc_keyframe_describer_new
        h = self._open(free, _lib.KeyframeDescriberPtr, new, handle, byref(options))
        read = lib.topoloc_keyframe_describer_local_features
        self._features = LocalFeatures(int(_out_call(c_uint32, read, h).value))
        self._dim = map.dim

    @property
    def local_features(self) -> LocalFeatures:
        """The local features it extracts."""
        return self._features

    @property
    def dim(self) -> int:
        """Global descriptor dimension D (the map's)."""
        return self._dim

    def __repr__(self) -> str:
        state = "closed" if not self._ptr else f"dim={self._dim} {self._features.name.lower()}"
        return f"<topoloc.KeyframeDescriber {state}>"


#: Depth units per metre a depth image given in metres (floats) is passed with by default:
#: millimetres, as ``topoloc_depth_image`` holds uint16 values.
DEPTH_UNITS_FOR_METRES = 1000.0


def _depth_image(
    depth: ArrayLike, units_per_metre: Optional[float], image_shape: Tuple[int, ...]
) -> Tuple[_lib.topoloc_depth_image, NDArray[np.uint16]]:
    """A ``topoloc_depth_image`` of ``depth`` (an (H, W) array of the image's size) and the
    uint16 array it points into (keep it alive for the call).

    uint16 ``depth`` is borrowed as it is and needs ``units_per_metre``. Float ``depth`` is in
    metres: it is rounded to ``units_per_metre`` (default :data:`DEPTH_UNITS_FOR_METRES`) into
    a new uint16 array, in which a value that is not finite, not above 0 or beyond 65535 units
    (65.535 m in millimetres) is 0, no measurement."""
    values = np.asarray(depth)
    metres = np.issubdtype(values.dtype, np.floating)
    if values.dtype != np.uint16 and not metres:
        raise TypeError(
            f"depth must be a uint16 array (with depth_units_per_metre) or a float array in "
            f"metres, got dtype {values.dtype}"
        )
    if units_per_metre is None and not metres:
        raise InvalidArgumentError(
            "uint16 depth needs depth_units_per_metre (1000 for millimetres, 5000 for TUM RGB-D)"
        )
    units = DEPTH_UNITS_FOR_METRES if units_per_metre is None else float(units_per_metre)
    if not np.isfinite(units) or units <= 0:
        raise InvalidArgumentError(f"depth_units_per_metre must be finite and > 0, got {units}")
    if values.shape != tuple(image_shape[:2]):
        raise InvalidArgumentError(
            f"depth is {values.shape}, the image is {tuple(image_shape[:2])}: "
            "register it to the image (same height and width)"
        )
    if metres:
        with np.errstate(invalid="ignore", over="ignore"):
            scaled = np.rint(values.astype(np.float64) * units)
            known = np.isfinite(scaled) & (scaled > 0) & (scaled <= np.iinfo(np.uint16).max)
        values = np.where(known, scaled, 0).astype(np.uint16)
    values = np.ascontiguousarray(values)
    out = _lib.topoloc_depth_image()
    out.values = values.ctypes.data_as(POINTER(c_uint16))
    out.values_len = values.size
    out.units_per_metre = units
    return out, values


def _describer_handle(describer: Any) -> KeyframeDescriber:
    """``describer`` when it is an open :class:`KeyframeDescriber`; else ``TypeError``."""
    if not isinstance(describer, KeyframeDescriber):
        raise TypeError(f"describer must be a topoloc.KeyframeDescriber, got {type(describer)}")
    return describer
