"""Caller-owned structs with a leading ``struct_size`` (mirrors ``src/ffi/versioned.rs``):
options and results filled with the library's defaults by their ``_init`` functions (what the
header's ``*_default(p)`` macros do), and the library's own size of each struct."""

from __future__ import annotations

import ctypes
from ctypes import POINTER, Structure, c_size_t, c_uint64
from typing import Any, Callable, Tuple, Type, TypeVar

from ._errors import check

__all__ = ["defaults", "scratch_struct", "library_struct_size"]

S = TypeVar("S", bound=Structure)

#: A struct's ``_init`` function: ``topoloc_status (*)(T *p, size_t size)``.
InitFunction = Callable[[Any, int], int]

# Room the library may fill when asked for its own struct size (see library_struct_size).
_SCRATCH_BYTES = 4096


def scratch_struct(cls: Type[S]) -> Tuple[S, "ctypes.Array[c_uint64]"]:
    """A zeroed ``cls`` at the start of an oversized buffer; keep the buffer alive with it."""
    buf = (c_uint64 * (max(_SCRATCH_BYTES, ctypes.sizeof(cls)) // 8))()
    return cls.from_buffer(buf), buf


def defaults(cls: Type[S], init: InitFunction) -> S:
    """A ``cls`` filled by the library's ``_init`` function with this struct's own size: the
    library writes at most that many bytes and sets ``struct_size`` to it (what the C header's
    ``*_default(p)`` macros do with ``sizeof *(p)``)."""
    out = cls()
    check(init(ctypes.byref(out), ctypes.sizeof(cls)))
    return out


def library_struct_size(cls: Type[S], init: InitFunction) -> int:
    """The library's own ``sizeof`` of struct ``cls``: its ``_init`` function, offered an
    oversized buffer, writes ``struct_size = min(offered, sizeof)``."""
    tmp, buf = scratch_struct(cls)
    check(init(ctypes.byref(tmp), ctypes.sizeof(buf)))
    return int(ctypes.cast(buf, POINTER(c_size_t))[0])
