"""The Pythonic API over the C ABI: :class:`Map`, :class:`MapBuilder`, :func:`map_from_keyframes`,
:class:`Localizer` and their result types. Import these from :mod:`topoloc`.
"""

from __future__ import annotations

import ctypes
import enum
import operator
import os
import threading
from ctypes import POINTER, byref, c_bool, c_char_p, c_double, c_float, c_size_t, c_uint8, c_uint32
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Type, TypeVar, Union

import numpy as np
from numpy.typing import ArrayLike

from . import _lib
from ._errors import (
    ConcurrentUseError,
    DimensionMismatchError,
    InvalidArgumentError,
    InvalidImageError,
    InvalidOptionError,
    InvalidUTF8Error,
    TopolocError,
    UnknownPlaceError,
    UnknownViewError,
)
from ._lib import check, lib

__all__ = [
    "Map",
    "MapBuilder",
    "map_from_keyframes",
    "Graph",
    "skeleton_graph",
    "skeleton_options_default",
    "Localizer",
    "Result",
    "Candidate",
    "PoseFix",
    "ViewInfo",
    "Gate",
    "LoopHint",
    "LoopCandidate",
    "LoopDetector",
    "loop_options_default",
    "ErrorStats",
    "TrajectoryReport",
    "evaluate_trajectory",
    "evaluate_trajectory_files",
    "version",
    "abi_version",
    "abi_version_minor",
    "status_name",
    "status_str",
]

PathLike = Union[str, bytes, "os.PathLike[str]", "os.PathLike[bytes]"]

_U32_MAX = 0xFFFFFFFF
_U64_MAX = 0xFFFFFFFFFFFFFFFF


# --------------------------------------------------------------------------------------------
# Argument conversion
# --------------------------------------------------------------------------------------------


def _int_in_range(value: Any, name: str, high: int, error: Type[TopolocError]) -> int:
    try:
        v = operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}") from None
    if not 0 <= v <= high:
        raise error(f"{name} {v} is out of range: expected an integer in [0, {high}]")
    return v


def _u32(value: Any, name: str, error: Type[TopolocError] = InvalidArgumentError) -> int:
    return _int_in_range(value, name, _U32_MAX, error)


def _descriptor(values: Any, name: str = "descriptor") -> np.ndarray:
    """A C-contiguous float32 1-D copy (or view) of ``values``."""
    arr = np.asarray(values, dtype=np.float32)
    if arr.ndim != 1:
        raise DimensionMismatchError(f"{name} must be a 1-D array of floats, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _pose(values: Any, name: str) -> np.ndarray:
    """A C-contiguous (row-major) float64 4x4 array."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (4, 4):
        raise InvalidArgumentError(f"{name} must be a 4x4 matrix, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _text(value: Optional[Union[str, bytes]], name: str) -> Optional[bytes]:
    """UTF-8 bytes for a C string argument (None stays None -> NULL)."""
    if value is None:
        return None
    if isinstance(value, str):
        try:
            data = value.encode("utf-8")
        except UnicodeEncodeError as e:
            raise InvalidUTF8Error(f"{name} cannot be encoded as UTF-8: {e}") from None
    elif isinstance(value, (bytes, bytearray)):
        data = bytes(value)
    else:
        raise TypeError(f"{name} must be str or bytes, got {type(value).__name__}")
    if b"\0" in data:
        raise InvalidArgumentError(f"{name} contains a NUL character")
    return data


def _path(value: PathLike, name: str = "path") -> bytes:
    data = os.fsencode(value)  # str paths: UTF-8 (surrogateescape), bytes paths: unchanged
    if b"\0" in data:
        raise InvalidArgumentError(f"{name} contains a NUL character")
    return data


def _f32_ptr(arr: np.ndarray):
    return arr.ctypes.data_as(POINTER(c_float))


def _f64_ptr(arr: np.ndarray):
    return arr.ctypes.data_as(POINTER(c_double))


def _matrix(values: ctypes.Array, n: int) -> np.ndarray:
    """A new (n, n) float64 array from a C ``double[n * n]`` in row-major order."""
    return np.array(values[:], dtype=np.float64).reshape(n, n)


# --------------------------------------------------------------------------------------------
# Images
# --------------------------------------------------------------------------------------------

#: Pixel format names -> (``TOPOLOC_PIXEL_*``, channels).
_PIXEL_FORMATS = {
    "gray": (_lib.PIXEL_GRAY8, 1),
    "rgb": (_lib.PIXEL_RGB8, 3),
    "bgr": (_lib.PIXEL_BGR8, 3),
    "rgba": (_lib.PIXEL_RGBA8, 4),
    "bgra": (_lib.PIXEL_BGRA8, 4),
}
#: Default pixel format by channel count.
_DEFAULT_FORMAT = {1: "gray", 3: "rgb", 4: "rgba"}


def _pixel_format(pixel_format: Optional[str], channels: int, name: str) -> int:
    """The ``TOPOLOC_PIXEL_*`` code for ``pixel_format`` (``None``: the default for
    ``channels``), checked against the array's channel count."""
    if pixel_format is None:
        pixel_format = _DEFAULT_FORMAT[channels]
    if not isinstance(pixel_format, str):
        raise TypeError(f"pixel_format must be a str, got {type(pixel_format).__name__}")
    key = pixel_format.lower()
    if key not in _PIXEL_FORMATS:
        raise InvalidImageError(
            f"pixel_format {pixel_format!r} is not one of {', '.join(repr(k) for k in _PIXEL_FORMATS)}"
        )
    code, wanted = _PIXEL_FORMATS[key]
    if wanted != channels:
        raise InvalidImageError(
            f"{name} has {channels} channel(s) but pixel_format {pixel_format!r} has {wanted}"
        )
    return code


def _rows_packed(arr: np.ndarray, channels: int) -> bool:
    """Whether ``arr`` (H, W) or (H, W, C) of uint8 has contiguous pixels within each row and
    rows at a positive stride of at least one row's bytes, the layout ``topoloc_image``
    describes."""
    h, w = arr.shape[:2]
    strides = arr.strides
    if arr.ndim == 3 and strides[2] != 1:
        return False
    if w > 1 and strides[1] != channels:
        return False
    return h == 1 or strides[0] >= w * channels


def _image(image: Any, pixel_format: Optional[str], name: str) -> Tuple[_lib.topoloc_image, np.ndarray]:
    """A ``topoloc_image`` borrowing the pixels of ``image`` and the array it points into (keep
    that alive until the C call returns).

    ``image``: uint8 array (H, W) grey, (H, W, 1) grey, (H, W, 3) RGB/BGR or (H, W, 4)
    RGBA/BGRA. Arrays whose rows are contiguous are passed as they are, with their row stride
    (e.g. a crop ``frame[10:200, 20:300]``); others (column steps, negative strides,
    planar/transposed layouts) are copied first.
    """
    if isinstance(image, (str, bytes, os.PathLike)):
        raise TypeError(f"{name} must be a numpy uint8 array of pixels, got a path ({image!r})")
    arr = np.asarray(image)
    if arr.dtype != np.uint8:
        raise TypeError(
            f"{name} must be a uint8 array (8 bits per channel), got dtype {arr.dtype}; "
            "scale to 0..255 and convert with .astype(np.uint8)"
        )
    if arr.ndim == 2:
        channels = 1
    elif arr.ndim == 3 and arr.shape[2] in (1, 3, 4):
        channels = int(arr.shape[2])
    else:
        raise InvalidImageError(
            f"{name} must have shape (H, W) or (H, W, 1) for grey, (H, W, 3) for RGB/BGR or "
            f"(H, W, 4) for RGBA/BGRA; got shape {arr.shape}"
        )
    fmt = _pixel_format(pixel_format, channels, name)
    h, w = int(arr.shape[0]), int(arr.shape[1])
    if h == 0 or w == 0:
        raise InvalidImageError(f"{name} has shape {arr.shape}: width and height must be at least 1")
    if h > _U32_MAX or w > _U32_MAX:
        raise InvalidImageError(f"{name} has shape {arr.shape}: too large")
    if arr.ndim == 3 and channels == 1:
        arr = arr[:, :, 0]
    if not _rows_packed(arr, channels):
        arr = np.ascontiguousarray(arr)
    row = w * channels
    stride = int(arr.strides[0]) if h > 1 else row
    out = _lib.topoloc_image()
    out.data = ctypes.cast(arr.ctypes.data, POINTER(c_uint8))
    out.data_len = stride * (h - 1) + row
    out.width = w
    out.height = h
    out.stride = stride
    out.format = fmt
    return out, arr


def _read_string(fn, *args) -> str:
    """Calls a ``(..., char *buf, size_t len, size_t *needed)`` function, growing the buffer."""
    needed = c_size_t(0)
    size = 64
    for _ in range(2):
        buf = ctypes.create_string_buffer(size)
        status = fn(*args, buf, size, byref(needed))
        if status == _lib.TOPOLOC_ERR_BUFFER_TOO_SMALL and needed.value > size:
            size = int(needed.value)
            continue
        check(status)
        return buf.raw[: max(int(needed.value) - 1, 0)].decode("utf-8")
    check(status)  # pragma: no cover - the size cannot grow between two calls on an immutable map
    raise AssertionError("unreachable")


def _read_array(fn, *args, ctype: Any = c_uint32, dtype: Any = np.uint32, width: int = 1) -> np.ndarray:
    """Calls a ``(..., T *buf, size_t len, size_t *count)`` function, growing the buffer:
    ``*count`` items of ``width`` values each, ``len`` counting values. Returns a new
    ``(count,)`` array, or ``(count, width)`` for ``width`` > 1."""
    count = c_size_t(0)
    capacity = 16
    for _ in range(2):
        out = np.empty(capacity * width, dtype=dtype)
        status = fn(*args, out.ctypes.data_as(POINTER(ctype)), out.size, byref(count))
        if status == _lib.TOPOLOC_ERR_BUFFER_TOO_SMALL and count.value > capacity:
            capacity = int(count.value)
            continue
        check(status)
        n = int(count.value)
        items = out[: n * width].copy()
        return items if width == 1 else items.reshape(n, width)
    check(status)  # pragma: no cover
    raise AssertionError("unreachable")


def _read_u32s(fn, *args) -> np.ndarray:
    """Calls a ``(..., uint32_t *buf, size_t len, size_t *count)`` function, growing the buffer."""
    return _read_array(fn, *args)


# --------------------------------------------------------------------------------------------
# Versions
# --------------------------------------------------------------------------------------------


def version() -> str:
    """Version of the loaded library, ``"MAJOR.MINOR.PATCH"`` (``topoloc_version``)."""
    return lib.topoloc_version().decode("ascii")


def abi_version() -> int:
    """C ABI version of the loaded library (``topoloc_abi_version``); equals
    :data:`topoloc.ABI_VERSION` (checked at import)."""
    return int(lib.topoloc_abi_version())


def abi_version_minor() -> int:
    """C ABI minor version of the loaded library (``topoloc_abi_version_minor``): items marked
    "ABI 1.N" in the header exist when this is at least N."""
    return int(lib.topoloc_abi_version_minor())


def status_name(status: int) -> Optional[str]:
    """C name of a status code, e.g. ``"TOPOLOC_ERR_IO"`` (``topoloc_status_name``), or
    ``None`` for a code the loaded library does not know."""
    name = lib.topoloc_status_name(int(status) & 0xFFFFFFFF)
    return None if name is None else name.decode("ascii")


def status_str(status: int) -> str:
    """Short English description of a status code (``topoloc_status_str``)."""
    return _lib.status_str(status)


# --------------------------------------------------------------------------------------------
# Map
# --------------------------------------------------------------------------------------------


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
    world_T_camera: Optional[np.ndarray]


def _load_options(expected_kind, expected_model, expected_dim) -> _lib.topoloc_map_load_options:
    options = _lib.defaults(_lib.topoloc_map_load_options, lib.topoloc_map_load_options_init)
    # c_char_p fields keep a reference to the bytes object in the struct (ctypes' _objects).
    options.expected_descriptor_kind = _text(expected_kind, "expected_kind")
    options.expected_descriptor_model = _text(expected_model, "expected_model")
    options.expected_descriptor_dim = _u32(expected_dim or 0, "expected_dim")
    return options


#: Backends a map can be built with -> ``TOPOLOC_BACKEND_*``.
_BUILD_BACKENDS = {
    "onnx": _lib.BACKEND_ONNX,
    "vlad-orb": _lib.BACKEND_VLAD_ORB,
    "vlad-sift": _lib.BACKEND_VLAD_SIFT,
}
#: Build stage codes -> names given to progress callbacks.
_STAGES: Dict[int, str] = {_lib.STAGE_DESCRIBING: "describing", _lib.STAGE_FITTING: "fitting"}
#: File name extensions listed by :meth:`Map.build_from_image_files` given a folder.
IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".pgm", ".ppm")

