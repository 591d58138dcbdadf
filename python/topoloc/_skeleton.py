"""Skeleton graphs from occupancy grids (mirrors ``src/ffi/skeleton.rs``): :class:`Graph` and
:func:`skeleton_graph`.
"""

from __future__ import annotations

from ctypes import byref, c_double, c_size_t, c_uint32
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple, Type

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _lib
from ._convert import _f64_ptr, _int_in_range, _out_call, _read_array, _real, _u8_ptr
from ._errors import InvalidArgumentError, TopolocError, UnknownPlaceError, check
from ._lib import lib
from ._options import Option, OptionTable, real

__all__ = ["Graph", "skeleton_graph", "skeleton_options_default"]

#: ``TOPOLOC_NODE_*`` codes by name, in code order.
NODE_KINDS = ("end", "corner", "branch", "intermediate")


@dataclass(frozen=True, eq=False)
class Graph:
    """A topological graph built from an occupancy grid by :func:`skeleton_graph`.

    Plain numpy arrays (copied out of the library; nothing to close):

    - ``positions``: (N, 3) float64, world position of each place in metres (the centre of its
      skeleton voxel);
    - ``kinds``: (N,) uint32 ``TOPOLOC_NODE_*`` codes, ``kind_names`` the same as strings
      (``"end"``, ``"corner"``, ``"branch"``, ``"intermediate"``); places come in the order
      branches, ends, corners, then intermediate places;
    - ``edges``: (E, 2) uint32 place pairs ``a < b``, sorted; ``lengths``: (E,) float64, the
      straight distance between them in metres;
    - ``skeleton``: (S, 3) int64 voxel indices ``(x, y, z)`` of the skeleton the graph was built
      on, in grid order (``occupied[tuple(graph.skeleton.T)]`` is all False).
    """

    positions: NDArray[np.float64]
    kinds: NDArray[np.uint32]
    edges: NDArray[np.uint32]
    lengths: NDArray[np.float64]
    skeleton: NDArray[np.int64]

    @property
    def place_count(self) -> int:
        """Number of places N."""
        return int(self.positions.shape[0])

    @property
    def edge_count(self) -> int:
        """Number of undirected edges E."""
        return int(self.edges.shape[0])

    @property
    def kind_names(self) -> List[str]:
        """The kind of each place as a string: ``"end"``, ``"corner"``, ``"branch"`` or
        ``"intermediate"``."""
        return [NODE_KINDS[k] for k in self.kinds]

    def kind_counts(self) -> Dict[str, int]:
        """Number of places of each kind, e.g. ``{"end": 2, "corner": 0, ...}``."""
        counts = np.bincount(self.kinds, minlength=len(NODE_KINDS))
        return {name: int(counts[i]) for i, name in enumerate(NODE_KINDS)}

    def neighbours(self, place: int) -> NDArray[np.uint32]:
        """Places joined to ``place``, increasing."""
        p = _int_in_range(place, "place", self.place_count - 1, UnknownPlaceError)
        a, b = self.edges[:, 0], self.edges[:, 1]
        return np.sort(np.concatenate([b[a == p], a[b == p]]))

    def __repr__(self) -> str:
        return (
            f"Graph(places={self.place_count}, edges={self.edge_count}, kinds={self.kind_counts()})"
        )


def _store_z_band(options: Any, value: Any, error: Type[TopolocError]) -> None:
    try:
        z_min, z_max = (_real(v, "z_band", error) for v in value)
    except ValueError:
        raise error(f"z_band must be (z_min, z_max), got {value!r}") from None
    options.use_z_band = True
    options.z_min_m, options.z_max_m = z_min, z_max


def _load_z_band(options: Any) -> Optional[Tuple[float, float]]:
    return (options.z_min_m, options.z_max_m) if options.use_z_band else None


#: The :func:`skeleton_graph` options: the fields of ``topoloc_skeleton_options``, ``z_band``
#: standing for ``use_z_band``, ``z_min_m`` and ``z_max_m``.
SKELETON_OPTIONS = OptionTable(
    "skeleton",
    _lib.topoloc_skeleton_options,
    lib.topoloc_skeleton_options_init,
    InvalidArgumentError,
    [
        Option("z_band", ("use_z_band", "z_min_m", "z_max_m"), _store_z_band, _load_z_band),
        real("min_clearance_m"),
        real("merge_radius_m"),
        real("max_edge_m"),
        real("corner_angle_deg"),
        real("corner_scale_m"),
        real("min_spur_m"),
    ],
)


def skeleton_options_default() -> Dict[str, Any]:
    """The library's defaults for :func:`skeleton_graph` options, as a dict (``z_band``
    ``None``: the whole grid); ``topoloc.h`` documents each on its ``topoloc_skeleton_options``
    field."""
    return SKELETON_OPTIONS.default_values()


