"""Describers (ABI 1.12; mirrors ``src/ffi/describer.rs``): :class:`Describer`, a map's
describer on its own.
"""

from __future__ import annotations

from ctypes import byref, c_size_t
from typing import Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import _IMAGE_BACKENDS, PathLike, _f32_ptr, _image
from ._errors import InvalidOptionError, check
from ._handles import _SingleThreaded
from ._lib import lib
from ._map import Map
from ._options import OptionTable, choice, file_path, unsigned

__all__ = ["Describer"]

#: The :class:`Describer` options: the fields of ``topoloc_describer_options``.
DESCRIBER_OPTIONS = OptionTable(
    "describer",
    _lib.topoloc_describer_options,
    lib.topoloc_describer_options_init,
    InvalidOptionError,
    [
        choice("backend", _IMAGE_BACKENDS),
        file_path("onnx_model_path"),
        file_path("onnx_runtime_path"),
        unsigned("threads"),
    ],
)


class Describer(_SingleThreaded):
    """A map's describer on its own (ABI 1.12): camera images to global descriptors exactly
    as the map's views were described, e.g. for :meth:`LoopDetector.add` or
    :meth:`Localizer.process`.

    ``map``: a :class:`Map` built from images (it stores its describer; otherwise
    :class:`NoDescriberError`). Options are keyword-only, named as the fields of
    ``topoloc_describer_options`` in ``topoloc.h``, which documents each one's default and
    range; left out or ``None``: the library's default. ``backend``: ``"auto"`` (the map's),
    or ``"onnx"``, ``"vlad-orb"``, ``"vlad-sift"`` to require it
    (:class:`DescriptorMismatchError` otherwise). ``onnx_model_path`` / ``onnx_runtime_path``
    override where the ONNX model (the very file the map was built with) and runtime are
    found; ``threads``: ONNX Runtime's intra-op threads. A value out of range raises
    :class:`InvalidOptionError`; loading fails with :class:`BackendUnavailableError` or
    :class:`ModelError`.

    Ownership: owns a C ``topoloc_describer`` handle, released by :meth:`close`, the ``with``
    statement or garbage collection; the map is not kept.

    Thread safety: single-threaded state; use from one thread at a time (concurrent calls
    raise ``RuntimeError``); one describer per thread for parallel work.
    """

    def __init__(
        self,
        map: Map,
        *,
        backend: Optional[Union[str, int]] = None,
        onnx_model_path: Optional[PathLike] = None,
        onnx_runtime_path: Optional[PathLike] = None,
        threads: Optional[int] = None,
    ) -> None:
        given = DESCRIBER_OPTIONS.pick(locals())
        self._init_guard()
        self._free = lib.topoloc_describer_free
        if not isinstance(map, Map):
            raise TypeError(f"map must be a topoloc.Map, got {type(map).__name__}")
        options = DESCRIBER_OPTIONS.fill(given)
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

    def describe(self, image: ArrayLike, pixel_format: Optional[str] = None) -> NDArray[np.float32]:
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