ProgressCallback = Callable[[str, int, int], Optional[bool]]


def _backend_code(value: Union[str, int], table: Dict[str, int], name: str, error: Type[TopolocError]) -> int:
    """A ``TOPOLOC_BACKEND_*`` code from its name (``"vlad-orb"``, also ``"vlad_orb"``) or code."""
    if isinstance(value, str):
        key = value.lower().replace("_", "-")
        if key not in table:
            raise error(f"{name} must be one of {', '.join(repr(k) for k in table)}, got {value!r}")
        return table[key]
    return _u32(value, name, error)


def _backend_name(code: int, table: Dict[str, int]) -> Union[str, int]:
    return next((k for k, v in table.items() if v == code), code)


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
        except BaseException as e:  # noqa: B902 - KeyboardInterrupt too: cancel, re-raise later
            self.error = e
            return False

    def finish(self, status: int, out) -> None:
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


def _image_map_options(
    backend: Union[str, int],
    dim: int,
    views_per_place: int,
    threads: int,
    onnx_model_path: Optional[PathLike],
    onnx_runtime_path: Optional[PathLike],
    onnx_taps: Optional[Union[str, Sequence[str]]],
    grid_rows: Optional[int],
    grid_cols: Optional[int],
    vlad_clusters: Optional[int],
    poses_tum_path: Optional[PathLike],
    place_spacing_m: Optional[float],
    vlad_dense: Optional[bool] = None,
    pca_precision: Optional[str] = None,
) -> _lib.topoloc_image_map_options:
    o = _lib.defaults(_lib.topoloc_image_map_options, lib.topoloc_image_map_options_init)
    o.backend = _backend_code(backend, _BUILD_BACKENDS, "backend", InvalidArgumentError)
    o.dim = _u32(dim, "dim")
    o.views_per_place = _u32(views_per_place, "views_per_place")
    o.threads = _u32(threads, "threads")
    # c_char_p fields keep a reference to the bytes object in the struct (ctypes' _objects).
    if onnx_model_path is not None:
        o.onnx_model_path = _path(onnx_model_path, "onnx_model_path")
    if onnx_runtime_path is not None:
        o.onnx_runtime_path = _path(onnx_runtime_path, "onnx_runtime_path")
    if onnx_taps is not None:
        taps = onnx_taps if isinstance(onnx_taps, str) else ",".join(onnx_taps)
        o.onnx_taps = _text(taps, "onnx_taps")
    if grid_rows is not None:
        o.grid_rows = _u32(grid_rows, "grid_rows")
    if grid_cols is not None:
        o.grid_cols = _u32(grid_cols, "grid_cols")
    if vlad_clusters is not None:
        o.vlad_clusters = _u32(vlad_clusters, "vlad_clusters")
    if vlad_dense is not None:
        o.vlad_dense = bool(vlad_dense)
    if poses_tum_path is not None:
        o.poses_tum_path = _path(poses_tum_path, "poses_tum_path")
    if place_spacing_m is not None:
        o.place_spacing_m = float(place_spacing_m)
    if pca_precision is not None:
        if pca_precision not in _PCA_PRECISIONS:
            raise InvalidArgumentError(
                f"pca_precision {pca_precision!r}: use one of {sorted(_PCA_PRECISIONS)}"
            )
        o.pca_precision = _PCA_PRECISIONS[pca_precision]
    return o


#: ``pca_precision`` names -> ``TOPOLOC_PCA_*`` (ABI 1.14).
_PCA_PRECISIONS = {"i8": _lib.PCA_I8, "f32": _lib.PCA_F32}


