"""Skeleton graphs from occupancy grids: ``topoloc.skeleton_graph`` on hand-made worlds, axis
order, options, errors and the README example."""

from __future__ import annotations

import re

import numpy as np
import pytest

import topoloc
from topoloc import _lib, _options

from conftest import PYTHON_DIR

VOXEL = 0.1


def carved(size_xy, height, rooms, voxel=VOXEL) -> np.ndarray:
    """``occupied[x, y, z]``: rock with the rectangles ``rooms`` ([x0, y0, x1, y1] metres)
    carved out over the full height."""
    nx, ny, nz = (round(v / voxel) for v in (*size_xy, height))
    centres_x = (np.arange(nx) + 0.5) * voxel
    centres_y = (np.arange(ny) + 0.5) * voxel
    free = np.zeros((nx, ny), dtype=bool)
    for x0, y0, x1, y1 in rooms:
        free |= ((centres_x > x0) & (centres_x < x1))[:, None] & (
            (centres_y > y0) & (centres_y < y1)
        )[None, :]
    return np.repeat(~free[:, :, None], nz, axis=2)


def t_junction() -> np.ndarray:
    return carved((9.0, 7.0), 2.0, [(1.0, 1.0, 8.0, 2.2), (3.9, 1.0, 5.1, 6.0)])


def ring() -> np.ndarray:
    return carved(
        (9.0, 7.0),
        2.0,
        [(1.0, 1.0, 8.0, 2.2), (1.0, 4.8, 8.0, 6.0), (1.0, 1.0, 2.2, 6.0), (6.8, 1.0, 8.0, 6.0)],
    )


def degrees(g: topoloc.Graph) -> np.ndarray:
    return np.bincount(g.edges.ravel(), minlength=g.place_count)


def components(g: topoloc.Graph) -> int:
    parent = list(range(g.place_count))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in g.edges:
        parent[root(int(a))] = root(int(b))
    return len({root(i) for i in range(g.place_count)})


def test_a_t_junction_has_one_branch_and_three_ends():
    occupied = t_junction()
    g = topoloc.skeleton_graph(occupied, VOXEL)
    assert g.kind_counts() == {
        "end": 3,
        "corner": 0,
        "branch": 1,
        "intermediate": g.kind_counts()["intermediate"],
    }
    assert g.kind_counts()["intermediate"] >= 1
    assert components(g) == 1 and g.edge_count == g.place_count - 1
    branch = g.kinds.tolist().index(topoloc.NODE_BRANCH)
    assert degrees(g)[branch] == 3
    assert list(g.neighbours(branch)) == sorted(g.neighbours(branch).tolist())
    assert len(g.neighbours(branch)) == 3
    np.testing.assert_allclose(g.positions[branch], [4.5, 1.6, 1.0], atol=0.5)
    # Places come branches first, then ends, corners, intermediates.
    assert g.kind_names[0] == "branch" and g.kind_names[-1] == "intermediate"
    # Edges: sorted pairs a < b with their straight lengths, at most max_edge_m (3 m).
    assert g.edges.dtype == np.uint32 and g.edges.shape == (g.edge_count, 2)
    assert (g.edges[:, 0] < g.edges[:, 1]).all()
    assert [tuple(e) for e in g.edges] == sorted(tuple(e) for e in g.edges)
    np.testing.assert_allclose(
        g.lengths, np.linalg.norm(g.positions[g.edges[:, 0]] - g.positions[g.edges[:, 1]], axis=1)
    )
    assert (g.lengths <= 3.0).all()
    # The skeleton lies in free space, and every place on it.
    assert g.skeleton.shape[1] == 3 and len(g.skeleton) > 50
    assert not occupied[tuple(g.skeleton.T)].any()
    place_voxels = np.floor(g.positions / VOXEL).astype(int)
    skeleton = {tuple(v) for v in g.skeleton}
    assert all(tuple(v) in skeleton for v in place_voxels)
    assert not g.positions.flags.writeable


