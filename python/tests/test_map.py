"""Maps: building, attributes, saving and loading, damaged files, keyframe maps, lifetimes."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

import topoloc

from conftest import KIND, MODEL, rot_z, unit

# ---------------------------------------------------------------------------------------------
# Builder and accessors
# ---------------------------------------------------------------------------------------------


def test_builder_map_has_everything_that_was_added(corridor):
    m = corridor.map
    assert (m.place_count, m.view_count, m.edge_count, m.dim) == (12, 24, 11, 64)
    assert m.descriptor_kind == KIND and m.descriptor_model == MODEL
    for p in range(12):
        assert m.place_views(p).tolist() == [2 * p, 2 * p + 1]
        assert m.place_views(p).dtype == np.uint32
        np.testing.assert_array_equal(m.place_position(p), [2.0 * p, 0.5, 0.0])
    assert m.neighbours(0).tolist() == [1]
    assert sorted(m.neighbours(5).tolist()) == [4, 6]
    assert m.neighbours(11).tolist() == [10]
    pairs, weights = m.edges()
    assert pairs.dtype == np.uint32 and pairs.shape == (11, 2)
    assert weights.dtype == np.float32 and weights.shape == (11,)
    np.testing.assert_array_equal(pairs, [[p, p + 1] for p in range(11)])
    np.testing.assert_allclose(weights, [1.0 + 0.5 * p for p in range(11)])


def test_view_attributes(corridor):
    m = corridor.map
    for v in (0, 1, 13, 23):
        info = m.view_info(v)
        assert info.view == v and info.place == v // 2
        assert info.keyframe_id == 1000 + v
        np.testing.assert_allclose(info.world_T_camera, corridor.poses[v], atol=1e-12)
        assert info.world_T_camera.shape == (4, 4) and info.world_T_camera.dtype == np.float64
        assert m.view_image(v) == f"images/place{v // 2:03d}_view{v % 2}.png"


def test_view_descriptors_are_unit_norm_copies(corridor):
    m = corridor.map
    all_d = m.view_descriptors()
    assert all_d.shape == (24, 64) and all_d.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(all_d, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(all_d, corridor.views, atol=1e-6)
    for v in (0, 7, 23):
        np.testing.assert_array_equal(m.view_descriptor(v), all_d[v])
    d = m.view_descriptor(3)
    d[:] = 0  # a copy: the map is unaffected
    np.testing.assert_array_equal(m.view_descriptor(3), all_d[3])


def test_views_without_attributes(small_map):
    info = small_map.view_info(1)
    assert info.place == 1 and info.keyframe_id is None and info.world_T_camera is None
    assert small_map.view_image(1) == ""
    assert small_map.place_position(1) is None
    assert small_map.descriptor_model == ""
    assert small_map.descriptor_kind == "toy"


def test_edges_are_sorted_and_oriented():
    with topoloc.MapBuilder("k", "m", 3) as b:
        for _ in range(4):
            b.add_view(b.add_place(), [1, 2, 3])
        b.add_edge(3, 1, 0.25)
        b.add_edge(2, 0, 4.0)
        b.add_edge(1, 0)
        m = b.build()
    pairs, weights = m.edges()
    assert pairs.tolist() == [[0, 1], [0, 2], [1, 3]]
    assert weights.tolist() == [1.0, 4.0, 0.25]
    assert sorted(m.neighbours(0).tolist()) == [1, 2]
    assert m.neighbours(3).tolist() == [1]


def test_large_results_grow_their_buffers():
    kind = "k" * 200  # past the first 64-byte buffer, within the 256-byte limit of a kind
    image = "s3://bucket/" + "x" * 500 + ".jpg"
    with topoloc.MapBuilder(kind, "model/" + "m" * 100, 2) as b:
        hub = b.add_place()
        for i in range(40):
            b.add_view(hub, [1.0, i + 1.0], image=image if i == 39 else None)
        for _ in range(25):
            leaf = b.add_place()
            b.add_view(leaf, [0.0, 1.0])
            b.add_edge(hub, leaf)
        m = b.build()
    assert m.descriptor_kind == kind
    assert m.descriptor_model == "model/" + "m" * 100
    assert m.place_views(hub).tolist() == list(range(40))
    assert sorted(m.neighbours(hub).tolist()) == list(range(1, 26))
    assert m.view_image(39) == image
    assert m.view_image(38) == ""


def test_builder_is_reusable_after_build():
    with topoloc.MapBuilder("k", None, 2) as b:
        b.add_view(b.add_place(), [1, 0])
        first = b.build()
        b.add_view(b.add_place([1, 2, 3]), [0, 1])
        second = b.build()
    assert (first.place_count, second.place_count) == (1, 2)
    np.testing.assert_array_equal(second.place_position(1), [1, 2, 3])


def test_builder_errors_leave_the_builder_unchanged():
    with topoloc.MapBuilder("k", "m", 4) as b:
        p = b.add_place()
        assert b.add_view(p, [1, 0, 0, 0]) == 0
        with pytest.raises(topoloc.UnknownPlaceError, match="unknown place 5"):
            b.add_view(5, [1, 0, 0, 0])
        with pytest.raises(topoloc.UnknownPlaceError):
            b.add_view(-1, [1, 0, 0, 0])
        with pytest.raises(topoloc.DimensionMismatchError, match="D=4"):
            b.add_view(p, [1, 0, 0])
        with pytest.raises(topoloc.DimensionMismatchError, match="1-D"):
            b.add_view(p, [[1, 0, 0, 0]])
        with pytest.raises(topoloc.NonFiniteError):
            b.add_view(p, [1, np.nan, 0, 0])
        with pytest.raises(topoloc.NonFiniteError):
            b.add_view(p, [1, np.inf, 0, 0])
        with pytest.raises(topoloc.ZeroDescriptorError):
            b.add_view(p, np.zeros(4))
        with pytest.raises(topoloc.InvalidArgumentError, match="rotation"):
            b.add_view(p, [1, 0, 0, 0], world_T_camera=np.diag([2.0, 1, 1, 1]))
        with pytest.raises(topoloc.InvalidArgumentError, match="last row"):
            bad = np.eye(4)
            bad[3, 0] = 1
            b.add_view(p, [1, 0, 0, 0], world_T_camera=bad)
        with pytest.raises(topoloc.InvalidArgumentError, match="4x4"):
            b.add_view(p, [1, 0, 0, 0], world_T_camera=np.eye(3))
        with pytest.raises(topoloc.NonFiniteError):
            bad = np.eye(4)
            bad[0, 3] = np.nan
            b.add_view(p, [1, 0, 0, 0], world_T_camera=bad)
        with pytest.raises(topoloc.InvalidArgumentError):
            b.add_view(p, [1, 0, 0, 0], keyframe_id=-3)
        with pytest.raises(topoloc.InvalidArgumentError, match="NUL"):
            b.add_view(p, [1, 0, 0, 0], image="a\0b")
        with pytest.raises(topoloc.InvalidArgumentError, match="3 values"):
            b.add_place([1, 2])
        with pytest.raises(topoloc.NonFiniteError, match="finite"):
            b.add_place([1, np.nan, 2])
        # Nothing of the above was added: ids continue from where they were.
        assert b.add_view(p, [0, 1, 0, 0], keyframe_id=2**64 - 1) == 1
        assert b.add_place() == 1
        b.add_view(1, [0, 0, 1, 0])
        m = b.build()
    assert m.view_count == 3 and m.place_count == 2
    assert m.view_info(1).keyframe_id == 2**64 - 1


def test_edge_errors():
    with topoloc.MapBuilder("k", "m", 2) as b:
        for _ in range(2):
            b.add_view(b.add_place(), [1, 1])
        with pytest.raises(topoloc.UnknownPlaceError):
            b.add_edge(0, 2)
        with pytest.raises(topoloc.UnknownPlaceError):
            b.add_edge(-1, 0)
        with pytest.raises(topoloc.InvalidArgumentError, match="itself"):
            b.add_edge(1, 1)
        for w in (0.0, -1.0):
            with pytest.raises(topoloc.InvalidArgumentError, match="weight"):
                b.add_edge(0, 1, w)
        for w in (float("nan"), float("inf")):
            with pytest.raises(topoloc.NonFiniteError, match="weight"):
                b.add_edge(0, 1, w)
        b.add_edge(0, 1)
        with pytest.raises(topoloc.InvalidArgumentError, match="exists"):
            b.add_edge(1, 0)
        assert b.build().edge_count == 1


def test_builder_creation_and_build_errors():
    with pytest.raises(topoloc.InvalidArgumentError, match="kind"):
        topoloc.MapBuilder("", "m", 4)
    with pytest.raises(topoloc.InvalidArgumentError, match="dimension"):
        topoloc.MapBuilder("k", "m", 0)
    with pytest.raises(topoloc.InvalidArgumentError):
        topoloc.MapBuilder("k", "m", -4)
    with pytest.raises(topoloc.InvalidUTF8Error):
        topoloc.MapBuilder(b"\xff\xfe", "m", 4)
    with pytest.raises(topoloc.EmptyMapError):
        topoloc.MapBuilder("k", "m", 4).build()
    with topoloc.MapBuilder("k", "m", 4) as b:
        b.add_view(b.add_place(), [1, 0, 0, 0])
        b.add_place()
        with pytest.raises(topoloc.InvalidMapError, match="1"):
            b.build()


#: The map's methods taking a place id, then those taking a view id: the error for an unknown id
#: and the first id the corridor map (12 places, 24 views) lacks.
ID_METHODS = [
    (("neighbours", "place_views", "place_position"), topoloc.UnknownPlaceError, 12),
    (("view_info", "view_descriptor", "view_image"), topoloc.UnknownViewError, 24),
]


@pytest.mark.parametrize("methods, error, first_unknown", ID_METHODS, ids=["place", "view"])
def test_unknown_place_and_view_on_a_map(corridor, methods, error, first_unknown):
    for method in methods:
        fn = getattr(corridor.map, method)
        with pytest.raises(error, match=str(first_unknown)):
            fn(first_unknown)
        with pytest.raises(error):
            fn(-1)
        with pytest.raises(IndexError):
            fn(2**32 - 1)


def test_ids_are_integers(corridor):
    with pytest.raises(TypeError):
        corridor.map.neighbours(1.5)
    assert corridor.map.neighbours(np.uint32(1)).tolist() == [0, 2]


def test_map_constructor_is_private():
    with pytest.raises(TypeError, match=r"Map\.load"):
        topoloc.Map()


# ---------------------------------------------------------------------------------------------
# Save and load
# ---------------------------------------------------------------------------------------------


def _assert_same_map(a: topoloc.Map, b: topoloc.Map):
    assert (a.place_count, a.view_count, a.edge_count, a.dim) == (
        b.place_count,
        b.view_count,
        b.edge_count,
        b.dim,
    )
    assert (a.descriptor_kind, a.descriptor_model) == (b.descriptor_kind, b.descriptor_model)
    np.testing.assert_array_equal(a.view_descriptors(), b.view_descriptors())
    for x, y in zip(a.edges(), b.edges()):
        np.testing.assert_array_equal(x, y)
    for p in range(a.place_count):
        np.testing.assert_array_equal(a.place_views(p), b.place_views(p))
        np.testing.assert_array_equal(a.neighbours(p), b.neighbours(p))
        pa, pb = a.place_position(p), b.place_position(p)
        assert (pa is None) == (pb is None)
        if pa is not None:
            np.testing.assert_array_equal(pa, pb)
    for v in range(a.view_count):
        ia, ib = a.view_info(v), b.view_info(v)
        assert (ia.place, ia.keyframe_id) == (ib.place, ib.keyframe_id)
        assert (ia.world_T_camera is None) == (ib.world_T_camera is None)
        if ia.world_T_camera is not None:
            np.testing.assert_allclose(ia.world_T_camera, ib.world_T_camera, atol=1e-12)
        assert a.view_image(v) == b.view_image(v)


def test_save_load_round_trip(corridor, map_file):
    assert map_file.is_file() and map_file.stat().st_size > 24 * 64 * 4
    with topoloc.Map.load(map_file) as loaded:
        _assert_same_map(corridor.map, loaded)
        # The loaded map's attributes are the originals.
        assert loaded.view_info(5).keyframe_id == 1005
        np.testing.assert_allclose(
            loaded.view_info(5).world_T_camera, corridor.poses[5], atol=1e-12
        )
        assert loaded.view_image(5) == "images/place002_view1.png"
    # str, bytes and pathlib paths are all accepted.
    for path in (str(map_file), bytes(map_file), map_file):
        with topoloc.Map.load(path) as m:
            assert m.view_count == 24


def test_save_of_a_loaded_map_is_byte_identical(map_file, tmp_path):
    again = tmp_path / "again.topomap"
    with topoloc.Map.load(map_file) as m:
        m.save(again)
    assert again.read_bytes() == map_file.read_bytes()


def test_from_bytes(corridor, map_file):
    data = map_file.read_bytes()
    for buf in (data, bytearray(data), memoryview(data)):
        with topoloc.Map.from_bytes(buf) as m:
            _assert_same_map(corridor.map, m)
    m = topoloc.Map.from_bytes(bytearray(data))
    m2 = topoloc.Map.from_bytes(data, expected_kind=KIND, expected_model=MODEL, expected_dim=64)
    assert m2.place_count == m.place_count == 12


def test_save_to_missing_directory(corridor, tmp_path):
    with pytest.raises(topoloc.MapIOError):
        corridor.map.save(tmp_path / "no" / "such" / "dir" / "x.topomap")


def test_load_missing_file(tmp_path):
    with pytest.raises(topoloc.MapIOError) as info:
        topoloc.Map.load(tmp_path / "absent.topomap")
    assert "absent.topomap" in info.value.message


def test_load_directory(tmp_path):
    with pytest.raises(topoloc.MapIOError):
        topoloc.Map.load(tmp_path)


def test_load_non_utf8_path():
    with pytest.raises(topoloc.InvalidUTF8Error):
        topoloc.Map.load(b"/tmp/\xff\xfe.topomap")


def test_not_a_map(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("hello world, this is not a map at all")
    with pytest.raises(topoloc.NotAMapError):
        topoloc.Map.load(text)
    empty = tmp_path / "empty"
    empty.write_bytes(b"")
    with pytest.raises(topoloc.NotAMapError):
        topoloc.Map.load(empty)
    with pytest.raises(topoloc.NotAMapError):
        topoloc.Map.from_bytes(b"")
    # A valid safetensors file without topoloc metadata.
    header = json.dumps({"x": {"dtype": "U8", "shape": [1], "data_offsets": [0, 1]}}).encode()
    st = tmp_path / "other.safetensors"
    st.write_bytes(struct.pack("<Q", len(header)) + header + b"\x07")
    with pytest.raises(topoloc.NotAMapError, match="metadata"):
        topoloc.Map.load(st)


def _header_end(data: bytes) -> int:
    return 8 + struct.unpack("<Q", data[:8])[0]


def test_truncated_files(map_file, tmp_path):
    data = map_file.read_bytes()
    end = _header_end(data)
    assert data[8:10] == b'{"'
    offsets = sorted({1, 7, 8, 9, 20, end - 1, end, end + 1, (end + len(data)) // 2, len(data) - 1})
    for cut in offsets:
        short = tmp_path / f"cut{cut}.topomap"
        short.write_bytes(data[:cut])
        with pytest.raises(topoloc.TruncatedMapError):
            topoloc.Map.load(short)
        with pytest.raises(topoloc.TruncatedMapError):
            topoloc.Map.from_bytes(data[:cut])


def test_trailing_bytes_are_corruption(map_file):
    data = map_file.read_bytes()
    with pytest.raises(topoloc.CorruptMapError):
        topoloc.Map.from_bytes(data + b"\0")


def test_flipped_bytes_are_detected(map_file, tmp_path):
    data = map_file.read_bytes()
    end = _header_end(data)
    for pos in (end, end + 100, (end + len(data)) // 2, len(data) - 1):
        damaged = bytearray(data)
        damaged[pos] ^= 0x01
        path = tmp_path / f"flip{pos}.topomap"
        path.write_bytes(bytes(damaged))
        with pytest.raises(topoloc.CorruptMapError, match="checksum"):
            topoloc.Map.load(path)
        with pytest.raises(topoloc.CorruptMapError):
            topoloc.Map.from_bytes(bytes(damaged))


def test_newer_major_version(map_file):
    data = map_file.read_bytes()
    marker = b'\\"version\\":\\"1.'
    assert data.count(marker) == 1
    newer = data.replace(marker, b'\\"version\\":\\"9.')
    with pytest.raises(topoloc.UnsupportedVersionError, match="9"):
        topoloc.Map.from_bytes(newer)


def test_descriptor_mismatch_at_load(map_file):
    for kwargs in (
        {"expected_kind": "dinov2"},
        {"expected_model": "other-model"},
        {"expected_dim": 128},
        {"expected_kind": KIND, "expected_model": MODEL, "expected_dim": 32},
    ):
        with pytest.raises(topoloc.DescriptorMismatchError) as info:
            topoloc.Map.load(map_file, **kwargs)
        assert KIND in info.value.message
        with pytest.raises(topoloc.DescriptorMismatchError):
            topoloc.Map.from_bytes(map_file.read_bytes(), **kwargs)
    for kwargs in (
        {"expected_kind": KIND, "expected_model": MODEL, "expected_dim": 64},
        {"expected_kind": ""},
    ):
        with topoloc.Map.load(map_file, **kwargs) as m:
            assert m.dim == 64


# ---------------------------------------------------------------------------------------------
# Lifetimes
# ---------------------------------------------------------------------------------------------


def test_map_context_manager_and_close(map_file):
    with topoloc.Map.load(map_file) as m:
        assert not m.closed
        assert m.place_count == 12
    assert m.closed
    assert "closed" in repr(m)
    with pytest.raises(ValueError, match="closed"):
        _ = m.place_count
    with pytest.raises(ValueError, match="closed"):
        m.view_descriptors()
    with pytest.raises(ValueError, match="closed"):
        with m:
            pass
    m.close()  # idempotent


def test_repr(corridor):
    r = repr(corridor.map)
    assert "places=12" in r and "views=24" in r and f"kind='{KIND}'" in r


def test_builder_context_manager_and_close():
    with topoloc.MapBuilder("k", "m", 2) as b:
        b.add_place()
    assert b.closed
    with pytest.raises(ValueError, match="closed"):
        b.add_place()
    with pytest.raises(ValueError, match="closed"):
        b.build()
    b.close()


def test_map_outlives_its_builder():
    b = topoloc.MapBuilder("k", "m", 2)
    b.add_view(b.add_place(), [3, 4])
    m = b.build()
    b.close()
    del b
    np.testing.assert_allclose(m.view_descriptor(0), [0.6, 0.8], atol=1e-7)


# ---------------------------------------------------------------------------------------------
# Maps from keyframes
# ---------------------------------------------------------------------------------------------


def _keyframe_descriptors(dim=32, seed=3):
    rng = np.random.default_rng(seed)
    a, b, c, d = unit(rng.standard_normal((4, dim)))
    tiny = lambda v: v + 1e-3 * rng.standard_normal(dim)  # noqa: E731 - same appearance
    return a, b, c, d, tiny


def test_map_from_keyframes_with_poses():
    a, b, c, d, tiny = _keyframe_descriptors()
    desc = np.stack([a, tiny(a), b, c, d, tiny(c)])
    xs = [0.0, 0.5, 0.2, 3.0, 6.0, 3.2]
    poses = np.stack([rot_z(0.1 * i, (x, 0.0, 0.0)) for i, x in enumerate(xs)])
    ids = np.array([10, 11, 12, 13, 14, 15], dtype=np.int64)
    m = topoloc.map_from_keyframes("k", "m", 32, desc, ids=ids, poses=poses)
    # kf1 is redundant (same spot, same look), kf2 a new look of place 0, kf5 redundant at place 1.
    assert (m.place_count, m.view_count) == (3, 4)
    assert [m.view_info(v).keyframe_id for v in range(4)] == [10, 12, 13, 14]
    assert m.place_views(0).tolist() == [0, 1]
    np.testing.assert_allclose(m.place_position(0), [0, 0, 0])
    np.testing.assert_allclose(m.place_position(1), [3, 0, 0])
    np.testing.assert_allclose(m.place_position(2), [6, 0, 0])
    np.testing.assert_allclose(m.view_info(1).world_T_camera, poses[2], atol=1e-12)
    assert m.edges()[0].tolist() == [[0, 1], [1, 2]]
    np.testing.assert_allclose(m.view_descriptor(1), b, atol=1e-6)


def test_map_from_keyframes_options():
    a, b, c, d, _tiny = _keyframe_descriptors()
    desc = np.stack([a, b, c, d])
    poses = np.stack([rot_z(0.0, (x, 0.0, 0.0)) for x in (0.0, 1.0, 2.0, 3.0)])
    # Wide spacing but one view per place: everything merges into place 0 with one view.
    m = topoloc.map_from_keyframes(
        "k", "m", 32, desc, poses=poses, place_spacing_m=10.0, max_views_per_place=1
    )
    assert (m.place_count, m.view_count) == (1, 1)
    # Narrow spacing: one place per keyframe; radius joins places up to 2 m apart.
    m = topoloc.map_from_keyframes(
        "k", "m", 32, desc, poses=poses, place_spacing_m=0.5, neighbour_radius_m=2.0
    )
    assert (m.place_count, m.view_count) == (4, 4)
    assert m.edges()[0].tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]
    # Novelty threshold below every similarity: nothing is novel, later looks are dropped.
    m = topoloc.map_from_keyframes(
        "k", "m", 32, desc, poses=poses, place_spacing_m=10.0, novelty_similarity=-1.0
    )
    assert m.view_count == 1


def test_map_from_keyframes_without_poses():
    a, b, c, _d, tiny = _keyframe_descriptors()
    desc = np.stack([a, tiny(a), b, tiny(b), c, a])
    m = topoloc.map_from_keyframes("k", None, 32, desc)
    assert (m.place_count, m.view_count) == (4, 4)
    assert [m.view_info(v).keyframe_id for v in range(4)] == [0, 2, 4, 5]
    assert all(m.place_position(p) is None for p in range(4))
    assert all(m.view_info(v).world_T_camera is None for v in range(4))
    assert m.edges()[0].tolist() == [[0, 1], [1, 2], [2, 3]]
    assert m.descriptor_model == ""


def test_map_from_keyframes_errors():
    a, b, _c, _d, _tiny = _keyframe_descriptors()
    desc = np.stack([a, b])
    with pytest.raises(topoloc.EmptyMapError):
        topoloc.map_from_keyframes("k", "m", 32, np.zeros((0, 32)))
    with pytest.raises(topoloc.DimensionMismatchError):
        topoloc.map_from_keyframes("k", "m", 32, a)
    with pytest.raises(topoloc.InvalidArgumentError, match="keyframe 1"):
        topoloc.map_from_keyframes("k", "m", 32, np.stack([a, np.zeros(32)]))  # all-zero descriptor
    with pytest.raises(topoloc.InvalidArgumentError, match="descriptor"):
        topoloc.map_from_keyframes("k", "m", 16, desc)  # 32 values, D = 16
    bad = desc.copy()
    bad[1, 3] = np.nan
    with pytest.raises(topoloc.InvalidArgumentError, match="keyframe 1"):
        topoloc.map_from_keyframes("k", "m", 32, bad)
    with pytest.raises(topoloc.InvalidArgumentError, match="place_spacing_m"):
        topoloc.map_from_keyframes("k", "m", 32, desc, place_spacing_m=0.0)
    with pytest.raises(topoloc.InvalidArgumentError, match="max_views_per_place"):
        topoloc.map_from_keyframes("k", "m", 32, desc, max_views_per_place=0)
    with pytest.raises(topoloc.InvalidArgumentError, match="shape"):
        topoloc.map_from_keyframes("k", "m", 32, desc, poses=np.stack([np.eye(4)] * 3))
    with pytest.raises(topoloc.InvalidArgumentError, match="rotation"):
        topoloc.map_from_keyframes(
            "k", "m", 32, desc, poses=np.stack([np.eye(4), np.diag([1.0, 1, -1, 1])])
        )
    with pytest.raises(topoloc.InvalidArgumentError, match="ids"):
        topoloc.map_from_keyframes("k", "m", 32, desc, ids=[1, 2, 3])
    with pytest.raises(topoloc.InvalidArgumentError, match="non-negative"):
        topoloc.map_from_keyframes("k", "m", 32, desc, ids=[1, -2])
    with pytest.raises(topoloc.InvalidArgumentError, match="kind"):
        topoloc.map_from_keyframes("", "m", 32, desc)
