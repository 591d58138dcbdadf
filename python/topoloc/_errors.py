"""Exceptions raised by the topoloc Python bindings (mirrors ``src/ffi/status.rs`` and
``src/ffi/error.rs``).

Every failing C call returns a ``topoloc_status`` code; :func:`check` turns it into an instance of
the :class:`TopolocError` subclass for that code, carrying the code (``.status``) and the
thread's last error message from ``topoloc_last_error_message`` (``.message``).

The status table is the library's own: :data:`STATUS_NAMES` is read at import with
``topoloc_status_name``, and each subclass names the C status it stands for
(``STATUS_NAME``, e.g. ``"TOPOLOC_ERR_IO"``), its code (``STATUS``) being looked up by that
name. A code without a class (from a newer library) raises :class:`TopolocError` itself.

Some classes also derive from a matching built-in exception (``ValueError`` for bad arguments and
descriptors, ``IndexError`` for unknown ids) so that generic Python error handling works too.
"""

from __future__ import annotations

from typing import ClassVar, Dict, List, Optional, Tuple, Type

from ._lib import TOPOLOC_OK
from ._version import last_error_message, status_name

__all__ = [
    "STATUS_NAMES",
    "BackendUnavailableError",
    "BufferTooSmallError",
    "CancelledError",
    "ConcurrentUseError",
    "CorruptMapError",
    "DescriptorMismatchError",
    "DimensionMismatchError",
    "EmptyMapError",
    "InvalidArgumentError",
    "InvalidImageError",
    "InvalidMapError",
    "InvalidOptionError",
    "InvalidUTF8Error",
    "MapIOError",
    "ModelError",
    "NoDescriberError",
    "NonFiniteError",
    "NotAMapError",
    "NullArgumentError",
    "PanicError",
    "StructSizeError",
    "TimestampError",
    "TopolocError",
    "TruncatedMapError",
    "UninformativeImageError",
    "UnknownPlaceError",
    "UnknownViewError",
    "UnsupportedVersionError",
    "ZeroDescriptorError",
    "check",
    "error_class_for_status",
    "error_from_status",
]

#: Codes asked of ``topoloc_status_name`` at import: the ``topoloc_status`` enum groups its
#: values in ranges of a hundred, the last ending at 999 (see ``topoloc.h``).
_STATUS_CODES = range(1000)


def _library_status_names() -> Dict[int, str]:
    """Every status the loaded library names, by code (``topoloc_status_name``)."""
    names: Dict[int, str] = {}
    for code in _STATUS_CODES:
        name = status_name(code)
        if name is not None:
            names[code] = name
    return names


#: ``topoloc_status`` values of the loaded library, by value: its C name for each code it knows.
STATUS_NAMES: Dict[int, str] = _library_status_names()


class TopolocError(Exception):
    """A topoloc call failed.

    Attributes:
        status: the ``topoloc_status`` code (an ``int``; see :data:`STATUS_NAMES`).
        message: the detailed message recorded by the library for the failing call (or by the
            bindings when they reject an argument before calling the library).

    Subclasses fix ``status`` (class attributes ``STATUS_NAME`` and ``STATUS``); the base class
    is raised directly only for a status code these bindings have no class for (a newer library).
    """

    #: The code of the status this class stands for (looked up by :attr:`STATUS_NAME` in
    #: :data:`STATUS_NAMES` at import); ``None`` for the base class.
    STATUS: ClassVar[Optional[int]] = None
    #: The C name of that status, e.g. ``"TOPOLOC_ERR_IO"``; ``None`` for the base class.
    STATUS_NAME: ClassVar[Optional[str]] = None

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

    def __reduce__(self) -> Tuple[Type[TopolocError], Tuple[str, int]]:
        # Keep status and message when pickled (e.g. across processes).
        return (type(self), (self.message, self.status))


class NullArgumentError(TopolocError):
    """A required pointer argument was NULL (a bug in the caller or the bindings)."""

    STATUS_NAME = "TOPOLOC_ERR_NULL_ARGUMENT"


class InvalidArgumentError(TopolocError, ValueError):
    """An argument is out of its valid range; the message names it."""

    STATUS_NAME = "TOPOLOC_ERR_INVALID_ARGUMENT"


class BufferTooSmallError(TopolocError):
    """A caller buffer was too small (the bindings size buffers themselves and retry)."""

    STATUS_NAME = "TOPOLOC_ERR_BUFFER_TOO_SMALL"


class StructSizeError(TopolocError):
    """An options or result struct had a ``struct_size`` the library does not know."""

    STATUS_NAME = "TOPOLOC_ERR_STRUCT_SIZE"


class InvalidUTF8Error(TopolocError, ValueError):
    """A string argument (e.g. a ``bytes`` path) is not valid UTF-8."""

    STATUS_NAME = "TOPOLOC_ERR_INVALID_UTF8"


class ConcurrentUseError(TopolocError, RuntimeError):
    """A handle was used by two calls at once (two threads, or a callback re-entering it; ABI
    1.13). The shim refuses a second thread itself; the library's own check backs it up."""

    STATUS_NAME = "TOPOLOC_ERR_CONCURRENT_USE"


class MapIOError(TopolocError):
    """Reading or writing a map file failed (missing file, permissions, full disk...)."""

    STATUS_NAME = "TOPOLOC_ERR_IO"


class NotAMapError(TopolocError):
    """The file or bytes are not a topoloc map."""

    STATUS_NAME = "TOPOLOC_ERR_NOT_A_MAP"


class TruncatedMapError(TopolocError):
    """The map file ends early."""

    STATUS_NAME = "TOPOLOC_ERR_TRUNCATED"