def _image_files(paths: Union[PathLike, Sequence[PathLike]]) -> List[bytes]:
    """Encoded file paths: the given sequence, or the image files of a folder sorted by name."""
    if isinstance(paths, (str, bytes, os.PathLike)):
        folder = Path(os.fsdecode(paths))
        if not folder.is_dir():
            raise InvalidArgumentError(
                f"{os.fsdecode(paths)!r} is not a folder: give a folder of images or a list of image files"
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


_H = TypeVar("_H", bound="_Handle")


class _Handle:
    """Owns one C handle: ``_ptr`` released with ``_free`` by :meth:`close`, the ``with``
    statement, or garbage collection. Methods called after :meth:`close` raise ``ValueError``."""

    _ptr: Any = None
    _free: Callable[[Any], Any]

    @property
    def _h(self) -> Any:
        if not self._ptr:
            raise ValueError(f"operation on a closed topoloc.{type(self).__name__}")
        return self._ptr

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return not self._ptr

    def close(self) -> None:
        """Releases the C handle (idempotent)."""
        ptr, self._ptr = self._ptr, None
        if ptr:
            self._free(ptr)

    def __enter__(self: _H) -> _H:
        self._h  # refuse a closed object
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass


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
            "use Map.load(), Map.from_bytes(), Map.build_from_images(), Map.build_from_image_files(), "
            "MapBuilder.build() or map_from_keyframes()"
        )

    @classmethod
    def _adopt(cls, ptr) -> "Map":
        self = cls.__new__(cls)
        self._ptr = ptr
        self._free = lib.topoloc_map_free  # kept so that __del__ works during interpreter exit
        return self

    # -- creation ------------------------------------------------------------------------------

    @classmethod
    def load(
        cls,
        path: PathLike,
        expected_kind: Optional[str] = None,
        expected_model: Optional[str] = None,
        expected_dim: int = 0,
    ) -> "Map":
        """Loads and validates a map file (memory-mapped: do not modify the file while the map
        is open; :meth:`save` replaces files atomically, which is safe).

        ``expected_kind`` / ``expected_model`` / ``expected_dim`` (``None``/``""``/``0`` = any)
        make the load fail with :class:`DescriptorMismatchError` when the map was built with
        another descriptor.

        Raises :class:`MapIOError`, :class:`NotAMapError`, :class:`TruncatedMapError`,
        :class:`CorruptMapError`, :class:`UnsupportedVersionError`,
        :class:`DescriptorMismatchError`, :class:`InvalidUTF8Error`.
        """
        options = _load_options(expected_kind, expected_model, expected_dim)
        out = _lib.MapPtr()
        check(lib.topoloc_map_load(_path(path), byref(options), byref(out)))
        return cls._adopt(out)

    @classmethod
    def from_bytes(
        cls,
        data: Union[bytes, bytearray, memoryview],
        expected_kind: Optional[str] = None,
        expected_model: Optional[str] = None,
        expected_dim: int = 0,
    ) -> "Map":
        """Loads and validates a map from bytes in the map file format (the library copies them;
        ``data`` may be released afterwards). Same options and errors as :meth:`load`."""
        buf = np.frombuffer(data, dtype=np.uint8)
        options = _load_options(expected_kind, expected_model, expected_dim)
        out = _lib.MapPtr()
        check(
            lib.topoloc_map_load_from_memory(
                buf.ctypes.data_as(POINTER(c_uint8)), buf.size, byref(options), byref(out)
            )
        )
        return cls._adopt(out)

    @classmethod
    def build_from_images(
        cls,
        images: Sequence[ArrayLike],
        backend: Union[str, int] = "onnx",
        dim: int = 512,
        views_per_place: int = 1,
        threads: int = 0,
        progress: Optional[ProgressCallback] = None,
        *,
        pixel_format: Optional[str] = None,
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        onnx_taps: Optional[Union[str, Sequence[str]]] = None,
        grid_rows: Optional[int] = None,
        grid_cols: Optional[int] = None,
        vlad_clusters: Optional[int] = None,
        vlad_dense: Optional[bool] = None,
        poses_tum_path: Optional[PathLike] = None,
        place_spacing_m: Optional[float] = None,
        pca_precision: Optional[str] = None,
    ) -> "Map":
        """Builds a map from camera images in memory (``topoloc_map_build_from_images``).

        ``images``: a sequence (or stacked array) of at least 2 uint8 arrays, each (H, W) grey,
        (H, W, 3) or (H, W, 4) colour (sizes may differ). ``pixel_format`` (``"gray"``,
        ``"rgb"``, ``"bgr"``, ``"rgba"``, ``"bgra"``) applies to every image; ``None`` means
        ``"rgb"`` for 3 channels and ``"rgba"`` for 4. Arrays with contiguous rows are read in
        place (crops included), others are copied. The pixels are only read during the call.

        Every image is described with ``backend`` in parallel (``threads``, 0 = one per core,
        at most 256; the threads end before the call returns):
        ``"onnx"`` (a CNN run by ONNX Runtime; ``onnx_model_path`` / ``onnx_runtime_path``
        default to the cache filled by ``scripts/setup-models.sh``, ``onnx_taps`` names the
        outputs pooled on a ``grid_rows`` x ``grid_cols`` grid), ``"vlad-orb"`` or
        ``"vlad-sift"`` (VLAD of OpenCV local features, ``vlad_clusters`` words, on a dense
        keypoint grid unless ``vlad_dense=False``; no learned weights). A PCA to ``dim``
        dimensions is fitted on all of them; with fewer than ``dim + 1`` images, ``dim`` becomes
        the number of images minus one (``Map.dim`` tells). Without ``poses_tum_path``, every
        ``views_per_place`` consecutive images form a place and places are chained in order; with a TUM trajectory
        (one pose per image, same order), places are made by ``place_spacing_m`` and hold at
        most ``views_per_place`` views. View ``v`` records its image index as keyframe id.
        ``pca_precision`` stores the PCA rows as ``"i8"`` (the default: a quarter of the size,
        map format 1.5) or ``"f32"`` (exact). Options left as ``None`` take the library
        defaults.

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
        prepared = [_image(img, pixel_format, f"images[{i}]") for i, img in enumerate(images)]
        n = len(prepared)
        array = (_lib.topoloc_image * max(n, 1))()
        for i, (img, _) in enumerate(prepared):
            array[i] = img
        options = _image_map_options(
            backend, dim, views_per_place, threads, onnx_model_path, onnx_runtime_path, onnx_taps,
            grid_rows, grid_cols, vlad_clusters, poses_tum_path, place_spacing_m, vlad_dense,
            pca_precision,
        )
        reporter = _Progress(progress)
        out = _lib.MapPtr()
        status = lib.topoloc_map_build_from_images(array, n, byref(options), reporter.callback, None, byref(out))
        del prepared  # the image array pointed into these until the call returned
        reporter.finish(status, out)
        return cls._adopt(out)

    @classmethod
    def build_from_image_files(
        cls,
        paths: Union[PathLike, Sequence[PathLike]],
        backend: Union[str, int] = "onnx",
        dim: int = 512,
        views_per_place: int = 1,
        threads: int = 0,
        progress: Optional[ProgressCallback] = None,
        *,
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        onnx_taps: Optional[Union[str, Sequence[str]]] = None,
        grid_rows: Optional[int] = None,
        grid_cols: Optional[int] = None,
        vlad_clusters: Optional[int] = None,
        vlad_dense: Optional[bool] = None,
        poses_tum_path: Optional[PathLike] = None,
        place_spacing_m: Optional[float] = None,
        pca_precision: Optional[str] = None,
    ) -> "Map":
        """Builds a map from image files (``topoloc_map_build_from_image_files``): any format
        OpenCV decodes, read and described in parallel.

        ``paths``: a list of image files in sequence order, or a folder, whose ``.jpg``,
        ``.jpeg``, ``.png``, ``.bmp``, ``.pgm`` and ``.ppm`` files are taken sorted by name.
        View ``v`` records the index of its image as keyframe id and its path as image
        reference (:meth:`view_image`). Other arguments, progress reports and errors as
        :meth:`build_from_images`; an unreadable file raises :class:`InvalidImageError` naming
        it, and a folder without images :class:`InvalidArgumentError`.
        """
        encoded = _image_files(paths)
        n = len(encoded)
        array = (c_char_p * max(n, 1))(*encoded)
        options = _image_map_options(
            backend, dim, views_per_place, threads, onnx_model_path, onnx_runtime_path, onnx_taps,
            grid_rows, grid_cols, vlad_clusters, poses_tum_path, place_spacing_m, vlad_dense,
            pca_precision,
        )
        reporter = _Progress(progress)
        out = _lib.MapPtr()
        status = lib.topoloc_map_build_from_image_files(array, n, byref(options), reporter.callback, None, byref(out))
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
            f"dim={self.dim} places={self.place_count} views={self.view_count} edges={self.edge_count}>"
        )

    # -- whole-map operations ------------------------------------------------------------------

    def save(self, path: PathLike) -> None:
        """Writes the map to ``path`` atomically (temporary file, fsync, rename).
        Raises :class:`MapIOError`."""
        check(lib.topoloc_map_save(self._h, _path(path)))

    def _size(self, fn) -> int:
        out = c_size_t(0)
        check(fn(self._h, byref(out)))
        return int(out.value)

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
        out = c_uint32(0)
        check(lib.topoloc_map_descriptor_dim(self._h, byref(out)))
        return int(out.value)

    @property
    def descriptor_kind(self) -> str:
        """Descriptor kind (backend family) the map was built with."""
        return _read_string(lib.topoloc_map_descriptor_kind, self._h)

    @property
    def descriptor_model(self) -> str:
        """Descriptor model identity the map was built with ("" if none was given)."""
        return _read_string(lib.topoloc_map_descriptor_model, self._h)

    # -- places --------------------------------------------------------------------------------

    def neighbours(self, place: int) -> np.ndarray:
        """Places joined to ``place`` by an edge, as a uint32 array.
        Raises :class:`UnknownPlaceError`."""
        place = _u32(place, "place", UnknownPlaceError)
        return _read_u32s(lib.topoloc_map_neighbours, self._h, place)

    def place_views(self, place: int) -> np.ndarray:
        """View ids of ``place``, as a uint32 array. Raises :class:`UnknownPlaceError`."""
        place = _u32(place, "place", UnknownPlaceError)
        return _read_u32s(lib.topoloc_map_place_views, self._h, place)

    def place_position(self, place: int) -> Optional[np.ndarray]:
        """Position of ``place`` in metres as a float64 array of 3, or ``None`` when the map has
        none. Raises :class:`UnknownPlaceError`."""
        place = _u32(place, "place", UnknownPlaceError)
        xyz = np.zeros(3, dtype=np.float64)
        has = c_bool(False)
        check(lib.topoloc_map_place_position(self._h, place, _f64_ptr(xyz), byref(has)))
        return xyz if has.value else None

    def edges(self) -> Tuple[np.ndarray, np.ndarray]:
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
        info = _lib.defaults(_lib.topoloc_view_info, lib.topoloc_view_info_init)
        check(lib.topoloc_map_view_info(self._h, view, byref(info)))
        pose = _matrix(info.world_T_camera, 4) if info.has_pose else None
        result = ViewInfo(
            view=view,
            place=int(info.place),
            keyframe_id=int(info.keyframe_id) if info.has_keyframe_id else None,
            world_T_camera=pose,
        )
        return result

    def view_descriptor(self, view: int) -> np.ndarray:
        """The unit-norm descriptor of ``view`` (a new float32 array of D values).
        Raises :class:`UnknownViewError`."""
        view = _u32(view, "view", UnknownViewError)
        d = self.dim
        out = np.empty(d, dtype=np.float32)
        check(lib.topoloc_map_view_descriptor(self._h, view, _f32_ptr(out), d))
        return out

    def view_descriptors(self) -> np.ndarray:
        """All view descriptors as a new (V, D) float32 array, row ``v`` being view ``v``."""
        h = self._h
        n, d = self.view_count, self.dim
        out = np.empty((n, d), dtype=np.float32)
        base = out.ctypes.data
        row = d * out.itemsize
        for v in range(n):
            check(lib.topoloc_map_view_descriptor(h, v, ctypes.cast(base + v * row, POINTER(c_float)), d))
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

    def view_keypoints(self, view: int) -> np.ndarray:
        """Pixel positions of ``view``'s keypoints as a new (N, 2) float32 array of ``x y``
        (OpenCV convention: the centre of the top-left pixel is (0, 0)), in the order
        :meth:`with_keypoint_points` expects their scene points. Raises
        :class:`UnknownViewError`, :class:`InvalidArgumentError` (the map stores no keypoints)."""
        view = _u32(view, "view", UnknownViewError)
        return _read_array(
            lib.topoloc_map_view_keypoints, self._h, view, ctype=c_float, dtype=np.float32, width=2
        )

    def with_keypoint_points(self, xyz: ArrayLike) -> "Map":
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
        out = _lib.MapPtr()
        check(lib.topoloc_map_with_keypoint_points(self._h, _f32_ptr(points), points.size, byref(out)))
        return Map._adopt(out)


# --------------------------------------------------------------------------------------------
# Building maps
# --------------------------------------------------------------------------------------------


class _SingleThreaded(_Handle):
    """Detects concurrent use of a single-threaded C object (which would be undefined
    behaviour) and raises :class:`ConcurrentUseError` (a ``RuntimeError``) instead, as the library
    itself does (``TOPOLOC_ERR_CONCURRENT_USE``)."""

    def _init_guard(self) -> None:
        self._busy = threading.Lock()

    def _enter(self, what: str):
        if not self._busy.acquire(blocking=False):
            raise ConcurrentUseError(f"{type(self).__name__}.{what} called while another thread uses this object")
        if not self._ptr:
            self._busy.release()
            raise ValueError(f"operation on a closed topoloc.{type(self).__name__}")
        return self._ptr

    def _leave(self) -> None:
        self._busy.release()

    def close(self) -> None:
        """Releases the C handle (idempotent)."""
        busy = getattr(self, "_busy", None)
        if busy is None:  # __init__ failed before the handle existed
            return
        with busy:
            super().close()


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
        self._init_guard()
        self._free = lib.topoloc_map_builder_free
        out = _lib.BuilderPtr()
        check(
            lib.topoloc_map_builder_new(
                _text(kind, "kind"), _text(model, "model"), _u32(dim, "dim"), byref(out)
            )
        )
        self._ptr = out

    def add_place(self, position: Optional[ArrayLike] = None) -> int:
        """Adds a place, optionally at ``position`` (3 floats, metres); returns its id."""
        pos = None
        if position is not None:
            pos = np.ascontiguousarray(np.asarray(position, dtype=np.float64))
            if pos.shape != (3,):
                raise InvalidArgumentError(f"position must have 3 values, got shape {pos.shape}")
        out = c_uint32(0)
        h = self._enter("add_place")
        try:
            check(lib.topoloc_map_builder_add_place(h, None if pos is None else _f64_ptr(pos), byref(out)))
        finally:
            self._leave()
        return int(out.value)

    def add_view(
        self,
        place: int,
        descriptor: ArrayLike,
        keyframe_id: Optional[int] = None,
        world_T_camera: Optional[ArrayLike] = None,
        image: Optional[Union[str, "os.PathLike[str]"]] = None,
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
            attrs = _lib.defaults(_lib.topoloc_view_attributes, lib.topoloc_view_attributes_init)
            if keyframe_id is not None:
                attrs.has_keyframe_id = True
                attrs.keyframe_id = _int_in_range(keyframe_id, "keyframe_id", _U64_MAX, InvalidArgumentError)
            if world_T_camera is not None:
                pose = _pose(world_T_camera, "world_T_camera")
                attrs.world_T_camera = _f64_ptr(pose)
            if image is not None:
                attrs.image = _text(os.fspath(image), "image")
        out = c_uint32(0)
        h = self._enter("add_view")
        try:
            check(
                lib.topoloc_map_builder_add_view(
                    h, place, _f32_ptr(q), q.size, None if attrs is None else byref(attrs), byref(out)
                )
            )
        finally:
            self._leave()
        del pose  # kept alive until here: attrs.world_T_camera points into it
        return int(out.value)

    def add_edge(self, a: int, b: int, weight: float = 1.0) -> None:
        """Joins places ``a`` and ``b`` (different, existing, not yet joined) with a finite
        ``weight`` > 0. Raises :class:`UnknownPlaceError`, :class:`InvalidArgumentError`."""
        a = _u32(a, "a", UnknownPlaceError)
        b = _u32(b, "b", UnknownPlaceError)
        h = self._enter("add_edge")
        try:
            check(lib.topoloc_map_builder_add_edge(h, a, b, float(weight)))
        finally:
            self._leave()

    def build(self) -> Map:
        """Validates what was added and returns a new :class:`Map` (the builder stays usable).
        Raises :class:`EmptyMapError` (no places), :class:`InvalidMapError` (e.g. a place
        without views)."""
        out = _lib.MapPtr()
        h = self._enter("build")
        try:
            check(lib.topoloc_map_builder_build(h, byref(out)))
        finally:
            self._leave()
        return Map._adopt(out)


def keyframe_options_default() -> Dict[str, Any]:
    """The library's defaults for :func:`map_from_keyframes` options, as a dict."""
    o = _lib.defaults(_lib.topoloc_keyframe_options, lib.topoloc_keyframe_options_init)
    return {f[0]: getattr(o, f[0]) for f in o._fields_ if f[0] != "struct_size"}


