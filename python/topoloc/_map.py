"""Maps (mirrors ``src/ffi/map.rs``, ``builder.rs``, ``images.rs`` and ``map_keypoints.rs``):
:class:`Map`, :class:`MapBuilder`, :func:`map_from_keyframes`, :class:`ViewInfo`, and the
progress reports of builds from images.
"""

from __future__ import annotations

import ctypes
import os
from ctypes import POINTER, byref, c_bool, c_char_p, c_double, c_float, c_size_t, c_uint32
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import (
    PathLike,
    _descriptor,
    _f32_ptr,
    _f64_ptr,
    _image,
    _keypoint_array,
    _matrix,
    _out_call,
    _path,
    _pose,
    _read_array,
    _read_string,
    _text,
    _u8_ptr,
    _u32,
    _u64,
)
from ._errors import (
    DimensionMismatchError,
    InvalidArgumentError,
    UnknownPlaceError,
    UnknownViewError,
    check,
)
from ._handles import _Handle, _SingleThreaded
from ._lib import lib
from ._options import (
    OptionTable,
    choice,
    defaults,
    file_path,
    flag,
    real,
    text,
    text_list,
    unsigned,
)

__all__ = ["Map", "MapBuilder", "ViewInfo", "keyframe_options_default", "map_from_keyframes"]


@dataclass(frozen=True, eq=False)
class ViewInfo:
    """Attributes of one view of a :class:`Map` (see :meth:`Map.view_info`).

    Attributes:
        view: the view id.
        place: the place the view belongs to.
        keyframe_id: host keyframe id, or ``None`` when the view has none.
        world_T_camera: camera pose as a (4, 4) float64 array (row-major ``[R t; 0 0 0 1]``,
            metres), or ``None`` when the view has none.
    """

    view: int
    place: int
    keyframe_id: Optional[int]
    world_T_camera: Optional[NDArray[np.float64]]


#: The options of :meth:`Map.load` and :meth:`Map.from_bytes`: the fields of
#: ``topoloc_map_load_options``, by shorter names.
LOAD_OPTIONS = OptionTable(
    "map load",
    _lib.topoloc_map_load_options,
    lib.topoloc_map_load_options_init,
    InvalidArgumentError,
    [
        text("expected_descriptor_kind", name="expected_kind"),
        text("expected_descriptor_model", name="expected_model"),
        unsigned("expected_descriptor_dim", name="expected_dim"),
    ],
)

#: Backends a map can be built with -> ``TOPOLOC_BACKEND_*``.
_BUILD_BACKENDS = {
    "onnx": _lib.BACKEND_ONNX,
    "vlad-orb": _lib.BACKEND_VLAD_ORB,
    "vlad-sift": _lib.BACKEND_VLAD_SIFT,
}
#: ``pca_precision`` names -> ``TOPOLOC_PCA_*`` (ABI 1.14).
_PCA_PRECISIONS = {"i8": _lib.PCA_I8, "f32": _lib.PCA_F32}
#: ``local_features`` names -> ``TOPOLOC_LOCAL_FEATURES_*`` (ABI 1.15).
_LOCAL_FEATURES = {
    "orb": _lib.LOCAL_FEATURES_ORB,
    "xfeat": _lib.LOCAL_FEATURES_XFEAT,
    "cells": _lib.LOCAL_FEATURES_CELLS,
}

#: The options of :meth:`Map.build_from_images` and :meth:`Map.build_from_image_files`: the
#: fields of ``topoloc_image_map_options``.
IMAGE_MAP_OPTIONS = OptionTable(
    "image map",
    _lib.topoloc_image_map_options,
    lib.topoloc_image_map_options_init,
    InvalidArgumentError,
    [
        choice("backend", _BUILD_BACKENDS),
        unsigned("dim"),
        unsigned("views_per_place"),
        unsigned("threads"),
        file_path("onnx_model_path"),
        file_path("onnx_runtime_path"),
        text_list("onnx_taps"),
        unsigned("grid_rows"),
        unsigned("grid_cols"),
        unsigned("vlad_clusters"),
        flag("vlad_dense"),
        file_path("poses_tum_path"),
        real("place_spacing_m"),
        choice("pca_precision", _PCA_PRECISIONS),
        unsigned("verification_keypoints"),
        choice("local_features", _LOCAL_FEATURES),
        file_path("xfeat_model_path"),
    ],
)

