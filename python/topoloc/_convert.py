"""Argument conversion and checks between Python values and the C ABI (mirrors
``src/ffi/convert.rs`` and the checks of ``src/ffi/boundary.rs``): integers, numbers, names of
enum codes, descriptors, poses, keypoint arrays, strings and paths; pointers into numpy arrays;
images and their pixel formats; reading strings and arrays that the library writes into caller
buffers.

Each check raises a typed error naming the argument (``name``) before the library is called.
"""

from __future__ import annotations

import ctypes
import operator
import os
from ctypes import POINTER, byref, c_double, c_float, c_size_t, c_uint8, c_uint32
from dataclasses import fields
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, Tuple, Type, TypeVar, Union

import numpy as np
from numpy.typing import NDArray

from . import _lib
from ._errors import (
    DimensionMismatchError,
    InvalidArgumentError,
    InvalidImageError,
    InvalidUTF8Error,
    TopolocError,
    check,
)

#: What the bindings accept as a file path: ``str``, ``bytes`` or an ``os.PathLike``.
PathLike = Union[str, bytes, "os.PathLike[str]", "os.PathLike[bytes]"]
#: A C function that the bindings call (its status or value).
CFunction = Callable[..., Any]

if TYPE_CHECKING:
    from _ctypes import _CData

    from _typeshed import DataclassInstance

_C = TypeVar("_C", bound="_CData")
_D = TypeVar("_D", bound="DataclassInstance")

_U32_MAX = 0xFFFFFFFF
_U64_MAX = 0xFFFFFFFFFFFFFFFF

# ---------------------------------------------------------------------------------------------
# Numbers, names, strings and paths
# ---------------------------------------------------------------------------------------------


def _int_in_range(value: Any, name: str, high: int, error: Type[TopolocError]) -> int:
    """``value`` as an integer in ``[0, high]``: ``TypeError`` for a non-integer, ``error``
    out of range."""
    try:
        v = operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}") from None
    if not 0 <= v <= high:
        raise error(f"{name} {v} is out of range: expected an integer in [0, {high}]")
    return v


def _u32(value: Any, name: str, error: Type[TopolocError] = InvalidArgumentError) -> int:
    """``value`` as a ``uint32_t``."""
    return _int_in_range(value, name, _U32_MAX, error)


def _u64(value: Any, name: str, error: Type[TopolocError] = InvalidArgumentError) -> int:
    """``value`` as a ``uint64_t``."""
    return _int_in_range(value, name, _U64_MAX, error)


def _real(value: Any, name: str, error: Type[TopolocError] = InvalidArgumentError) -> float:
    """``value`` as a ``float``/``double``; ``TypeError`` for what is not a real number (the
    library checks the range: NaN and infinities included)."""
    if isinstance(value, (str, bytes, bytearray)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}") from None


def _code(value: Any, name: str, codes: Mapping[str, int], error: Type[TopolocError]) -> int:
    """A C enum code from its name in ``codes`` (case and ``-``/``_`` ignored: ``"vlad_orb"``
    is ``"vlad-orb"``) or from the code itself."""
    if isinstance(value, str):
        wanted = _name_key(value)
        for known, code in codes.items():
            if _name_key(known) == wanted:
                return code
        raise error(f"{name} must be one of {', '.join(repr(k) for k in codes)}, got {value!r}")
    return _u32(value, name, error)


def _name_key(name: str) -> str:
    return name.lower().replace("_", "-")


def _code_name(code: int, codes: Mapping[str, int]) -> Union[str, int]:
    """The name of ``code`` in ``codes`` (a code without a name, from a newer library, stays an
    int)."""
    return next((k for k, v in codes.items() if v == code), code)


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
    """The bytes of a file path for the library (``str`` paths as the file system encodes them)."""
    data = os.fsencode(value)  # str paths: UTF-8 (surrogateescape), bytes paths: unchanged
    if b"\0" in data:
        raise InvalidArgumentError(f"{name} contains a NUL character")
    return data


