"""Ownership of C handles (mirrors ``src/ffi/handles.rs``): an object owning one handle, and the
single-threaded variant that refuses concurrent use.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any, Callable, Iterator, TypeVar

from ._convert import _out_call
from ._errors import ConcurrentUseError, check

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
        _ = self._h  # refuse a closed object
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass


class _SingleThreaded(_Handle):
    """Detects concurrent use of a single-threaded C object (which would be undefined
    behaviour) and raises :class:`ConcurrentUseError` (a ``RuntimeError``) instead, as the library
    itself does (``TOPOLOC_ERR_CONCURRENT_USE``)."""

    def _init_guard(self) -> None:
        self._busy = threading.Lock()

    def _open(
        self, free: Callable[[Any], Any], ptr_type: Any, new: Callable[..., int], *args: Any
    ) -> Any:
        """Creates the handle with ``new(*args, &handle)``, to be released with ``free``; the
        first call of ``__init__`` (``close`` works even when ``new`` fails)."""
        self._init_guard()
        self._free = free
        self._ptr = _out_call(ptr_type, new, *args)
        return self._ptr

    def _enter(self, what: str) -> Any:
        if not self._busy.acquire(blocking=False):
            raise ConcurrentUseError(
                f"{type(self).__name__}.{what} called while another thread uses this object"
            )
        if not self._ptr:
            self._busy.release()
            raise ValueError(f"operation on a closed topoloc.{type(self).__name__}")
        return self._ptr

    def _leave(self) -> None:
        self._busy.release()

    @contextlib.contextmanager
    def _using(self, what: str) -> Iterator[Any]:
        """``with self._using("method") as h``: the handle, held by this thread until the block
        ends (:meth:`_enter` and :meth:`_leave`)."""
        h = self._enter(what)
        try:
            yield h
        finally:
            self._leave()

    def _call(self, what: str, fn: Callable[..., int], *args: Any) -> None:
        """Calls ``fn(handle, *args)`` for method ``what`` and checks its status."""
        with self._using(what) as h:
            check(fn(h, *args))

    def close(self) -> None:
        """Releases the C handle (idempotent)."""
        busy = getattr(self, "_busy", None)
        if busy is None:  # __init__ failed before the handle existed
            return
        with busy:
            super().close()