def map_from_keyframes(
    kind: str,
    model: Optional[str],
    dim: int,
    descriptors: ArrayLike,
    ids: Optional[ArrayLike] = None,
    poses: Optional[ArrayLike] = None,
    place_spacing_m: Optional[float] = None,
    novelty_similarity: Optional[float] = None,
    neighbour_radius_m: Optional[float] = None,
    max_views_per_place: Optional[int] = None,
) -> Map:
    """Builds a map from an ordered keyframe sequence (a SLAM run or image sequence).

    ``descriptors``: (K, D) array-like of global descriptors. ``ids``: K host keyframe ids
    (default ``0..K-1``), stored with the views they become. ``poses``: ``None`` or a (K, 4, 4)
    array of ``world_T_camera`` rigid transforms. With poses, a keyframe joins the nearest
    place within ``place_spacing_m`` and becomes a new view there only when its appearance is
    novel (best cosine similarity below ``novelty_similarity``, at most
    ``max_views_per_place`` views); places closer than ``neighbour_radius_m`` are joined.
    Without poses, a keyframe starts a new place when novel with respect to the current place
    and is dropped otherwise. Consecutive keyframes' places are always joined. Options left as
    ``None`` take the library defaults (:func:`keyframe_options_default`).

    Returns a new :class:`Map`. Raises :class:`EmptyMapError` (K = 0),
    :class:`InvalidArgumentError` (bad keyframe or option; the message names it),
    :class:`DimensionMismatchError` (``descriptors`` not 2-D).
    """
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

    options = _lib.defaults(_lib.topoloc_keyframe_options, lib.topoloc_keyframe_options_init)
    if place_spacing_m is not None:
        options.place_spacing_m = float(place_spacing_m)
    if novelty_similarity is not None:
        options.novelty_similarity = float(novelty_similarity)
    if neighbour_radius_m is not None:
        options.neighbour_radius_m = float(neighbour_radius_m)
    if max_views_per_place is not None:
        options.max_views_per_place = _u32(max_views_per_place, "max_views_per_place")

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

    out = _lib.MapPtr()
    check(
        lib.topoloc_map_from_keyframes(
            _text(kind, "kind"),
            _text(model, "model"),
            _u32(dim, "dim"),
            keyframes,
            k,
            byref(options),
            byref(out),
        )
    )
    del desc, pose_arr  # the keyframe array pointed into these until the call returned
    return Map._adopt(out)


