"""Versions of the loaded library and the names and descriptions of its status codes
(mirrors ``src/ffi/version.rs``).
"""

from __future__ import annotations

from typing import Optional


from . import _lib
from ._lib import lib

__all__ = ['version', 'abi_version', 'abi_version_minor', 'status_name', 'status_str']


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