class CorruptMapError(TopolocError):
    """The map file is damaged (checksum, inconsistent arrays, invalid values)."""

    STATUS_NAME = "TOPOLOC_ERR_CORRUPT"


class UnsupportedVersionError(TopolocError):
    """The map file has a newer major format version than this library reads."""

    STATUS_NAME = "TOPOLOC_ERR_UNSUPPORTED_VERSION"


class DescriptorMismatchError(TopolocError):
    """The map was built with another descriptor (kind, model or dimension) than expected."""

    STATUS_NAME = "TOPOLOC_ERR_DESCRIPTOR_MISMATCH"


class EmptyMapError(TopolocError):
    """The map (or the input to a builder) has no places."""

    STATUS_NAME = "TOPOLOC_ERR_EMPTY_MAP"


class InvalidMapError(TopolocError):
    """The map being built is inconsistent (e.g. a place without views)."""

    STATUS_NAME = "TOPOLOC_ERR_INVALID_MAP"


class UnknownPlaceError(TopolocError, IndexError):
    """A place id is out of range."""

    STATUS_NAME = "TOPOLOC_ERR_UNKNOWN_PLACE"


class UnknownViewError(TopolocError, IndexError):
    """A view id is out of range."""

    STATUS_NAME = "TOPOLOC_ERR_UNKNOWN_VIEW"


class DimensionMismatchError(TopolocError, ValueError):
    """A descriptor has the wrong number of values (or is not a 1-D array)."""

    STATUS_NAME = "TOPOLOC_ERR_DIMENSION_MISMATCH"


class NonFiniteError(TopolocError, ValueError):
    """A descriptor, pose, timestamp or number is NaN or infinite."""

    STATUS_NAME = "TOPOLOC_ERR_NON_FINITE"


class ZeroDescriptorError(TopolocError, ValueError):
    """A descriptor is all zeros and cannot be normalised."""

    STATUS_NAME = "TOPOLOC_ERR_ZERO_DESCRIPTOR"


class TimestampError(TopolocError, ValueError):
    """A frame timestamp is earlier than the previous frame's (filter mode); call ``reset()``
    to start a new sequence."""

    STATUS_NAME = "TOPOLOC_ERR_TIMESTAMP"


class InvalidOptionError(TopolocError, ValueError):
    """A localizer option is out of range."""

    STATUS_NAME = "TOPOLOC_ERR_INVALID_OPTION"


class InvalidImageError(TopolocError, ValueError):
    """An image is unusable: wrong shape or pixel format for its channels, zero or too large a
    size (the library accepts 1..8192 pixels a side), a bad stride, or an unreadable image file
    (the message names it)."""

    STATUS_NAME = "TOPOLOC_ERR_INVALID_IMAGE"


class UninformativeImageError(TopolocError, ValueError):
    """The image carries no place information (blank, constant, or no local feature found): the
    frame was not localized and the localizer state is unchanged."""

    STATUS_NAME = "TOPOLOC_ERR_UNINFORMATIVE_IMAGE"


class BackendUnavailableError(TopolocError):
    """A describing backend cannot be loaded: ONNX Runtime or the model file is missing or
    cannot be opened (the message names every path tried). Create the localizer with
    ``image_backend="none"`` to localize descriptors only."""

    STATUS_NAME = "TOPOLOC_ERR_BACKEND_UNAVAILABLE"


class ModelError(TopolocError):
    """The model file loaded but does not work (corrupt, missing outputs, run error), or a
    local-feature extractor failed."""

    STATUS_NAME = "TOPOLOC_ERR_MODEL"


class NoDescriberError(TopolocError):
    """A frame carries an image but the localizer cannot describe images: the map stores no
    describer (it was built from descriptors) or the localizer was created with
    ``image_backend="none"``; or a backend was required from a map that stores none."""

    STATUS_NAME = "TOPOLOC_ERR_NO_DESCRIBER"


class CancelledError(TopolocError):
    """The progress callback of a map build asked to stop (returned ``False``). Not raised
    when the callback itself raised: that exception is re-raised instead."""

    STATUS_NAME = "TOPOLOC_ERR_CANCELLED"


class PanicError(TopolocError):
    """A bug inside topoloc was caught at the C boundary; the object involved should be closed."""

    STATUS_NAME = "TOPOLOC_ERR_PANIC"


def _subclasses(cls: Type[TopolocError]) -> List[Type[TopolocError]]:
    """Every subclass of ``cls``, depth first."""
    out: List[Type[TopolocError]] = []
    for sub in cls.__subclasses__():
        out += [sub, *_subclasses(sub)]
    return out


#: The classes by the C name of their status.
_BY_NAME: Dict[str, Type[TopolocError]] = {
    cls.STATUS_NAME: cls for cls in _subclasses(TopolocError) if cls.STATUS_NAME is not None
}
#: The classes by status code, for the codes the library names.
_BY_STATUS: Dict[int, Type[TopolocError]] = {
    code: _BY_NAME[name] for code, name in STATUS_NAMES.items() if name in _BY_NAME
}
for _code, _cls in _BY_STATUS.items():
    _cls.STATUS = _code
del _code, _cls


def error_class_for_status(status: int) -> Type[TopolocError]:
    """The exception class for a status code (:class:`TopolocError` for unknown codes)."""
    return _BY_STATUS.get(int(status), TopolocError)


def error_from_status(status: int, message: str) -> TopolocError:
    """Builds the exception for a non-zero status code and its message."""
    return error_class_for_status(status)(message, int(status))


def check(status: int) -> None:
    """Raises the exception for a non-zero status, with the thread's last error message."""
    if status != TOPOLOC_OK:
        raise error_from_status(status, last_error_message())