# --------------------------------------------------------------------------------------------
# Skeleton graphs from occupancy grids
# --------------------------------------------------------------------------------------------

#: ``TOPOLOC_NODE_*`` codes by name, in code order.
NODE_KINDS = ("end", "corner", "branch", "intermediate")


@dataclass(frozen=True, eq=False)
class Graph:
    """A topological graph built from an occupancy grid by :func:`skeleton_graph`.

    Plain numpy arrays (copied out of the library; nothing to close):

    - ``positions``: (N, 3) float64, world position of each place in metres (the centre of its
      skeleton voxel);
    - ``kinds``: (N,) uint32 ``TOPOLOC_NODE_*`` codes, ``kind_names`` the same as strings
      (``"end"``, ``"corner"``, ``"branch"``, ``"intermediate"``); places come in the order
      branches, ends, corners, then intermediate places;
    - ``edges``: (E, 2) uint32 place pairs ``a < b``, sorted; ``lengths``: (E,) float64, the
      straight distance between them in metres;
    - ``skeleton``: (S, 3) int64 voxel indices ``(x, y, z)`` of the skeleton the graph was built
      on, in grid order (``occupied[tuple(graph.skeleton.T)]`` is all False).
    """

    positions: np.ndarray
    kinds: np.ndarray
    edges: np.ndarray
    lengths: np.ndarray
    skeleton: np.ndarray

    @property
    def place_count(self) -> int:
        """Number of places N."""
        return int(self.positions.shape[0])

    @property
    def edge_count(self) -> int:
        """Number of undirected edges E."""
        return int(self.edges.shape[0])

    @property
    def kind_names(self) -> List[str]:
        """The kind of each place as a string: ``"end"``, ``"corner"``, ``"branch"`` or
        ``"intermediate"``."""
        return [NODE_KINDS[k] for k in self.kinds]

    def kind_counts(self) -> Dict[str, int]:
        """Number of places of each kind, e.g. ``{"end": 2, "corner": 0, ...}``."""
        counts = np.bincount(self.kinds, minlength=len(NODE_KINDS))
        return {name: int(counts[i]) for i, name in enumerate(NODE_KINDS)}

    def neighbours(self, place: int) -> np.ndarray:
        """Places joined to ``place``, increasing."""
        p = _int_in_range(place, "place", self.place_count - 1, UnknownPlaceError)
        a, b = self.edges[:, 0], self.edges[:, 1]
        return np.sort(np.concatenate([b[a == p], a[b == p]]))

    def __repr__(self) -> str:
        return f"Graph(places={self.place_count}, edges={self.edge_count}, kinds={self.kind_counts()})"


def skeleton_options_default() -> Dict[str, Any]:
    """The library's defaults for :func:`skeleton_graph` options, as a dict (``z_band`` is
    ``None``: the whole grid)."""
    o = _lib.defaults(_lib.topoloc_skeleton_options, lib.topoloc_skeleton_options_init)
    out: Dict[str, Any] = {"z_band": (o.z_min_m, o.z_max_m) if o.use_z_band else None}
    for f in o._fields_:
        if f[0] not in ("struct_size", "use_z_band", "z_min_m", "z_max_m"):
            out[f[0]] = getattr(o, f[0])
    return out


def _occupancy_cells(occupied: Any) -> Tuple[np.ndarray, Tuple[int, int, int]]:
    """The cells of an ``occupied[x, y, z]`` array as uint8, x fastest, and ``(nx, ny, nz)``."""
    arr = np.asarray(occupied)
    if arr.dtype != np.bool_ and arr.dtype.kind not in "iu":
        raise TypeError(
            f"occupied must be a bool or integer array (non-zero = occupied), got dtype {arr.dtype}; "
            "threshold occupancy probabilities first, e.g. occupied = probability > 0.5"
        )
    if arr.ndim == 2:
        arr = arr[:, :, np.newaxis]
    if arr.ndim != 3:
        raise InvalidArgumentError(
            f"occupied must have shape (nx, ny, nz) (indexed occupied[x, y, z]) or (nx, ny) for a "
            f"single layer; got shape {arr.shape}"
        )
    # (nx, ny, nz) indexed [x, y, z] -> C order of (nz, ny, nx): x fastest, as the C API wants.
    cells = np.ascontiguousarray((arr != 0).transpose(2, 1, 0), dtype=np.uint8)
    nx, ny, nz = (int(n) for n in arr.shape)
    return cells, (nx, ny, nz)


