"""Exceptions raised by the topoloc Python bindings.

Every failing C call returns a ``topoloc_status`` code; the bindings turn it into an instance of
the :class:`TopolocError` subclass registered for that code, carrying the code (``.status``) and
the thread's last error message from ``topoloc_last_error_message`` (``.message``).

Some classes also derive from a matching built-in exception (``ValueError`` for bad arguments and
descriptors, ``IndexError`` for unknown ids) so that generic Python error handling works too.

This module does not load the shared library: it only defines the classes and the mapping.
"""

from __future__ import annotations

from typing import Dict, Optional, Type

__all__ = [
    "TopolocError",
    "NullArgumentError",
    "InvalidArgumentError",
    "BufferTooSmallError",
    "StructSizeError",
    "InvalidUTF8Error",
    "MapIOError",
    "NotAMapError",
    "TruncatedMapError",
    "CorruptMapError",
    "UnsupportedVersionError",
    "DescriptorMismatchError",
    "EmptyMapError",
    "InvalidMapError",
    "UnknownPlaceError",
    "UnknownViewError",
    "DimensionMismatchError",
    "NonFiniteError",
    "ZeroDescriptorError",
    "TimestampError",
    "InvalidOptionError",
    "InvalidImageError",
    "UninformativeImageError",
    "BackendUnavailableError",
    "ModelError",
    "NoDescriberError",
    "CancelledError",
    "ConcurrentUseError",
    "PanicError",
    "STATUS_NAMES",
    "error_class_for_status",
    "error_from_status",
]

#: ``topoloc_status`` values of the C header, by value (they are never renumbered).
STATUS_NAMES: Dict[int, str] = {
    0: "TOPOLOC_OK",
    1: "TOPOLOC_ERR_NULL_ARGUMENT",
    2: "TOPOLOC_ERR_INVALID_ARGUMENT",
    3: "TOPOLOC_ERR_BUFFER_TOO_SMALL",
    4: "TOPOLOC_ERR_STRUCT_SIZE",
    5: "TOPOLOC_ERR_INVALID_UTF8",
    6: "TOPOLOC_ERR_CONCURRENT_USE",
    100: "TOPOLOC_ERR_IO",
    101: "TOPOLOC_ERR_NOT_A_MAP",
    102: "TOPOLOC_ERR_TRUNCATED",
    103: "TOPOLOC_ERR_CORRUPT",
    104: "TOPOLOC_ERR_UNSUPPORTED_VERSION",
    105: "TOPOLOC_ERR_DESCRIPTOR_MISMATCH",
    106: "TOPOLOC_ERR_EMPTY_MAP",
    107: "TOPOLOC_ERR_INVALID_MAP",
    108: "TOPOLOC_ERR_UNKNOWN_PLACE",
    109: "TOPOLOC_ERR_UNKNOWN_VIEW",
    200: "TOPOLOC_ERR_DIMENSION_MISMATCH",
    201: "TOPOLOC_ERR_NON_FINITE",
    202: "TOPOLOC_ERR_ZERO_DESCRIPTOR",
    203: "TOPOLOC_ERR_TIMESTAMP",
    204: "TOPOLOC_ERR_INVALID_OPTION",
    300: "TOPOLOC_ERR_INVALID_IMAGE",
    301: "TOPOLOC_ERR_UNINFORMATIVE_IMAGE",
    302: "TOPOLOC_ERR_BACKEND_UNAVAILABLE",
    303: "TOPOLOC_ERR_MODEL",
    304: "TOPOLOC_ERR_NO_DESCRIBER",
    305: "TOPOLOC_ERR_CANCELLED",
    900: "TOPOLOC_ERR_PANIC",
}


class TopolocError(Exception):
    """A topoloc call failed.

    Attributes:
        status: the ``topoloc_status`` code (an ``int``; see :data:`STATUS_NAMES`).
        message: the detailed message recorded by the library for the failing call (or by the
            bindings when they reject an argument before calling the library).

    Subclasses fix ``status`` (class attribute ``STATUS``); the base class is raised directly
    only for a status code these bindings do not know (a newer library).
    """

    STATUS: Optional[int] = None

    def __init__(self, message: str = "", status: Optional[int] = None) -> None:
        if status is None:
            status = self.STATUS if self.STATUS is not None else -1
        self.status: int = int(status)
        self.message: str = str(message)
        super().__init__(self.message)

    @property
    def status_name(self) -> str:
        """Symbolic name of :attr:`status`, e.g. ``"TOPOLOC_ERR_TIMESTAMP"``."""
        return STATUS_NAMES.get(self.status, f"unknown status {self.status}")

    def __str__(self) -> str:
        text = self.message or "(no message)"
        return f"{text} [{self.status_name} = {self.status}]"

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.message!r}, status={self.status})"

    def __reduce__(self):  # keep status and message when pickled (e.g. across processes)
        return (type(self), (self.message, self.status))


class NullArgumentError(TopolocError):
    """A required pointer argument was NULL (a bug in the caller or the bindings)."""

    STATUS = 1


class InvalidArgumentError(TopolocError, ValueError):
    """An argument is out of its valid range; the message names it."""

    STATUS = 2


