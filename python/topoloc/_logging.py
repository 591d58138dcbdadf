"""The library's log records in Python's :mod:`logging` (ABI 1.13).

At import the bridge is installed at ``WARNING``: records of the library (target
``topoloc::map::file`` becomes the logger ``topoloc.map.file``) and of ONNX Runtime (logger
``onnxruntime``) reach ``logging``, whose handlers decide what is shown. More detail with
:func:`set_log_level` (``logging.INFO``: maps loaded and saved, backends loaded;
``logging.DEBUG``: loop decisions per keyframe; :data:`TRACE`: per frame). Records are dropped
inside the library, before formatting, when they are more verbose than that level, so the
default costs nothing per frame. The library itself never writes to stdout or stderr.
"""

from __future__ import annotations

import atexit
import logging
import threading
from typing import Optional

from . import _lib
from ._errors import check

__all__ = ["TRACE", "log_level", "set_log_level"]

#: Python level of the library's ``TRACE`` records (below ``logging.DEBUG``).
TRACE = 5

# topoloc_log_level -> Python level
_TO_PYTHON = {1: logging.ERROR, 2: logging.WARNING, 3: logging.INFO, 4: logging.DEBUG, 5: TRACE}

_lock = threading.Lock()
_level: Optional[int] = None


def _forward(level: int, target: bytes, message: bytes, _user_data: object) -> None:
    # Runs on whichever thread the library logs from; ctypes takes the GIL. Never raises into C.
    try:
        name = target.decode("utf-8", errors="replace").replace("::", ".")
        logging.getLogger(name).log(
            _TO_PYTHON.get(level, logging.ERROR), "%s", message.decode("utf-8", errors="replace")
        )
    except Exception:  # a logging failure must not unwind into the library
        pass


# Kept alive for as long as the library may call it.
_CALLBACK = _lib.topoloc_log_fn(_forward)


def _library_level(python_level: int) -> int:
    """The most verbose ``TOPOLOC_LOG_*`` level whose records pass ``python_level``."""
    if python_level > logging.CRITICAL:
        return 0
    for code in (5, 4, 3, 2, 1):
        if _TO_PYTHON[code] >= python_level:
            return code
    return 1


def set_log_level(level: int) -> None:
    """Forwards the library's records of ``level`` (a :mod:`logging` level) and more severe to
    :mod:`logging`; above ``logging.CRITICAL`` turns the bridge off. Thread-safe.

    Raises :class:`~topoloc.InvalidArgumentError` when another Rust ``log`` logger owns the
    process, :class:`~topoloc.ConcurrentUseError` when called from inside a log handler."""
    global _level
    level = int(level)
    code = _library_level(level)
    with _lock:
        if code == 0:
            check(_lib.lib.topoloc_set_log_callback(_lib.topoloc_log_fn(), 0, None))
        else:
            check(_lib.lib.topoloc_set_log_callback(_CALLBACK, code, None))
        _level = level


def log_level() -> Optional[int]:
    """The level last given to :func:`set_log_level` (``logging.WARNING`` after import)."""
    return _level


def _off_at_exit() -> None:
    # No record may reach Python while the interpreter shuts down.
    try:
        _lib.lib.topoloc_set_log_callback(_lib.topoloc_log_fn(), 0, None)
    except Exception:
        pass


set_log_level(logging.WARNING)
atexit.register(_off_at_exit)