def skeleton_graph(
    occupied: ArrayLike,
    voxel_size: float,
    origin: ArrayLike = (0.0, 0.0, 0.0),
    *,
    z_band: Optional[Tuple[float, float]] = None,
    min_clearance_m: Optional[float] = None,
    merge_radius_m: Optional[float] = None,
    max_edge_m: Optional[float] = None,
    corner_angle_deg: Optional[float] = None,
    corner_scale_m: Optional[float] = None,
    min_spur_m: Optional[float] = None,
) -> Graph:
    """Builds the topological graph of the free space of an occupancy voxel grid
    (``topoloc_graph_from_occupancy``): the free space is thinned to a one-voxel-thin 3D
    skeleton, whose ends, corners and junctions become places (merged when closer than
    ``merge_radius_m`` along it), joined where the skeleton links them by an obstacle-free
    straight segment; intermediate places are inserted where a segment would cross an obstacle
    or be longer than ``max_edge_m``.

    ``occupied``: bool or integer array of shape ``(nx, ny, nz)``, **indexed**
    ``occupied[x, y, z]`` (non-zero = occupied; a 2-D ``(nx, ny)`` array is one layer). Voxel
    ``(x, y, z)`` covers ``origin + voxel_size * [x, x+1) x [y, y+1) x [z, z+1)`` metres, z up.
    Any memory layout is accepted (the cells are copied).

    Options left as ``None`` take the library defaults (:func:`skeleton_options_default`):
    ``z_band`` ``(z_min, z_max)`` metres, only voxels whose centre lies in it; ``min_clearance_m``
    free voxels closer than this to an obstacle count as occupied; ``merge_radius_m``;
    ``max_edge_m`` (at least two voxels); ``corner_angle_deg`` smallest bend that makes a corner;
    ``corner_scale_m`` distance over which bends are measured; ``min_spur_m`` dead ends shorter
    than this are removed.

    Returns a :class:`Graph`. Raises :class:`InvalidArgumentError` naming the problem
    (``occupied`` shape, ``voxel_size``, ``origin``, ``cells`` when every voxel is occupied,
    ``z_band`` when the band holds no free voxel, ``min_clearance_m`` when nothing keeps the
    clearance, or another option out of range), ``TypeError`` for a float ``occupied``.
    """
    cells, dims = _occupancy_cells(occupied)
    org = np.ascontiguousarray(np.asarray(origin, dtype=np.float64))
    if org.shape != (3,):
        raise InvalidArgumentError(f"origin must have 3 values (x, y, z), got shape {org.shape}")
    options = _lib.defaults(_lib.topoloc_skeleton_options, lib.topoloc_skeleton_options_init)
    if z_band is not None:
        band = tuple(float(v) for v in z_band)
        if len(band) != 2:
            raise InvalidArgumentError(f"z_band must be (z_min, z_max), got {z_band!r}")
        options.use_z_band = True
        options.z_min_m, options.z_max_m = band
    for name, value in (
        ("min_clearance_m", min_clearance_m),
        ("merge_radius_m", merge_radius_m),
        ("max_edge_m", max_edge_m),
        ("corner_angle_deg", corner_angle_deg),
        ("corner_scale_m", corner_scale_m),
        ("min_spur_m", min_spur_m),
    ):
        if value is not None:
            setattr(options, name, float(value))

    out = _lib.GraphPtr()
    check(
        lib.topoloc_graph_from_occupancy(
            (c_size_t * 3)(*dims),
            float(voxel_size),
            _f64_ptr(org),
            cells.ctypes.data_as(POINTER(c_uint8)),
            cells.size,
            byref(options),
            byref(out),
        )
    )
    try:
        return _read_graph(out)
    finally:
        lib.topoloc_graph_free(out)


def _read_graph(h) -> Graph:
    """Copies a ``topoloc_graph`` into a :class:`Graph`."""
    places, edges = c_size_t(0), c_size_t(0)
    check(lib.topoloc_graph_place_count(h, byref(places)))
    check(lib.topoloc_graph_edge_count(h, byref(edges)))
    positions = np.empty((places.value, 3), dtype=np.float64)
    kinds = np.empty(places.value, dtype=np.uint32)
    kind = c_uint32(0)
    for p in range(places.value):
        check(lib.topoloc_graph_place(h, p, _f64_ptr(positions[p]), byref(kind)))
        kinds[p] = kind.value
    pairs = np.empty((edges.value, 2), dtype=np.uint32)
    lengths = np.empty(edges.value, dtype=np.float64)
    a, b, length = c_uint32(0), c_uint32(0), c_double(0.0)
    for e in range(edges.value):
        check(lib.topoloc_graph_edge(h, e, byref(a), byref(b), byref(length)))
        pairs[e] = (a.value, b.value)
        lengths[e] = length.value
    skeleton = _read_u32s(lib.topoloc_graph_skeleton, h).astype(np.int64).reshape(-1, 3)
    for arr in (positions, kinds, pairs, lengths, skeleton):
        arr.flags.writeable = False
    return Graph(positions, kinds, pairs, lengths, skeleton)


# --------------------------------------------------------------------------------------------
# Localization
# --------------------------------------------------------------------------------------------


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
#: Localizer ``image_backend`` names -> ``TOPOLOC_BACKEND_*``.
_IMAGE_BACKENDS = {
    "auto": _lib.BACKEND_AUTO,
    "none": _lib.BACKEND_NONE,
    "onnx": _lib.BACKEND_ONNX,
    "vlad-orb": _lib.BACKEND_VLAD_ORB,
    "vlad-sift": _lib.BACKEND_VLAD_SIFT,
}
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
    o = _lib.defaults(_lib.topoloc_localizer_options, lib.topoloc_localizer_options_init)
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
        options = _lib.defaults(_lib.topoloc_localizer_options, lib.topoloc_localizer_options_init)
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
        self._result = _lib.defaults(_lib.topoloc_result, lib.topoloc_result_init)
        self._frame = _lib.defaults(_lib.topoloc_frame, lib.topoloc_frame_init)

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


# --------------------------------------------------------------------------------------------
# Loop closure (ABI 1.5)
# --------------------------------------------------------------------------------------------


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
            points); otherwise it has unit length (a direction).
        matched_T_query: (4, 4) float64, the query camera in the matched camera's optical
            frame (z forward, x right, y down); the identity without a pose.
        covariance: (6, 6) float64 covariance of ``matched_T_query`` for a right
            perturbation, in GTSAM Pose3 tangent order: rotation (rad) x y z, then
            translation (m) x y z; zeros without a pose.
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
    matched_T_query: np.ndarray
    covariance: np.ndarray


@dataclass(frozen=True)
class LoopCandidate:
    """One relocalization candidate of :meth:`LoopDetector.query`: keyframe ``keyframe_id``,
    its ``place``, and the cosine ``similarity`` of the query to it."""

    keyframe_id: int
    place: int
    similarity: float


#: Options of :class:`LoopDetector` (the ``topoloc_loop_options`` fields) -> converter kind.
_LOOP_OPTION_KINDS = {
    "candidates": "u32",
    "exclude_recent_ids": "u64",
    "exclude_recent_s": "float",
    "min_inliers": "u32",
    "consistent_keyframes": "u32",
    "odometry_gate": "bool",
    "odometry_max_rotation_deg": "float",
    "odometry_max_translation_m": "float",
    "fx": "float",
    "fy": "float",
    "cx": "float",
    "cy": "float",
    "novelty_similarity": "float",
    "place_spacing_m": "float",
    "neighbour_radius_m": "float",
    "candidate_id_gap": "u64",
    "odometry_max_translation_per_m": "float",
    "pose_reprojection_px": "float",
    "odometry_search_m": "float",
    "odometry_candidates": "u32",
}


def loop_options_default() -> Dict[str, Any]:
    """The library's default :class:`LoopDetector` options (``topoloc_loop_options_init``) as
    a dict keyed by the C field names (``fx == 0``: no intrinsics, hints carry no pose)."""
    o = _lib.defaults(_lib.topoloc_loop_options, lib.topoloc_loop_options_init)
    return _loop_options_dict(o)


def _loop_options_dict(o: _lib.topoloc_loop_options) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for name, kind in _LOOP_OPTION_KINDS.items():
        value = getattr(o, name)
        out[name] = float(value) if kind == "float" else bool(value) if kind == "bool" else int(value)
    return out