def test_a_ring_is_a_cycle_with_four_corners():
    g = topoloc.skeleton_graph(ring(), VOXEL)
    assert g.edge_count == g.place_count and (degrees(g) == 2).all() and components(g) == 1
    counts = g.kind_counts()
    assert (counts["end"], counts["corner"], counts["branch"]) == (0, 4, 0)


def test_axis_order_is_x_y_z_and_origin_shifts_positions():
    occupied = t_junction()
    g = topoloc.skeleton_graph(occupied, VOXEL)
    # Swapping x and y mirrors the world: the branch moves to (y, x).
    swapped = topoloc.skeleton_graph(np.ascontiguousarray(occupied.transpose(1, 0, 2)), VOXEL)
    branch = lambda graph: graph.positions[graph.kinds == topoloc.NODE_BRANCH][0]  # noqa: E731
    np.testing.assert_allclose(branch(swapped)[[1, 0, 2]], branch(g), atol=0.3)
    # Any memory layout is accepted: a Fortran-ordered copy gives the same graph.
    fortran = topoloc.skeleton_graph(np.asfortranarray(occupied), VOXEL)
    np.testing.assert_array_equal(fortran.positions, g.positions)
    np.testing.assert_array_equal(fortran.edges, g.edges)
    # uint8 cells (non-zero = occupied) are the same as bool.
    as_bytes = topoloc.skeleton_graph(occupied.astype(np.uint8) * 255, VOXEL)
    np.testing.assert_array_equal(as_bytes.positions, g.positions)
    shifted = topoloc.skeleton_graph(occupied, VOXEL, origin=(10.0, -5.0, 2.0))
    np.testing.assert_allclose(shifted.positions, g.positions + np.array([10.0, -5.0, 2.0]))
    np.testing.assert_array_equal(shifted.skeleton, g.skeleton)


def test_the_same_grid_gives_the_same_graph():
    a = topoloc.skeleton_graph(ring(), VOXEL, max_edge_m=1.5)
    b = topoloc.skeleton_graph(ring(), VOXEL, max_edge_m=1.5)
    for name in ("positions", "kinds", "edges", "lengths", "skeleton"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name


def test_options_change_the_graph():
    occupied = t_junction()
    default = topoloc.skeleton_graph(occupied, VOXEL)
    short = topoloc.skeleton_graph(occupied, VOXEL, max_edge_m=1.0)
    assert short.place_count > default.place_count and (short.lengths <= 1.0).all()
    # A height band: the skeleton stays in the layers whose centres are in [0.5, 0.8].
    banded = topoloc.skeleton_graph(occupied, VOXEL, z_band=(0.5, 0.8))
    assert set(banded.skeleton[:, 2]) <= {5, 6, 7}
    assert ((banded.positions[:, 2] >= 0.5) & (banded.positions[:, 2] <= 0.8)).all()
    # Clearance: the junction's centre is the farthest from the walls (0.73 m to the nearest
    # face, the corridors' centre lines 0.55 m): it alone keeps 0.7 m, and nothing keeps 0.8 m.
    narrow = topoloc.skeleton_graph(occupied, VOXEL, min_clearance_m=0.7)
    assert narrow.place_count == 1 and narrow.edge_count == 0
    np.testing.assert_allclose(narrow.positions[0][:2], [4.45, 1.75])
    with pytest.raises(topoloc.InvalidArgumentError, match="min_clearance_m"):
        topoloc.skeleton_graph(occupied, VOXEL, min_clearance_m=0.8)
    d = topoloc.skeleton_options_default()
    assert d == {
        "z_band": None,
        "min_clearance_m": 0.0,
        "merge_radius_m": 1.0,
        "max_edge_m": 3.0,
        "corner_angle_deg": 40.0,
        "corner_scale_m": 0.5,
        "min_spur_m": 1.0,
    }


def test_a_single_layer_2d_grid_is_accepted():
    plan = t_junction()[:, :, 0]
    g = topoloc.skeleton_graph(plan, VOXEL)
    assert g.kind_counts()["branch"] == 1 and g.kind_counts()["end"] == 3
    assert (g.skeleton[:, 2] == 0).all()


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"merge_radius_m": -1.0}, "merge_radius_m"),
        ({"max_edge_m": 0.0}, "max_edge_m"),
        ({"max_edge_m": 0.15}, "max_edge_m"),
        ({"corner_angle_deg": 180.0}, "corner_angle_deg"),
        ({"corner_scale_m": float("nan")}, "corner_scale_m"),
        ({"min_spur_m": -0.5}, "min_spur_m"),
        ({"min_clearance_m": float("inf")}, "min_clearance_m"),
        ({"z_band": (2.0, 1.0)}, "z_band"),
        ({"z_band": (10.0, 11.0)}, "z_band"),
    ],
)
def test_bad_options_name_the_field(kwargs, field):
    with pytest.raises(topoloc.InvalidArgumentError, match=field) as info:
        topoloc.skeleton_graph(t_junction(), VOXEL, **kwargs)
    assert info.value.status == 2