#: The options of :func:`map_from_keyframes`: the fields of ``topoloc_keyframe_options``.
KEYFRAME_OPTIONS = OptionTable(
    "keyframe",
    _lib.topoloc_keyframe_options,
    lib.topoloc_keyframe_options_init,
    InvalidArgumentError,
    [
        real("place_spacing_m"),
        real("novelty_similarity"),
        real("neighbour_radius_m"),
        unsigned("max_views_per_place"),
    ],
)

#: Build stage codes -> names given to progress callbacks.
_STAGES: Dict[int, str] = {_lib.STAGE_DESCRIBING: "describing", _lib.STAGE_FITTING: "fitting"}
#: File name extensions listed by :meth:`Map.build_from_image_files` given a folder.
IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".pgm", ".ppm")

#: ``progress(stage, done, total)`` of a build from images; ``False`` cancels.
ProgressCallback = Callable[[str, int, int], Optional[bool]]


class _Progress:
    """Adapts a Python progress callable to ``topoloc_progress_fn``.

    The C library calls :attr:`callback` on the thread that started the build. An exception
    raised by the callable (including ``KeyboardInterrupt``) must not unwind through C (ctypes
    would print and drop it): it is stored in :attr:`error`, the build is cancelled by
    returning false, and the caller re-raises it once the C call has returned.
    """

    def __init__(self, progress: Optional[ProgressCallback]) -> None:
        if progress is not None and not callable(progress):
            raise TypeError(f"progress must be callable or None, got {type(progress).__name__}")
        self.progress = progress
        self.error: Optional[BaseException] = None
        self.callback = _lib.topoloc_progress_fn(self._call)

    def _call(self, _user_data: Any, stage: int, done: int, total: int) -> bool:
        try:
            if self.error is not None:
                return False
            if self.progress is None:
                return True
            name: Any = _STAGES.get(stage, stage)  # a newer library's stage stays an int
            answer = self.progress(name, int(done), int(total))
            return answer is None or bool(answer)
        except BaseException as e:  # KeyboardInterrupt too: cancel, re-raise later
            self.error = e
            return False

    def finish(self, status: int, out: Any) -> None:
        """After the C call: re-raises the callback's exception (releasing a map built anyway),
        or raises the exception for ``status``."""
        error, self.error = self.error, None
        if error is not None:
            if status == _lib.TOPOLOC_OK and out:
                lib.topoloc_map_free(out)
            try:
                raise error
            finally:
                error = None
        check(status)


def _image_files(paths: Union[PathLike, Sequence[PathLike]]) -> List[bytes]:
    """Encoded file paths: the given sequence, or the image files of a folder sorted by name."""
    if isinstance(paths, (str, bytes, os.PathLike)):
        folder = Path(os.fsdecode(paths))
        if not folder.is_dir():
            raise InvalidArgumentError(
                f"{os.fsdecode(paths)!r} is not a folder: give a folder of images or a list of "
                "image files"
            )
        files = sorted(
            (p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()),
            key=lambda p: p.name,
        )
        if not files:
            raise InvalidArgumentError(
                f"no image files ({', '.join(IMAGE_EXTENSIONS)}) in the folder {str(folder)!r}"
            )
        return [_path(p) for p in files]
    return [_path(p, f"paths[{i}]") for i, p in enumerate(paths)]


def _map_handle(map: Any) -> Any:
    """The C handle of ``map``, an argument that must be an open :class:`Map`."""
    if not isinstance(map, Map):
        raise TypeError(f"map must be a topoloc.Map, got {type(map).__name__}")
    return map._h