def _occupancy_cells(occupied: Any) -> Tuple[NDArray[np.uint8], Tuple[int, int, int]]:
    """The cells of an ``occupied[x, y, z]`` array as uint8, x fastest, and ``(nx, ny, nz)``."""
    arr = np.asarray(occupied)
    if arr.dtype != np.bool_ and arr.dtype.kind not in "iu":
        raise TypeError(
            "occupied must be a bool or integer array (non-zero = occupied), "
            f"got dtype {arr.dtype}; "
            "threshold occupancy probabilities first, e.g. occupied = probability > 0.5"
        )
    if arr.ndim == 2:
        arr = arr[:, :, np.newaxis]
    if arr.ndim != 3:
        raise InvalidArgumentError(
            f"occupied must have shape (nx, ny, nz) (indexed occupied[x, y, z]) or (nx, ny) for a "
            f"single layer; got shape {arr.shape}"
        )
    # (nx, ny, nz) indexed [x, y, z] -> C order of (nz, ny, nx): x fastest, as the C API wants.
    cells = np.ascontiguousarray((arr != 0).transpose(2, 1, 0), dtype=np.uint8)
    nx, ny, nz = (int(n) for n in arr.shape)
    return cells, (nx, ny, nz)


def skeleton_graph(
    occupied: ArrayLike,
    voxel_size: float,
    origin: ArrayLike = (0.0, 0.0, 0.0),
    *,
    z_band: Optional[Tuple[float, float]] = None,
    min_clearance_m: Optional[float] = None,
    merge_radius_m: Optional[float] = None,
    max_edge_m: Optional[float] = None,
    corner_angle_deg: Optional[float] = None,
    corner_scale_m: Optional[float] = None,
    min_spur_m: Optional[float] = None,
) -> Graph:
    """Builds the topological graph of the free space of an occupancy voxel grid
    (``topoloc_graph_from_occupancy``): the free space is thinned to a one-voxel-thin 3D
    skeleton, whose ends, corners and junctions become places (merged when closer than
    ``merge_radius_m`` along it), joined where the skeleton links them by an obstacle-free
    straight segment; intermediate places are inserted where a segment would cross an obstacle
    or be longer than ``max_edge_m``.

    ``occupied``: bool or integer array of shape ``(nx, ny, nz)``, **indexed**
    ``occupied[x, y, z]`` (non-zero = occupied; a 2-D ``(nx, ny)`` array is one layer). Voxel
    ``(x, y, z)`` covers ``origin + voxel_size * [x, x+1) x [y, y+1) x [z, z+1)`` metres, z up.
    Any memory layout is accepted (the cells are copied).

    Options are keyword-only, named as the fields of ``topoloc_skeleton_options`` in
    ``topoloc.h``, which documents each one's default and range (``z_band=(z_min, z_max)``
    stands for ``use_z_band``, ``z_min_m`` and ``z_max_m``); left out or ``None``: the
    library's default (:func:`skeleton_options_default`). ``z_band``: only voxels whose centre
    lies in it (metres); ``min_clearance_m``: free voxels closer than this to an obstacle count
    as occupied; ``merge_radius_m``; ``max_edge_m``; ``corner_angle_deg``: the smallest bend
    that makes a corner; ``corner_scale_m``: the distance over which bends are measured;
    ``min_spur_m``: dead ends shorter than this are removed.

    Returns a :class:`Graph`. Raises :class:`InvalidArgumentError` naming the problem
    (``occupied`` shape, ``voxel_size``, ``origin``, ``cells`` when every voxel is occupied,
    ``z_band`` when the band holds no free voxel, ``min_clearance_m`` when nothing keeps the
    clearance, or another option out of range), ``TypeError`` for a float ``occupied``.
    """
    given = SKELETON_OPTIONS.pick(locals())
    cells, dims = _occupancy_cells(occupied)
    org = np.ascontiguousarray(np.asarray(origin, dtype=np.float64))
    if org.shape != (3,):
        raise InvalidArgumentError(f"origin must have 3 values (x, y, z), got shape {org.shape}")
    options = SKELETON_OPTIONS.fill(given)
    out = _out_call(
        _lib.GraphPtr,
        lib.topoloc_graph_from_occupancy,
        (c_size_t * 3)(*dims),
        float(voxel_size),
        _f64_ptr(org),
        _u8_ptr(cells),
        cells.size,
        byref(options),
    )
    try:
        return _read_graph(out)
    finally:
        lib.topoloc_graph_free(out)


def _read_graph(h: Any) -> Graph:
    """Copies a ``topoloc_graph`` into a :class:`Graph`."""
    places = _out_call(c_size_t, lib.topoloc_graph_place_count, h)
    edges = _out_call(c_size_t, lib.topoloc_graph_edge_count, h)
    positions = np.empty((places.value, 3), dtype=np.float64)
    kinds = np.empty(places.value, dtype=np.uint32)
    kind = c_uint32(0)
    for p in range(places.value):
        check(lib.topoloc_graph_place(h, p, _f64_ptr(positions[p]), byref(kind)))
        kinds[p] = kind.value
    pairs = np.empty((edges.value, 2), dtype=np.uint32)
    lengths = np.empty(edges.value, dtype=np.float64)
    a, b, length = c_uint32(0), c_uint32(0), c_double(0.0)
    for e in range(edges.value):
        check(lib.topoloc_graph_edge(h, e, byref(a), byref(b), byref(length)))
        pairs[e] = (a.value, b.value)
        lengths[e] = length.value
    skeleton = _read_array(lib.topoloc_graph_skeleton, h).astype(np.int64).reshape(-1, 3)
    for arr in (positions, kinds, pairs, lengths, skeleton):
        arr.flags.writeable = False
    return Graph(positions, kinds, pairs, lengths, skeleton)