def _loop_options(given: Dict[str, Any]) -> _lib.topoloc_loop_options:
    """The library defaults with the options in ``given`` (``None`` values: the default)."""
    unknown = sorted(set(given) - set(_LOOP_OPTION_KINDS))
    if unknown:
        raise TypeError(
            f"unexpected loop detector option(s) {', '.join(repr(n) for n in unknown)}; "
            f"the options are {', '.join(_LOOP_OPTION_KINDS)}"
        )
    options = _lib.defaults(_lib.topoloc_loop_options, lib.topoloc_loop_options_init)
    for name, value in given.items():
        if value is None:
            continue
        kind = _LOOP_OPTION_KINDS[name]
        if kind == "u32":
            value = _u32(value, name, InvalidOptionError)
        elif kind == "u64":
            value = _int_in_range(value, name, _U64_MAX, InvalidOptionError)
        elif kind == "bool":
            value = bool(value)
        else:
            value = float(value)
        setattr(options, name, value)
    return options


def _keypoint_array(values: Any, name: str, columns: int, count: Optional[int]) -> np.ndarray:
    """A C-contiguous float32 (N, columns) array; ``count``: the N it must have."""
    arr = np.asarray(values)
    if arr.size and arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be an array of real numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float32, copy=False)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise InvalidArgumentError(f"{name} must be an (N, {columns}) array, got shape {arr.shape}")
    if count is not None and arr.shape[0] != count:
        raise InvalidArgumentError(
            f"{name} has {arr.shape[0]} rows but keypoints has {count}: one row per keypoint"
        )
    return np.ascontiguousarray(arr, dtype=np.float32)


def _binary_descriptors(values: Any, count: int) -> np.ndarray:
    """The keypoints' 32-byte descriptors as a C-contiguous uint8 (N, 32) array."""
    if isinstance(values, (bytes, bytearray, memoryview)):
        flat = np.frombuffer(values, dtype=np.uint8)
        if flat.size % 32:
            raise InvalidArgumentError(f"keypoint_descriptors has {flat.size} bytes, not a multiple of 32")
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
            f"keypoint_descriptors has {arr.shape[0]} rows but keypoints has {count}: one per keypoint"
        )
    return np.ascontiguousarray(arr, dtype=np.uint8)


class Describer(_SingleThreaded):
    """A map's describer on its own (ABI 1.12): camera images to global descriptors exactly
    as the map's views were described, e.g. for :meth:`LoopDetector.add` or
    :meth:`Localizer.process`.

    ``map``: a :class:`Map` built from images (it stores its describer; otherwise
    :class:`NoDescriberError`). ``backend``: ``"auto"`` (default: the map's), or ``"onnx"``,
    ``"vlad-orb"``, ``"vlad-sift"`` to require it (:class:`DescriptorMismatchError`
    otherwise). ``onnx_model_path`` / ``onnx_runtime_path`` override where the ONNX model (the
    very file the map was built with) and runtime are found; ``threads``: ONNX Runtime
    intra-op threads (1..64). Loading fails with :class:`BackendUnavailableError` or
    :class:`ModelError`.

    Ownership: owns a C ``topoloc_describer`` handle, released by :meth:`close`, the ``with``
    statement or garbage collection; the map is not kept.

    Thread safety: single-threaded state; use from one thread at a time (concurrent calls
    raise ``RuntimeError``); one describer per thread for parallel work.
    """

    def __init__(
        self,
        map: Map,
        backend: Union[str, int] = "auto",
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        threads: int = 1,
    ) -> None:
        self._init_guard()
        self._free = lib.topoloc_describer_free
        if not isinstance(map, Map):
            raise TypeError(f"map must be a topoloc.Map, got {type(map).__name__}")
        options = _lib.defaults(_lib.topoloc_describer_options, lib.topoloc_describer_options_init)
        options.backend = _backend_code(backend, _IMAGE_BACKENDS, "backend", InvalidOptionError)
        if onnx_model_path is not None:
            options.onnx_model_path = _path(onnx_model_path, "onnx_model_path")
        if onnx_runtime_path is not None:
            options.onnx_runtime_path = _path(onnx_runtime_path, "onnx_runtime_path")
        options.threads = _u32(threads, "threads", InvalidOptionError)
        out = _lib.DescriberPtr()
        check(lib.topoloc_describer_new(map._h, byref(options), byref(out)))
        self._ptr = out
        dim = c_size_t(0)
        check(lib.topoloc_describer_dim(out, byref(dim)))
        self._dim = int(dim.value)

    @property
    def dim(self) -> int:
        """Descriptor dimension D (the map's)."""
        return self._dim

    def describe(self, image: ArrayLike, pixel_format: Optional[str] = None) -> np.ndarray:
        """The global descriptor of ``image`` (a uint8 array, (H, W) grey or (H, W, 3) /
        (H, W, 4) colour; ``pixel_format`` as for :meth:`Localizer.process`): D float32 values
        of unit norm. Raises ``TypeError`` (not uint8), :class:`InvalidImageError`,
        :class:`UninformativeImageError` (blank or featureless), :class:`ModelError`."""
        img, pixels = _image(image, pixel_format, "image")
        out = np.empty(self._dim, dtype=np.float32)
        h = self._enter("describe")
        try:
            check(lib.topoloc_describer_describe(h, byref(img), _f32_ptr(out), out.size, None))
        finally:
            self._leave()
            del pixels
        return out

    def __repr__(self) -> str:
        state = "closed" if not self._ptr else f"dim={self._dim}"
        return f"<topoloc.Describer {state}>"


