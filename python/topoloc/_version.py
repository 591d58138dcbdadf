"""Versions and status texts of the loaded library (mirrors ``src/ffi/version.rs``): its
version and C ABI version, the C name and English description of each status code, and the
calling thread's last error message."""

from __future__ import annotations

import ctypes
from typing import Optional

from ._lib import TOPOLOC_OK, lib

__all__ = [
    "abi_version",
    "abi_version_minor",
    "last_error_message",
    "status_name",
    "status_str",
    "version",
]

_U32_MASK = 0xFFFFFFFF


def version() -> str:
    """Version of the loaded library, ``"MAJOR.MINOR.PATCH"`` (``topoloc_version``)."""
    text: bytes = lib.topoloc_version()
    return text.decode("ascii")


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
    name: Optional[bytes] = lib.topoloc_status_name(int(status) & _U32_MASK)
    return None if name is None else name.decode("ascii")


def status_str(status: int) -> str:
    """Short English description of a status code (``topoloc_status_str``)."""
    text: bytes = lib.topoloc_status_str(int(status) & _U32_MASK)
    return text.decode("utf-8", errors="replace")


def last_error_message() -> str:
    """The calling thread's last error message ("" if none; ``topoloc_last_error_message``):
    reads the size first, then the text."""
    needed = ctypes.c_size_t(0)
    lib.topoloc_last_error_message(None, 0, ctypes.byref(needed))
    size = max(int(needed.value), 1)
    buf = ctypes.create_string_buffer(size)
    status = lib.topoloc_last_error_message(buf, size, ctypes.byref(needed))
    if status != TOPOLOC_OK:  # the message cannot change between the two calls on one thread
        return ""
    return buf.value.decode("utf-8", errors="replace")