class Map(_Handle):
    """An immutable topological map: places (graph nodes) holding views (descriptors with
    optional keyframe id, pose and image reference), joined by weighted undirected edges.

    Create one with :meth:`load`, :meth:`from_bytes`, :meth:`build_from_images`,
    :meth:`build_from_image_files`, :meth:`MapBuilder.build` or :func:`map_from_keyframes`; the
    constructor is not public. Maps built from images store their describer (the backend's
    identity and the fitted PCA/codebook), kept by :meth:`save`, so that a :class:`Localizer` on
    them also accepts camera images.

    Ownership: the object owns one C ``topoloc_map`` handle, released by :meth:`close`, by the
    ``with`` statement, or when the object is garbage collected. :class:`Localizer` objects keep
    their own reference to the map data, so closing a map never affects them. Methods called
    after :meth:`close` raise ``ValueError``.

    Thread safety: a map is immutable; its read methods may be called from many threads at once
    (the C calls release the GIL). Do not call :meth:`close` while another thread still uses it.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError(
            "use Map.load(), Map.from_bytes(), Map.build_from_images(), "
            "Map.build_from_image_files(), "
            "MapBuilder.build() or map_from_keyframes()"
        )

    @classmethod
    def _adopt(cls, ptr: Any) -> Map:
        self = cls.__new__(cls)
        self._ptr = ptr
        self._free = lib.topoloc_map_free  # kept so that __del__ works during interpreter exit
        return self

    @classmethod
    def _made_by(cls, fn: Callable[..., int], *args: Any) -> Map:
        """The map that ``fn(*args, &map)`` creates."""
        return cls._adopt(_out_call(_lib.MapPtr, fn, *args))

    # -- creation ------------------------------------------------------------------------------

    @classmethod
    def load(
        cls,
        path: PathLike,
        *,
        expected_kind: Optional[str] = None,
        expected_model: Optional[str] = None,
        expected_dim: Optional[int] = None,
    ) -> Map:
        """Loads and validates a map file (memory-mapped: do not modify the file while the map
        is open; :meth:`save` replaces files atomically, which is safe).

        ``expected_kind`` / ``expected_model`` / ``expected_dim`` (keyword-only; the fields
        ``expected_descriptor_kind``, ``_model`` and ``_dim`` of ``topoloc_map_load_options``
        in ``topoloc.h``; left out or ``None``: any) make the load fail with
        :class:`DescriptorMismatchError` when the map was built with another descriptor.

        Raises :class:`MapIOError`, :class:`NotAMapError`, :class:`TruncatedMapError`,
        :class:`CorruptMapError`, :class:`UnsupportedVersionError`,
        :class:`DescriptorMismatchError`, :class:`InvalidUTF8Error`.
        """
        options = LOAD_OPTIONS.fill(LOAD_OPTIONS.pick(locals()))
        return cls._made_by(lib.topoloc_map_load, _path(path), byref(options))

    @classmethod
    def from_bytes(
        cls,
        data: Union[bytes, bytearray, memoryview],
        *,
        expected_kind: Optional[str] = None,
        expected_model: Optional[str] = None,
        expected_dim: Optional[int] = None,
    ) -> Map:
        """Loads and validates a map from bytes in the map file format (the library copies them;
        ``data`` may be released afterwards). Same options and errors as :meth:`load`."""
        options = LOAD_OPTIONS.fill(LOAD_OPTIONS.pick(locals()))
        buf = np.frombuffer(data, dtype=np.uint8)
        load = lib.topoloc_map_load_from_memory
        return cls._made_by(load, _u8_ptr(buf), buf.size, byref(options))

    @classmethod
    def build_from_images(
        cls,
        images: Sequence[ArrayLike],
        *,
        pixel_format: Optional[str] = None,
        progress: Optional[ProgressCallback] = None,
        backend: Optional[Union[str, int]] = None,
        dim: Optional[int] = None,
        views_per_place: Optional[int] = None,
        threads: Optional[int] = None,
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        onnx_taps: Optional[Union[str, Sequence[str]]] = None,
        grid_rows: Optional[int] = None,
        grid_cols: Optional[int] = None,
        vlad_clusters: Optional[int] = None,
        vlad_dense: Optional[bool] = None,
        poses_tum_path: Optional[PathLike] = None,
        place_spacing_m: Optional[float] = None,
        pca_precision: Optional[Union[str, int]] = None,
        verification_keypoints: Optional[int] = None,
        local_features: Optional[Union[str, int]] = None,
        xfeat_model_path: Optional[PathLike] = None,
    ) -> Map:
        """Builds a map from camera images in memory (``topoloc_map_build_from_images``).

        ``images``: a sequence (or stacked array) of at least 2 uint8 arrays, each (H, W) grey,
        (H, W, 3) or (H, W, 4) colour (sizes may differ). ``pixel_format`` (``"gray"``,
        ``"rgb"``, ``"bgr"``, ``"rgba"``, ``"bgra"``) applies to every image; ``None`` means
        ``"rgb"`` for 3 channels and ``"rgba"`` for 4. Arrays with contiguous rows are read in
        place (crops included), others are copied. The pixels are only read during the call.

        Every image is described with the ``backend`` in parallel (``threads``; they end
        before the call returns), then a PCA to ``dim`` dimensions is fitted on all of them
        (with fewer than ``dim + 1`` images, ``dim`` becomes the number of images minus one:
        :attr:`Map.dim` tells). ``backend``: ``"onnx"`` (a CNN run by ONNX Runtime:
        ``onnx_model_path``, ``onnx_runtime_path``, and ``onnx_taps``, the outputs pooled, a
        string or a sequence of names, on a ``grid_rows`` x ``grid_cols`` grid), ``"vlad-orb"``
        or ``"vlad-sift"`` (VLAD of OpenCV local features: ``vlad_clusters`` words, keypoints on
        a dense grid or detected, ``vlad_dense``; no learned weights). Without
        ``poses_tum_path``, every ``views_per_place`` consecutive images form a place and
        places are chained in order; with a TUM trajectory (one pose per image, same order),
        places are made by ``place_spacing_m`` and hold at most ``views_per_place`` views. View
        ``v`` records its image index as keyframe id. ``pca_precision``: ``"i8"`` or ``"f32"``,
        how the map stores its PCA rows. Each view stores ``verification_keypoints`` local
        features (0: none) for geometric verification and loop hints, of the kind
        ``local_features`` (ABI 1.15): ``"xfeat"`` (its network from ``xfeat_model_path``
        or the set-up cache), ``"orb"``, or ``"cells"`` (the ONNX
        backend's own feature map; no pose). :class:`LocalFeatures` values work too.

        Options are keyword-only, named as the fields of ``topoloc_image_map_options`` in
        ``topoloc.h``, which documents each one's default and range; left out or ``None``: the
        library's default.

        ``progress(stage, done, total)``, if given, is called on this thread about ten times a
        second with ``stage`` ``"describing"`` (``done`` of ``total`` images) or ``"fitting"``
        (0 or 1 of 1); returning ``False`` cancels the build (:class:`CancelledError`;
        returning ``None`` goes on). An exception raised by ``progress`` (or a
        ``KeyboardInterrupt`` arriving while it runs) cancels the build and is re-raised here.

        Returns a new :class:`Map` that stores its describer. Raises :class:`InvalidImageError`
        (the message names the image), ``TypeError`` (not uint8), :class:`InvalidArgumentError`
        (fewer than 2 images, bad options), :class:`BackendUnavailableError`,
        :class:`ModelError`, :class:`MapIOError` (poses file), :class:`CancelledError`.
        """
        given = IMAGE_MAP_OPTIONS.pick(locals())
        prepared = [_image(img, pixel_format, f"images[{i}]") for i, img in enumerate(images)]
        array = (_lib.topoloc_image * max(len(prepared), 1))(*(img for img, _ in prepared))
        # The image array points into the prepared pixels until the call returns.
        return cls._build(lib.topoloc_map_build_from_images, array, len(prepared), given, progress)

    @classmethod
    def build_from_image_files(
        cls,
        paths: Union[PathLike, Sequence[PathLike]],
        *,
        progress: Optional[ProgressCallback] = None,
        backend: Optional[Union[str, int]] = None,
        dim: Optional[int] = None,
        views_per_place: Optional[int] = None,
        threads: Optional[int] = None,
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        onnx_taps: Optional[Union[str, Sequence[str]]] = None,
        grid_rows: Optional[int] = None,
        grid_cols: Optional[int] = None,
        vlad_clusters: Optional[int] = None,
        vlad_dense: Optional[bool] = None,
        poses_tum_path: Optional[PathLike] = None,
        place_spacing_m: Optional[float] = None,
        pca_precision: Optional[Union[str, int]] = None,
        verification_keypoints: Optional[int] = None,
        local_features: Optional[Union[str, int]] = None,
        xfeat_model_path: Optional[PathLike] = None,
    ) -> Map:
        """Builds a map from image files (``topoloc_map_build_from_image_files``): any format
        OpenCV decodes, read and described in parallel.

        ``paths``: a list of image files in sequence order, or a folder, whose ``.jpg``,
        ``.jpeg``, ``.png``, ``.bmp``, ``.pgm`` and ``.ppm`` files are taken sorted by name.
        View ``v`` records the index of its image as keyframe id and its path as image
        reference (:meth:`view_image`). Options, progress reports and errors as
        :meth:`build_from_images`; an unreadable file raises :class:`InvalidImageError` naming
        it, and a folder without images :class:`InvalidArgumentError`.
        """
        given = IMAGE_MAP_OPTIONS.pick(locals())
        encoded = _image_files(paths)
        array = (c_char_p * max(len(encoded), 1))(*encoded)
        return cls._build(
            lib.topoloc_map_build_from_image_files, array, len(encoded), given, progress
        )

    @classmethod
    def _build(
        cls,
        build: Callable[..., int],
        images: Any,
        count: int,
        options: Dict[str, Any],
        progress: Optional[ProgressCallback],
    ) -> Map:
        """The body of :meth:`build_from_images` and :meth:`build_from_image_files`, which
        differ only in how the images arrive: ``build(images, count, options, progress_fn,
        user_data, out)``."""
        filled = IMAGE_MAP_OPTIONS.fill(options)
        reporter = _Progress(progress)
        out = _lib.MapPtr()
        status = build(images, count, byref(filled), reporter.callback, None, byref(out))
        reporter.finish(status, out)
        return cls._adopt(out)

    # -- lifetime ------------------------------------------------------------------------------

    def close(self) -> None:
        """Releases the C handle (idempotent). Localizers created from the map keep working."""
        super().close()

    def __repr__(self) -> str:
        if self.closed:
            return "<topoloc.Map (closed)>"
        return (
            f"<topoloc.Map kind={self.descriptor_kind!r} model={self.descriptor_model!r} "
            f"dim={self.dim} places={self.place_count} views={self.view_count} "
            f"edges={self.edge_count}>"
        )

    # -- whole-map operations ------------------------------------------------------------------

    def save(self, path: PathLike) -> None:
        """Writes the map to ``path`` atomically (temporary file, fsync, rename).
        Raises :class:`MapIOError`."""
        check(lib.topoloc_map_save(self._h, _path(path)))

    def _size(self, fn: Callable[..., int]) -> int:
        return int(_out_call(c_size_t, fn, self._h).value)

    @property
    def place_count(self) -> int:
        """Number of places."""
        return self._size(lib.topoloc_map_place_count)

    @property
    def view_count(self) -> int:
        """Number of views."""
        return self._size(lib.topoloc_map_view_count)

    @property
    def edge_count(self) -> int:
        """Number of undirected edges."""
        return self._size(lib.topoloc_map_edge_count)

    @property
    def dim(self) -> int:
        """Descriptor dimension D."""
        return int(_out_call(c_uint32, lib.topoloc_map_descriptor_dim, self._h).value)

    @property
    def descriptor_kind(self) -> str:
        """Descriptor kind (backend family) the map was built with."""
        return _read_string(lib.topoloc_map_descriptor_kind, self._h)

    @property
    def descriptor_model(self) -> str:
        """Descriptor model identity the map was built with ("" if none was given)."""
        return _read_string(lib.topoloc_map_descriptor_model, self._h)

    # -- places --------------------------------------------------------------------------------

    def neighbours(self, place: int) -> NDArray[np.uint32]:
        """Places joined to ``place`` by an edge, as a uint32 array.
        Raises :class:`UnknownPlaceError`."""
        place = _u32(place, "place", UnknownPlaceError)
        return _read_array(lib.topoloc_map_neighbours, self._h, place)

    def place_views(self, place: int) -> NDArray[np.uint32]:
        """View ids of ``place``, as a uint32 array. Raises :class:`UnknownPlaceError`."""
        place = _u32(place, "place", UnknownPlaceError)
        return _read_array(lib.topoloc_map_place_views, self._h, place)

    def place_position(self, place: int) -> Optional[NDArray[np.float64]]:
        """Position of ``place`` in metres as a float64 array of 3, or ``None`` when the map has
        none. Raises :class:`UnknownPlaceError`."""
        place = _u32(place, "place", UnknownPlaceError)
        xyz = np.zeros(3, dtype=np.float64)
        has = c_bool(False)
        check(lib.topoloc_map_place_position(self._h, place, _f64_ptr(xyz), byref(has)))
        return xyz if has.value else None

    def edges(self) -> Tuple[NDArray[np.uint32], NDArray[np.float32]]:
        """All edges, sorted by (a, b) with a < b: ``(pairs, weights)`` where ``pairs`` is an
        (E, 2) uint32 array and ``weights`` an (E,) float32 array."""
        h = self._h
        n = self.edge_count
        pairs = np.empty((n, 2), dtype=np.uint32)
        weights = np.empty(n, dtype=np.float32)
        a, b, w = c_uint32(), c_uint32(), c_float()
        for i in range(n):
            check(lib.topoloc_map_edge(h, i, byref(a), byref(b), byref(w)))
            pairs[i, 0], pairs[i, 1], weights[i] = a.value, b.value, w.value
        return pairs, weights

    # -- views ---------------------------------------------------------------------------------

    def view_info(self, view: int) -> ViewInfo:
        """Place, keyframe id and pose of ``view``. Raises :class:`UnknownViewError`."""
        view = _u32(view, "view", UnknownViewError)
        info = defaults(_lib.topoloc_view_info, lib.topoloc_view_info_init)
        check(lib.topoloc_map_view_info(self._h, view, byref(info)))
        pose = _matrix(info.world_T_camera, 4) if info.has_pose else None
        result = ViewInfo(
            view=view,
            place=int(info.place),
            keyframe_id=int(info.keyframe_id) if info.has_keyframe_id else None,
            world_T_camera=pose,
        )
        return result

    def view_descriptor(self, view: int) -> NDArray[np.float32]:
        """The unit-norm descriptor of ``view`` (a new float32 array of D values).
        Raises :class:`UnknownViewError`."""
        view = _u32(view, "view", UnknownViewError)
        d = self.dim
        out = np.empty(d, dtype=np.float32)
        check(lib.topoloc_map_view_descriptor(self._h, view, _f32_ptr(out), d))
        return out

    def view_descriptors(self) -> NDArray[np.float32]:
        """All view descriptors as a new (V, D) float32 array, row ``v`` being view ``v``."""
        h = self._h
        n, d = self.view_count, self.dim
        out = np.empty((n, d), dtype=np.float32)
        base = out.ctypes.data
        row = d * out.itemsize
        for v in range(n):
            check(
                lib.topoloc_map_view_descriptor(
                    h, v, ctypes.cast(base + v * row, POINTER(c_float)), d
                )
            )
        return out

    def view_image(self, view: int) -> str:
        """Image reference (path or URI) of ``view``; "" when it has none.
        Raises :class:`UnknownViewError`."""
        view = _u32(view, "view", UnknownViewError)
        return _read_string(lib.topoloc_map_view_image, self._h, view)

    # -- keypoints (ABI 1.6) -------------------------------------------------------------------

    @property
    def keypoint_total(self) -> int:
        """Number of keypoints of all views together (0 when the map stores none; maps built
        from images store them): the rows :meth:`with_keypoint_points` takes."""
        return self._size(lib.topoloc_map_keypoint_total)

    def view_keypoints(self, view: int) -> NDArray[np.float32]:
        """Pixel positions of ``view``'s keypoints as a new (N, 2) float32 array of ``x y``
        (OpenCV convention: the centre of the top-left pixel is (0, 0)), in the order
        :meth:`with_keypoint_points` expects their scene points. Raises
        :class:`UnknownViewError`, :class:`InvalidArgumentError` (the map stores no keypoints)."""
        view = _u32(view, "view", UnknownViewError)
        return _read_array(
            lib.topoloc_map_view_keypoints, self._h, view, ctype=c_float, dtype=np.float32, width=2
        )

    def with_keypoint_points(self, xyz: ArrayLike) -> Map:
        """A new :class:`Map`, a copy of this one whose keypoints carry their scene points: with
        it and camera intrinsics, a :class:`Localizer` reports pose fixes (:class:`PoseFix`).

        ``xyz``: (:attr:`keypoint_total`, 3) array of the map-frame position (the frame of the
        place positions and view poses, metres) of each keypoint, view after view in the order
        of :meth:`view_keypoints`; a row of three NaN where unknown. This map is unchanged; the
        copy holds its descriptors in memory. An array that is not (N, 3) raises
        :class:`InvalidArgumentError` (``TypeError`` for a non-numeric dtype) before the library
        is called; the library raises :class:`InvalidArgumentError` for a map without
        keypoints, the wrong number of rows, or a row neither finite nor all NaN.
        """
        points = _keypoint_array(xyz, "xyz", 3, None)
        copy = lib.topoloc_map_with_keypoint_points
        return Map._made_by(copy, self._h, _f32_ptr(points), points.size)


class MapBuilder(_SingleThreaded):
    """Collects places, views and edges, then produces a validated :class:`Map`.

    ``kind`` names the descriptor family (non-empty), ``model`` its model identity (may be
    ``None``), ``dim`` its dimension D (> 0). Every ``add_*`` method validates its input and
    leaves the builder unchanged on error; :meth:`build` may be called repeatedly.

    Ownership: owns a C ``topoloc_map_builder`` handle, released by :meth:`close`, the ``with``
    statement or garbage collection. Thread safety: single-threaded state; use from one thread
    at a time (concurrent calls raise ``RuntimeError``).
    """

    def __init__(self, kind: str, model: Optional[str], dim: int) -> None:
        self._open(
            lib.topoloc_map_builder_free,
            _lib.BuilderPtr,
            lib.topoloc_map_builder_new,
            _text(kind, "kind"),
            _text(model, "model"),
            _u32(dim, "dim"),
        )

    def add_place(self, position: Optional[ArrayLike] = None) -> int:
        """Adds a place, optionally at ``position`` (3 floats, metres); returns its id."""
        pos = None
        if position is not None:
            pos = np.ascontiguousarray(np.asarray(position, dtype=np.float64))
            if pos.shape != (3,):
                raise InvalidArgumentError(f"position must have 3 values, got shape {pos.shape}")
        with self._using("add_place") as h:
            add = lib.topoloc_map_builder_add_place
            out = _out_call(c_uint32, add, h, None if pos is None else _f64_ptr(pos))
        return int(out.value)

    def add_view(
        self,
        place: int,
        descriptor: ArrayLike,
        keyframe_id: Optional[int] = None,
        world_T_camera: Optional[ArrayLike] = None,
        image: Optional[Union[str, os.PathLike[str]]] = None,
    ) -> int:
        """Adds a view to ``place`` and returns its id.

        ``descriptor``: D floats (any array-like; normalised by the library). ``keyframe_id``:
        host keyframe id (0..2**64-1). ``world_T_camera``: 4x4 rigid transform (rotation block
        orthonormal with det +1, last row 0 0 0 1). ``image``: path or URI of the source image.

        Raises :class:`UnknownPlaceError`, :class:`DimensionMismatchError`,
        :class:`NonFiniteError`, :class:`ZeroDescriptorError`, :class:`InvalidArgumentError`.
        """
        place = _u32(place, "place", UnknownPlaceError)
        q = _descriptor(descriptor)
        attrs = None
        pose = None
        if keyframe_id is not None or world_T_camera is not None or image is not None:
            attrs = defaults(_lib.topoloc_view_attributes, lib.topoloc_view_attributes_init)
            if keyframe_id is not None:
                attrs.has_keyframe_id = True
                attrs.keyframe_id = _u64(keyframe_id, "keyframe_id")
            if world_T_camera is not None:
                pose = _pose(world_T_camera, "world_T_camera")
                attrs.world_T_camera = _f64_ptr(pose)
            if image is not None:
                attrs.image = _text(os.fspath(image), "image")
        with self._using("add_view") as h:
            add = lib.topoloc_map_builder_add_view
            by_attrs = None if attrs is None else byref(attrs)
            out = _out_call(c_uint32, add, h, place, _f32_ptr(q), q.size, by_attrs)
        del pose  # kept alive until here: attrs.world_T_camera points into it
        return int(out.value)

    def add_edge(self, a: int, b: int, weight: float = 1.0) -> None:
        """Joins places ``a`` and ``b`` (different, existing, not yet joined) with a finite
        ``weight`` > 0. Raises :class:`UnknownPlaceError`, :class:`InvalidArgumentError`."""
        a = _u32(a, "a", UnknownPlaceError)
        b = _u32(b, "b", UnknownPlaceError)
        self._call("add_edge", lib.topoloc_map_builder_add_edge, a, b, float(weight))

    def build(self) -> Map:
        """Validates what was added and returns a new :class:`Map` (the builder stays usable).
        Raises :class:`EmptyMapError` (no places), :class:`InvalidMapError` (e.g. a place
        without views)."""
        with self._using("build") as h:
            return Map._made_by(lib.topoloc_map_builder_build, h)


def keyframe_options_default() -> Dict[str, Any]:
    """The library's defaults for :func:`map_from_keyframes` options, as a dict keyed by the
    fields of ``topoloc_keyframe_options``, which ``topoloc.h`` documents."""
    return KEYFRAME_OPTIONS.default_values()


def map_from_keyframes(
    kind: str,
    model: Optional[str],
    dim: int,
    descriptors: ArrayLike,
    ids: Optional[ArrayLike] = None,
    poses: Optional[ArrayLike] = None,
    *,
    place_spacing_m: Optional[float] = None,
    novelty_similarity: Optional[float] = None,
    neighbour_radius_m: Optional[float] = None,
    max_views_per_place: Optional[int] = None,
) -> Map:
    """Builds a map from an ordered keyframe sequence (a SLAM run or image sequence).

    ``descriptors``: (K, D) array-like of global descriptors. ``ids``: K host keyframe ids
    (``None``: ``0`` to ``K-1``), stored with the views they become. ``poses``: ``None`` or a
    (K, 4, 4) array of ``world_T_camera`` rigid transforms. With poses, a keyframe joins the nearest
    place within ``place_spacing_m`` and becomes a new view there only when its appearance is
    novel (best cosine similarity below ``novelty_similarity``, at most
    ``max_views_per_place`` views); places closer than ``neighbour_radius_m`` are joined.
    Without poses, a keyframe starts a new place when novel with respect to the current place
    and is dropped otherwise. Consecutive keyframes' places are always joined.

    Options are keyword-only, named as the fields of ``topoloc_keyframe_options`` in
    ``topoloc.h``, which documents each one's default and range; left out or ``None``: the
    library's default (:func:`keyframe_options_default`).

    Returns a new :class:`Map`. Raises :class:`EmptyMapError` (K = 0),
    :class:`InvalidArgumentError` (bad keyframe or option; the message names it),
    :class:`DimensionMismatchError` (``descriptors`` not 2-D).
    """
    given = KEYFRAME_OPTIONS.pick(locals())
    desc = np.asarray(descriptors, dtype=np.float32)
    if desc.ndim != 2:
        raise DimensionMismatchError(f"descriptors must be a (K, D) array, got shape {desc.shape}")
    desc = np.ascontiguousarray(desc)
    k, d = desc.shape

    if ids is None:
        id_arr = np.arange(k, dtype=np.uint64)
    else:
        raw = np.asarray(ids)
        if raw.shape != (k,):
            raise InvalidArgumentError(f"ids must have shape ({k},), got {raw.shape}")
        if k and raw.dtype.kind not in "iu":
            raise TypeError(f"ids must be integers, got dtype {raw.dtype}")
        if k and raw.dtype.kind == "i" and (raw < 0).any():
            raise InvalidArgumentError("ids must be non-negative")
        id_arr = raw.astype(np.uint64)

    pose_arr = None
    if poses is not None:
        pose_arr = np.asarray(poses, dtype=np.float64)
        if pose_arr.shape != (k, 4, 4):
            raise InvalidArgumentError(f"poses must have shape ({k}, 4, 4), got {pose_arr.shape}")
        pose_arr = np.ascontiguousarray(pose_arr)

    options = KEYFRAME_OPTIONS.fill(given)

    keyframes = (_lib.topoloc_keyframe * k)()
    desc_base, row = desc.ctypes.data, d * desc.itemsize
    pose_base = pose_arr.ctypes.data if pose_arr is not None else 0
    for i in range(k):
        kf = keyframes[i]
        kf.id = int(id_arr[i])
        kf.descriptor = ctypes.cast(desc_base + i * row, POINTER(c_float))
        kf.descriptor_len = d
        if pose_arr is not None:
            kf.world_T_camera = ctypes.cast(pose_base + i * 16 * 8, POINTER(c_double))

    out = Map._made_by(
        lib.topoloc_map_from_keyframes,
        _text(kind, "kind"),
        _text(model, "model"),
        _u32(dim, "dim"),
        keyframes,
        k,
        byref(options),
    )
    del desc, pose_arr  # the keyframe array pointed into these until the call returned
    return out