class LoopDetector(_SingleThreaded):
    """Loop-closure hints for a SLAM run: keyframes in, at most one gated hint per keyframe out.

    ``LoopDetector(kind, model, dim, **options)`` starts an empty detector for global
    descriptors of ``kind`` / ``model`` (non-empty strings) and dimension ``dim``;
    :meth:`from_map` starts one whose first session is a saved map (a second session closes
    loops against it). Each :meth:`add` verifies the keyframe's loop candidates (keyframes
    outside the exclusion window) against its keypoints and gates the best one; the keyframe
    then joins the detector's place graph.

    Options (keyword arguments named as the ``topoloc_loop_options`` fields; left out or
    ``None``: the library default, :func:`loop_options_default`): ``candidates`` (verified per
    keyframe, 1..64), ``exclude_recent_ids`` and ``exclude_recent_s`` (the exclusion window),
    ``min_inliers`` (8..10000), ``consistent_keyframes`` (1..100), ``odometry_gate``,
    ``odometry_max_rotation_deg``, ``odometry_max_translation_m`` and
    ``odometry_max_translation_per_m`` (the bound grows with the distance travelled between
    the two keyframes: the odometry's drift rate), the pinhole intrinsics
    ``fx``, ``fy``, ``cx``, ``cy`` (pixels; ``fx == 0``: none, hints carry no pose), and the
    place graph's ``novelty_similarity``, ``place_spacing_m``, ``neighbour_radius_m``, and
    ``candidate_id_gap`` (candidates from different stretches of ids; 0: off), and
    ``pose_reprojection_px`` (the metric pose fit's inlier threshold, pixels), and
    ``odometry_candidates`` and ``odometry_search_m`` (keyframes the odometry puts near the new
    one, checked besides appearance's candidates; 0: none). Invalid
    options raise :class:`InvalidOptionError`, unknown names ``TypeError``.

    Ownership: owns a C ``topoloc_loop_detector`` handle, released by :meth:`close`, the
    ``with`` statement or garbage collection. A map given to :meth:`from_map` is not kept.

    Thread safety: single-threaded state; use from one thread at a time (concurrent calls raise
    ``RuntimeError``).
    """

    def __init__(self, kind: str, model: str, dim: int, **options: Any) -> None:
        self._init_guard()
        self._free = lib.topoloc_loop_detector_free
        opts = _loop_options(options)
        out = _lib.LoopDetectorPtr()
        check(
            lib.topoloc_loop_detector_new(
                _text(kind, "kind"), _text(model, "model"), _u32(dim, "dim"), byref(opts), byref(out)
            )
        )
        self._finish_init(out, opts, int(dim))

    @classmethod
    def from_map(cls, map: Map, **options: Any) -> "LoopDetector":
        """A detector whose first session is ``map``'s views (with their stored keypoints and,
        where known, scene points; e.g. a map written by :meth:`save` and read with
        :meth:`Map.load`): new keyframes, with ids above the map's, close loops against it.
        Options as for the constructor. Raises :class:`InvalidOptionError` (also a view
        without keyframe id), :class:`InvalidArgumentError` (keyframe ids not increasing)."""
        if not isinstance(map, Map):
            raise TypeError(f"map must be a topoloc.Map, got {type(map).__name__}")
        self = cls.__new__(cls)
        self._init_guard()
        self._free = lib.topoloc_loop_detector_free
        opts = _loop_options(options)
        out = _lib.LoopDetectorPtr()
        check(lib.topoloc_loop_detector_from_map(map._h, byref(opts), byref(out)))
        self._finish_init(out, opts, map.dim)
        return self

    def _finish_init(self, ptr, options: _lib.topoloc_loop_options, dim: int) -> None:
        self._ptr = ptr
        self._options = _loop_options_dict(options)
        self._dim = dim
        # Reused per keyframe.
        self._keyframe = _lib.defaults(_lib.topoloc_loop_keyframe, lib.topoloc_loop_keyframe_init)
        self._hint = _lib.defaults(_lib.topoloc_loop_hint, lib.topoloc_loop_hint_init)

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
        out = c_size_t(0)
        h = self._enter("__len__")
        try:
            check(lib.topoloc_loop_detector_len(h, byref(out)))
        finally:
            self._leave()
        return int(out.value)

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
        kid = _int_in_range(id, "id", _U64_MAX, InvalidArgumentError)
        ts = float(timestamp)
        q = _descriptor(descriptor)
        if (keypoints is None) != (keypoint_descriptors is None):
            raise InvalidArgumentError("give keypoints and keypoint_descriptors together (or neither)")
        points = descriptors = scene = None
        n = 0
        if keypoints is not None:
            points = _keypoint_array(keypoints, "keypoints", 2, None)
            n = int(points.shape[0])
            descriptors = _binary_descriptors(keypoint_descriptors, n)
        if camera_points is not None:
            if points is None:
                raise InvalidArgumentError("camera_points needs keypoints (one scene point per keypoint)")
            scene = _keypoint_array(camera_points, "camera_points", 3, n)
        body = None if world_T_body is None else _pose(world_T_body, "world_T_body")
        camera = None if body_T_camera is None else _pose(body_T_camera, "body_T_camera")

        h = self._enter("add")
        try:
            kf, hint = self._keyframe, self._hint
            kf.struct_size = ctypes.sizeof(_lib.topoloc_loop_keyframe)
            kf.id = kid
            kf.timestamp = ts
            kf.descriptor = _f32_ptr(q)
            kf.descriptor_len = q.size
            kf.world_T_body = None if body is None else _f64_ptr(body)
            kf.body_T_camera = None if camera is None else _f64_ptr(camera)
            kf.keypoint_count = n
            kf.keypoints = None if points is None else _f32_ptr(points)
            kf.keypoint_descriptors = None if descriptors is None else descriptors.ctypes.data_as(POINTER(c_uint8))
            kf.camera_points = None if scene is None else _f32_ptr(scene)
            hint.struct_size = ctypes.sizeof(_lib.topoloc_loop_hint)
            try:
                check(lib.topoloc_loop_detector_add(h, byref(kf), byref(hint)))
            finally:
                kf.descriptor = None
                kf.descriptor_len = 0
                kf.world_T_body = kf.body_T_camera = None
                kf.keypoint_count = 0
                kf.keypoints = kf.keypoint_descriptors = kf.camera_points = None
            return _loop_hint(hint)
        finally:
            self._leave()
            del q, points, descriptors, scene, body, camera

    def confirmed(self) -> List[LoopHint]:
        """The hints of earlier keyframes that the last :meth:`add` confirmed (ABI 1.10),
        oldest first: when an added keyframe's hint is accepted because it completes a
        consistency streak, the streak's earlier keyframes, refused as
        :attr:`Gate.INCONSISTENT` while it was short, are accepted too (each with its own
        ``query_id``; at most one accepted hint per keyframe in all). Empty after an
        :meth:`add` whose hint was not accepted; replaced by the next :meth:`add`, kept by a
        failed one and by :meth:`erase`."""
        h = self._enter("confirmed")
        try:
            count = c_size_t(0)
            check(lib.topoloc_loop_detector_confirmed_count(h, byref(count)))
            hints = []
            for i in range(int(count.value)):
                raw = _lib.defaults(_lib.topoloc_loop_hint, lib.topoloc_loop_hint_init)
                check(lib.topoloc_loop_detector_confirmed(h, i, byref(raw)))
                hints.append(_loop_hint(raw))
            return hints
        finally:
            self._leave()

    def query(self, descriptor: ArrayLike, max_results: int) -> List[LoopCandidate]:
        """Relocalization: the (at most ``max_results``) keyframes most similar to
        ``descriptor`` (D floats; not added, and every keyframe may match), most similar
        first. Raises :class:`DimensionMismatchError`, :class:`NonFiniteError`,
        :class:`ZeroDescriptorError`."""
        q = _descriptor(descriptor)
        capacity = _int_in_range(max_results, "max_results", _U32_MAX, InvalidArgumentError)
        found = (_lib.topoloc_loop_candidate * max(capacity, 1))()
        count = c_size_t(0)
        h = self._enter("query")
        try:
            check(lib.topoloc_loop_detector_query(h, _f32_ptr(q), q.size, found, capacity, byref(count)))
        finally:
            self._leave()
        n = min(int(count.value), capacity)
        return [LoopCandidate(int(c.keyframe_id), int(c.place), float(c.similarity)) for c in found[:n]]

    def erase(self, id: int) -> None:
        """Removes keyframe ``id`` and its features (e.g. when SLAM culls it).
        Raises :class:`InvalidArgumentError` (no keyframe with that id)."""
        kid = _int_in_range(id, "id", _U64_MAX, InvalidArgumentError)
        h = self._enter("erase")
        try:
            check(lib.topoloc_loop_detector_erase(h, kid))
        finally:
            self._leave()

    def save(self, path: PathLike) -> None:
        """Saves the keyframes and their place graph as a topoloc map file (a view per
        keyframe, keyframe ids kept), atomically, for a later session: :meth:`Map.load`, then
        :meth:`from_map`. Raises :class:`MapIOError`, :class:`EmptyMapError`."""
        encoded = _path(path)
        h = self._enter("save")
        try:
            check(lib.topoloc_loop_detector_save(h, encoded))
        finally:
            self._leave()


def _loop_hint(hint: Any) -> LoopHint:
    """The :class:`LoopHint` of a C ``topoloc_loop_hint``."""
    return LoopHint(
        query_id=int(hint.query_id),
        query_place=int(hint.query_place),
        has_match=bool(hint.has_match),
        accepted=bool(hint.accepted),
        gate=_gate(int(hint.gate)),
        matched_id=int(hint.matched_id),
        place=int(hint.place),
        inliers=int(hint.inliers),
        confidence=float(hint.confidence),
        has_pose=bool(hint.has_pose),
        scale_known=bool(hint.scale_known),
        matched_T_query=_matrix(hint.matched_T_query, 4),
        covariance=_matrix(hint.covariance, 6),
    )


def _gate(code: int) -> Union[Gate, int]:
    """The :class:`Gate` of a code (a code from a newer library stays an int)."""
    try:
        return Gate(code)
    except ValueError:
        return code


# ---------------------------------------------------------------------------------------------
# Trajectory metrics (ABI 1.11)
# ---------------------------------------------------------------------------------------------

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
    o = _lib.defaults(_lib.topoloc_trajectory_options, lib.topoloc_trajectory_options_init)
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
    report = _lib.defaults(_lib.topoloc_trajectory_report, lib.topoloc_trajectory_report_init)
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
    report = _lib.defaults(_lib.topoloc_trajectory_report, lib.topoloc_trajectory_report_init)
    check(
        lib.topoloc_trajectory_evaluate_files(
            _path(reference_path, "reference_path"), _path(estimate_path, "estimate_path"),
            _TRAJECTORY_FORMATS[format], byref(o), byref(report),
        )
    )
    return _trajectory_report(report)
