"""Describers (ABI 1.12; mirrors ``src/ffi/describer.rs``): :class:`Describer`, a map's
describer on its own.
"""

from __future__ import annotations

from ctypes import byref, c_size_t
from typing import Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import _IMAGE_BACKENDS, PathLike, _f32_ptr, _image, _out_call
from ._errors import InvalidOptionError
from ._handles import _SingleThreaded
from ._lib import lib
from ._map import Map, _map_handle
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
        handle = _map_handle(map)
        options = DESCRIBER_OPTIONS.fill(given)
        free, new = lib.topoloc_describer_free, lib.topoloc_describer_new
        h = self._open(free, _lib.DescriberPtr, new, handle, byref(options))
        self._dim = int(_out_call(c_size_t, lib.topoloc_describer_dim, h).value)

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
        describe = lib.topoloc_describer_describe
        self._call("describe", describe, byref(img), _f32_ptr(out), out.size, None)
        del pixels  # kept alive until here: img points into it
        return out

    def __repr__(self) -> str:
        state = "closed" if not self._ptr else f"dim={self._dim}"
        return f"<topoloc.Describer {state}>"