def test_bad_grids_are_refused():
    with pytest.raises(topoloc.InvalidArgumentError, match="cells"):
        topoloc.skeleton_graph(np.ones((5, 4, 3), dtype=bool), VOXEL)
    with pytest.raises(topoloc.InvalidArgumentError, match="dims"):
        topoloc.skeleton_graph(np.zeros((0, 4, 3), dtype=bool), VOXEL)
    with pytest.raises(topoloc.InvalidArgumentError, match="voxel_size"):
        topoloc.skeleton_graph(np.zeros((4, 4, 3), dtype=bool), 0.0)
    with pytest.raises(topoloc.InvalidArgumentError, match="origin"):
        topoloc.skeleton_graph(
            np.zeros((4, 4, 3), dtype=bool), VOXEL, origin=(0.0, float("nan"), 0.0)
        )
    with pytest.raises(topoloc.InvalidArgumentError, match="origin"):
        topoloc.skeleton_graph(np.zeros((4, 4, 3), dtype=bool), VOXEL, origin=(0.0, 0.0))
    with pytest.raises(topoloc.InvalidArgumentError, match="occupied"):
        topoloc.skeleton_graph(np.zeros((4, 4, 3, 2), dtype=bool), VOXEL)
    with pytest.raises(TypeError, match="threshold"):
        topoloc.skeleton_graph(np.zeros((4, 4, 3)), VOXEL)
    with pytest.raises(topoloc.InvalidArgumentError, match="z_band"):
        topoloc.skeleton_graph(np.zeros((4, 4, 3), dtype=bool), VOXEL, z_band=(1.0,))


def test_neighbours_of_an_unknown_place():
    g = topoloc.skeleton_graph(t_junction(), VOXEL)
    with pytest.raises(topoloc.UnknownPlaceError):
        g.neighbours(g.place_count)
    assert "Graph(places=" in repr(g)


def test_the_c_struct_defaults_match():
    raw = _options.defaults(_lib.topoloc_skeleton_options, _lib.lib.topoloc_skeleton_options_init)
    assert raw.struct_size == _lib.ctypes.sizeof(_lib.topoloc_skeleton_options)
    assert not raw.use_z_band
    assert (raw.merge_radius_m, raw.max_edge_m) == (1.0, 3.0)


def test_readme_skeleton_example_runs(capsys):
    text = (PYTHON_DIR / "README.md").read_text()
    code = next(b for b in re.findall(r"```python\n(.*?)```", text, re.S) if "skeleton_graph" in b)
    exec(compile(code, "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "{'end': 2, 'corner': 1, 'branch': 0, 'intermediate': 1}"
    assert len(lines) == 4  # the counts, then three edges of a chain of four places