# ---------------------------------------------------------------------------------------------
# Arrays and pointers into them
# ---------------------------------------------------------------------------------------------


def _real_array(values: Any, name: str) -> NDArray[Any]:
    """``values`` as an array of real numbers: ``TypeError`` for complex, boolean, string or
    object elements (which a cast to float would change or drop silently)."""
    arr = np.asarray(values)
    if arr.size and arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be an array of real numbers, got dtype {arr.dtype}")
    return arr


def _descriptor(values: Any, name: str = "descriptor") -> NDArray[np.float32]:
    """A C-contiguous float32 1-D copy (or view) of ``values``."""
    arr = _real_array(values, name)
    if arr.ndim != 1:
        raise DimensionMismatchError(f"{name} must be a 1-D array of floats, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _pose(values: Any, name: str) -> NDArray[np.float64]:
    """A C-contiguous (row-major) float64 4x4 array."""
    arr = _real_array(values, name)
    if arr.shape != (4, 4):
        raise InvalidArgumentError(f"{name} must be a 4x4 matrix, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _keypoint_array(
    values: Any, name: str, columns: int, count: Optional[int]
) -> NDArray[np.float32]:
    """A C-contiguous float32 (N, columns) array; ``count``: the N it must have."""
    arr = _real_array(values, name).astype(np.float32, copy=False)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise InvalidArgumentError(f"{name} must be an (N, {columns}) array, got shape {arr.shape}")
    if count is not None and arr.shape[0] != count:
        raise InvalidArgumentError(
            f"{name} has {arr.shape[0]} rows but keypoints has {count}: one row per keypoint"
        )
    return np.ascontiguousarray(arr, dtype=np.float32)


def _f32_ptr(arr: NDArray[np.float32]) -> ctypes._Pointer[c_float]:
    """A ``float *`` to the first value of a C-contiguous float32 array."""
    return arr.ctypes.data_as(POINTER(c_float))


def _f64_ptr(arr: NDArray[np.float64]) -> ctypes._Pointer[c_double]:
    """A ``double *`` to the first value of a C-contiguous float64 array."""
    return arr.ctypes.data_as(POINTER(c_double))


def _u8_ptr(arr: NDArray[np.uint8]) -> ctypes._Pointer[c_uint8]:
    """A ``uint8_t *`` to the first value of a uint8 array."""
    return arr.ctypes.data_as(POINTER(c_uint8))


def _matrix(values: ctypes.Array[c_double], n: int) -> NDArray[np.float64]:
    """A new (n, n) float64 array from a C ``double[n * n]`` in row-major order."""
    return np.array(values[:], dtype=np.float64).reshape(n, n)


# ---------------------------------------------------------------------------------------------
# Images
# ---------------------------------------------------------------------------------------------

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

#: Names of the describing backends (``TOPOLOC_BACKEND_*``) of localizers and describers.
_IMAGE_BACKENDS = {
    "auto": _lib.BACKEND_AUTO,
    "none": _lib.BACKEND_NONE,
    "onnx": _lib.BACKEND_ONNX,
    "vlad-orb": _lib.BACKEND_VLAD_ORB,
    "vlad-sift": _lib.BACKEND_VLAD_SIFT,
}


def _pixel_format(pixel_format: Optional[str], channels: int, name: str) -> int:
    """The ``TOPOLOC_PIXEL_*`` code for ``pixel_format`` (``None``: the default for
    ``channels``), checked against the array's channel count."""
    if pixel_format is None:
        pixel_format = _DEFAULT_FORMAT[channels]
    if not isinstance(pixel_format, str):
        raise TypeError(f"pixel_format must be a str, got {type(pixel_format).__name__}")
    key = pixel_format.lower()
    if key not in _PIXEL_FORMATS:
        known = ", ".join(repr(k) for k in _PIXEL_FORMATS)
        raise InvalidImageError(f"pixel_format {pixel_format!r} is not one of {known}")
    code, wanted = _PIXEL_FORMATS[key]
    if wanted != channels:
        raise InvalidImageError(
            f"{name} has {channels} channel(s) but pixel_format {pixel_format!r} has {wanted}"
        )
    return code


def _rows_packed(arr: NDArray[np.uint8], channels: int) -> bool:
    """Whether ``arr`` (H, W) or (H, W, C) of uint8 has contiguous pixels within each row and
    rows at a positive stride of at least one row's bytes, the layout ``topoloc_image``
    describes."""
    h, w = arr.shape[:2]
    strides = arr.strides
    if arr.ndim == 3 and strides[2] != 1:
        return False
    if w > 1 and strides[1] != channels:
        return False
    return bool(h == 1 or strides[0] >= w * channels)


def _image(
    image: Any, pixel_format: Optional[str], name: str
) -> Tuple[_lib.topoloc_image, NDArray[np.uint8]]:
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
        raise InvalidImageError(
            f"{name} has shape {arr.shape}: width and height must be at least 1"
        )
    if h > _U32_MAX or w > _U32_MAX:
        raise InvalidImageError(f"{name} has shape {arr.shape}: too large")
    if arr.ndim == 3 and channels == 1:
        arr = arr[:, :, 0]
    if not _rows_packed(arr, channels):
        arr = np.ascontiguousarray(arr)
    row = w * channels
    stride = int(arr.strides[0]) if h > 1 else row
    out = _lib.topoloc_image()
    out.data = _u8_ptr(arr)
    out.data_len = stride * (h - 1) + row
    out.width = w
    out.height = h
    out.stride = stride
    out.format = fmt
    return out, arr


# ---------------------------------------------------------------------------------------------
# Reading what the library writes into caller buffers
# ---------------------------------------------------------------------------------------------


def _out_call(out_type: Type[_C], fn: CFunction, *args: Any) -> _C:
    """Calls ``fn(*args, &out)`` with a new ``out_type`` (a ctypes value or pointer type), raises
    the exception for a failing status, and returns ``out``."""
    out = out_type()
    check(fn(*args, byref(out)))
    return out


def _from_struct(cls: Type[_D], struct: Any, **computed: Any) -> _D:
    """A ``cls`` (a dataclass of the package) whose fields are ``computed`` or else the C
    ``struct``'s fields of the same names (ctypes reads them as ``int``, ``float`` or ``bool``)."""
    names = [f.name for f in fields(cls)]
    return cls(**{n: computed[n] if n in computed else getattr(struct, n) for n in names})


def _read_string(fn: CFunction, *args: Any) -> str:
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


def _read_array(
    fn: CFunction,
    *args: Any,
    ctype: Any = c_uint32,
    dtype: Any = np.uint32,
    width: int = 1,
) -> NDArray[Any]:
    """Calls a ``(..., T *buf, size_t len, size_t *count)`` function, growing the buffer:
    ``*count`` items of ``width`` values each, ``len`` counting values. Returns a new
    ``(count,)`` array, or ``(count, width)`` for ``width`` > 1 (``uint32_t`` values unless
    ``ctype`` and ``dtype`` say otherwise)."""
    count = c_size_t(0)
    capacity = 16
    for _ in range(2):
        out: NDArray[Any] = np.empty(capacity * width, dtype=dtype)
        status = fn(*args, out.ctypes.data_as(POINTER(ctype)), out.size, byref(count))
        if status == _lib.TOPOLOC_ERR_BUFFER_TOO_SMALL and count.value > capacity:
            capacity = int(count.value)
            continue
        check(status)
        n = int(count.value)
        items: NDArray[Any] = out[: n * width].copy()
        return items if width == 1 else items.reshape(n, width)
    check(status)  # pragma: no cover
    raise AssertionError("unreachable")