class BufferTooSmallError(TopolocError):
    """A caller buffer was too small (the bindings size buffers themselves and retry)."""

    STATUS = 3


class StructSizeError(TopolocError):
    """An options or result struct had a ``struct_size`` the library does not know."""

    STATUS = 4


class InvalidUTF8Error(TopolocError, ValueError):
    """A string argument (e.g. a ``bytes`` path) is not valid UTF-8."""

    STATUS = 5


class ConcurrentUseError(TopolocError, RuntimeError):
    """A handle was used by two calls at once (two threads, or a callback re-entering it; ABI
    1.13). The shim refuses a second thread itself; the library's own check backs it up."""

    STATUS = 6


class MapIOError(TopolocError):
    """Reading or writing a map file failed (missing file, permissions, full disk...)."""

    STATUS = 100


class NotAMapError(TopolocError):
    """The file or bytes are not a topoloc map."""

    STATUS = 101


class TruncatedMapError(TopolocError):
    """The map file ends early."""

    STATUS = 102


class CorruptMapError(TopolocError):
    """The map file is damaged (checksum, inconsistent arrays, invalid values)."""

    STATUS = 103


class UnsupportedVersionError(TopolocError):
    """The map file has a newer major format version than this library reads."""

    STATUS = 104


class DescriptorMismatchError(TopolocError):
    """The map was built with another descriptor (kind, model or dimension) than expected."""

    STATUS = 105


class EmptyMapError(TopolocError):
    """The map (or the input to a builder) has no places."""

    STATUS = 106


class InvalidMapError(TopolocError):
    """The map being built is inconsistent (e.g. a place without views)."""

    STATUS = 107


class UnknownPlaceError(TopolocError, IndexError):
    """A place id is out of range."""

    STATUS = 108


class UnknownViewError(TopolocError, IndexError):
    """A view id is out of range."""

    STATUS = 109


class DimensionMismatchError(TopolocError, ValueError):
    """A descriptor has the wrong number of values (or is not a 1-D array)."""

    STATUS = 200


class NonFiniteError(TopolocError, ValueError):
    """A descriptor, pose, timestamp or number is NaN or infinite."""

    STATUS = 201


class ZeroDescriptorError(TopolocError, ValueError):
    """A descriptor is all zeros and cannot be normalised."""

    STATUS = 202


class TimestampError(TopolocError, ValueError):
    """A frame timestamp is earlier than the previous frame's (filter mode); call ``reset()``
    to start a new sequence."""

    STATUS = 203


class InvalidOptionError(TopolocError, ValueError):
    """A localizer option is out of range."""

    STATUS = 204


class InvalidImageError(TopolocError, ValueError):
    """An image is unusable: wrong shape or pixel format for its channels, zero or too large a
    size (the library accepts 1..8192 pixels a side), a bad stride, or an unreadable image file
    (the message names it)."""

    STATUS = 300


class UninformativeImageError(TopolocError, ValueError):
    """The image carries no place information (blank, constant, or no local feature found): the
    frame was not localized and the localizer state is unchanged."""

    STATUS = 301


class BackendUnavailableError(TopolocError):
    """A describing backend cannot be loaded: ONNX Runtime or the model file is missing or
    cannot be opened (the message names every path tried). Create the localizer with
    ``image_backend="none"`` to localize descriptors only."""

    STATUS = 302


class ModelError(TopolocError):
    """The model file loaded but does not work (corrupt, missing outputs, run error), or a
    local-feature extractor failed."""

    STATUS = 303


class NoDescriberError(TopolocError):
    """A frame carries an image but the localizer cannot describe images: the map stores no
    describer (it was built from descriptors) or the localizer was created with
    ``image_backend="none"``; or a backend was required from a map that stores none."""

    STATUS = 304


class CancelledError(TopolocError):
    """The progress callback of a map build asked to stop (returned ``False``). Not raised
    when the callback itself raised: that exception is re-raised instead."""

    STATUS = 305


class PanicError(TopolocError):
    """A bug inside topoloc was caught at the C boundary; the object involved should be closed."""

    STATUS = 900


_BY_STATUS: Dict[int, Type[TopolocError]] = {
    cls.STATUS: cls
    for cls in (
        NullArgumentError,
        InvalidArgumentError,
        BufferTooSmallError,
        StructSizeError,
        InvalidUTF8Error,
        ConcurrentUseError,
        MapIOError,
        NotAMapError,
        TruncatedMapError,
        CorruptMapError,
        UnsupportedVersionError,
        DescriptorMismatchError,
        EmptyMapError,
        InvalidMapError,
        UnknownPlaceError,
        UnknownViewError,
        DimensionMismatchError,
        NonFiniteError,
        ZeroDescriptorError,
        TimestampError,
        InvalidOptionError,
        InvalidImageError,
        UninformativeImageError,
        BackendUnavailableError,
        ModelError,
        NoDescriberError,
        CancelledError,
        PanicError,
    )
}


def error_class_for_status(status: int) -> Type[TopolocError]:
    """The exception class for a status code (:class:`TopolocError` for unknown codes)."""
    return _BY_STATUS.get(int(status), TopolocError)


def error_from_status(status: int, message: str) -> TopolocError:
    """Builds the exception for a non-zero status code and its message."""
    return error_class_for_status(status)(message, int(status))
