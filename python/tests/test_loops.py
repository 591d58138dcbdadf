"""Loop closure (ABI 1.5): options, hints for a revisit from another pose, the gates, errors
that leave the detector unchanged, relocalization, erase, and a second session from a saved
map."""

from __future__ import annotations

import ctypes
import dataclasses

import numpy as np
import pytest

import topoloc
from topoloc import _lib, _options

DIM = 8
POINTS = 60
# Options of the C test: candidates may be any keyframe 5 ids back, at any time, and one
# keyframe is consistent enough.
OPTIONS = dict(exclude_recent_ids=5, exclude_recent_s=0.0, consistent_keyframes=1)

# The second camera of two_views(): 0.3 m right, 0.1 m ahead, turned 3 degrees about y.
YAW = np.radians(3.0)
OFFSET = np.array([0.3, 0.0, 0.1])


def two_views():
    """``(first, second, descriptors)``: POINTS scene points 3-8 m in front of a 300-pixel
    pinhole camera (320 x 240, principal point (160, 120)) seen from it and from the second
    camera, each with the same random 32-byte descriptor in both views (the generator of
    tests/c/test_loops.c, loop_keypoints, with its 32-bit LCG), and the points in the first
    camera's frame ``(first, second, descriptors, scene)``."""
    state = 12345
    c, s = np.cos(YAW), np.sin(YAW)

    def step():
        nonlocal state
        state = (state * 1664525 + 1013904223) & 0xFFFFFFFF
        return state

    first, second, descriptors, scene = [], [], [], []
    while len(first) < POINTS:
        z = 3.0 + 5.0 * (step() >> 8) / 16777216.0
        x = ((step() >> 8) / 16777216.0 - 0.5) * z
        y = ((step() >> 8) / 16777216.0 - 0.5) * 0.7 * z
        # The second camera: p' = R^T (p - t), R a yaw about y.
        qx = c * (x - OFFSET[0]) - s * (z - OFFSET[2])
        qz = s * (x - OFFSET[0]) + c * (z - OFFSET[2])
        u1, v1 = 300.0 * x / z + 160.0, 300.0 * y / z + 120.0
        u2, v2 = 300.0 * qx / qz + 160.0, 300.0 * y / qz + 120.0
        if qz < 0.5 or not (
            0 <= u1 <= 319 and 0 <= v1 <= 239 and 0 <= u2 <= 319 and 0 <= v2 <= 239
        ):
            continue
        first.append((u1, v1))
        second.append((u2, v2))
        descriptors.append([step() >> 24 for _ in range(32)])
        scene.append((x, y, z))
    return (
        np.array(first, dtype=np.float32),
        np.array(second, dtype=np.float32),
        np.array(descriptors, dtype=np.uint8),
        np.array(scene, dtype=np.float32),
    )


def descriptor(scene: int) -> np.ndarray:
    """The C test's global descriptor of a scene."""
    d = 0.05 * np.arange(DIM, dtype=np.float32)
    d[scene % DIM] = 1.0
    return d


@pytest.fixture
def views():
    return two_views()


@pytest.fixture
def detector():
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS) as det:
        yield det


def test_generator_matches_the_c_test(views):
    first, second, descriptors, scene = views
    assert first.shape == second.shape == (POINTS, 2) and descriptors.shape == (POINTS, 32)
    assert ((first >= 0) & (first <= [319, 239])).all() and (
        (second >= 0) & (second <= [319, 239])
    ).all()
    assert len({bytes(row) for row in descriptors}) == POINTS
    # The keypoints are the scene points' projections.
    np.testing.assert_allclose(first, 300.0 * scene[:, :2] / scene[:, 2:] + [160, 120], rtol=1e-5)


def test_options_defaults():
    d = topoloc.loop_options_default()
    raw = _options.defaults(_lib.topoloc_loop_options, _lib.lib.topoloc_loop_options_init)
    assert raw.struct_size == ctypes.sizeof(_lib.topoloc_loop_options)
    assert set(d) == {name for name, _ in _lib.topoloc_loop_options._fields_} - {"struct_size"}
    estimators = {
        "ransac": _lib.PAIR_ESTIMATOR_RANSAC,
        "magsac": _lib.PAIR_ESTIMATOR_MAGSAC,
        "usac_fast": _lib.PAIR_ESTIMATOR_USAC_FAST,
    }
    for name, value in d.items():
        assert estimators.get(value, value) == getattr(raw, name), name
    assert d["candidates"] == 5 and d["min_inliers"] == 30 and d["consistent_keyframes"] == 3
    assert d["exclude_recent_ids"] == 30 and d["exclude_recent_s"] == 10.0
    assert d["odometry_gate"] is True
    assert d["odometry_max_rotation_deg"] == 30.0 and d["odometry_max_translation_m"] == 1.0
    assert (d["fx"], d["fy"], d["cx"], d["cy"]) == (0.0, 0.0, 0.0, 0.0)
    assert d["novelty_similarity"] == pytest.approx(0.9)
    assert d["place_spacing_m"] == 2.0 and d["neighbour_radius_m"] == 3.0
    assert d["candidate_id_gap"] == 10
    assert d["odometry_max_translation_per_m"] == 0.02 and d["pose_reprojection_px"] == 5.0
    assert d["odometry_candidates"] == 1 and d["odometry_search_m"] == 2.0
    assert d["max_match_pace"] == 3.0 and d["match_pace_slack_s"] == 0.5
    # ABI 1.17: the verification options the CLI had alone.
    assert d["refine_keyframes"] == 5 and d["pose_min_inliers"] == 30
    assert d["pair_estimator"] == "ransac" and d["pair_iterations"] == 100
    assert d["pair_min_cosine"] == pytest.approx(0.82)
    assert d["cells_pair_estimator"] == "magsac" and d["cells_pair_iterations"] == 1000
    assert d["cells_pair_min_cosine"] == -1.0
    with topoloc.LoopDetector("test", "loops", DIM) as det:
        assert det.options == d and det.dim == DIM
    with topoloc.LoopDetector(
        "test", "loops", DIM, min_inliers=40, odometry_gate=False, fx=None
    ) as det:
        assert det.options == dict(d, min_inliers=40, odometry_gate=False)


def test_invalid_options():
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.LoopDetector("test", "loops", DIM, candidates=0)
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.LoopDetector("test", "loops", DIM, min_inliers=-1)
    with pytest.raises(TypeError, match="min_inlier"):
        topoloc.LoopDetector("test", "loops", DIM, min_inlier=30)
    with pytest.raises(topoloc.InvalidArgumentError):
        topoloc.LoopDetector("", "loops", DIM)
    for dim in (65537, 2**30, 2**32 - 1):
        with pytest.raises(topoloc.InvalidArgumentError, match="dimension"):
            topoloc.LoopDetector("test", "loops", dim)
    with pytest.raises(topoloc.InvalidArgumentError):
        topoloc.LoopDetector("test", "loops", 0)


def test_gate_constants():
    assert [int(g) for g in topoloc.Gate] == [0, 1, 2, 3, 4, 5, 6]
    for g in topoloc.Gate:
        assert getattr(_lib, f"GATE_{g.name}") == g


def test_first_keyframe_has_no_candidate(detector, views):
    first, _, descriptors, _ = views
    hint = detector.add(0, 0.0, descriptor(1), first, descriptors)
    assert isinstance(hint, topoloc.LoopHint)
    assert hint.query_id == 0 and not hint.has_match and not hint.accepted
    assert hint.gate is topoloc.Gate.NO_CANDIDATE
    assert not hint.has_pose
    assert hint.matched_T_query.shape == (4, 4) and hint.covariance.shape == (6, 6)
    assert len(detector) == 1


def test_revisit_from_another_pose_is_accepted(detector, views):
    first, second, descriptors, _ = views
    detector.add(0, 0.0, descriptor(1), first, descriptors)
    hint = detector.add(10, 10.0, descriptor(1), second, descriptors)
    assert hint.query_id == 10 and hint.has_match and hint.accepted
    assert hint.gate == topoloc.Gate.ACCEPTED and hint.matched_id == 0
    assert hint.inliers >= 30 and hint.confidence > 0.99
    assert not hint.has_pose  # no intrinsics
    assert len(detector) == 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        hint.accepted = False


def test_relative_pose_with_intrinsics_and_scene_points(views):
    first, second, descriptors, scene = views
    camera = dict(fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS, **camera) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors, camera_points=scene)
        hint = det.add(10, 10.0, descriptor(1), second, descriptors)
    assert hint.accepted and hint.has_pose and hint.scale_known
    c, s = np.cos(YAW), np.sin(YAW)
    rotation = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    pose = hint.matched_T_query
    assert pose.dtype == np.float64 and pose.shape == (4, 4)
    np.testing.assert_allclose(pose[3], [0, 0, 0, 1])
    np.testing.assert_allclose(pose[:3, :3], rotation, atol=1e-3)
    np.testing.assert_allclose(pose[:3, 3], OFFSET, atol=1e-2)
    cov = hint.covariance
    assert cov.shape == (6, 6) and np.allclose(cov, cov.T) and (np.diag(cov) >= 0).all()


def test_query_candidates(detector, views):
    first, second, descriptors, _ = views
    detector.add(0, 0.0, descriptor(1), first, descriptors)
    detector.add(10, 10.0, descriptor(1), second, descriptors)
    found = detector.query(descriptor(1), 4)
    assert len(found) == 2 and all(isinstance(c, topoloc.LoopCandidate) for c in found)
    assert {c.keyframe_id for c in found} == {0, 10}
    assert found[0].similarity > 0.99
    assert [c.similarity for c in found] == sorted((c.similarity for c in found), reverse=True)
    assert len(detector.query(descriptor(1), 1)) == 1
    assert detector.query(descriptor(1), 0) == []
    # Room is made for what can be found, not for what is asked.
    assert len(detector.query(descriptor(1), 2**32 - 1)) == 2
    with pytest.raises(topoloc.InvalidArgumentError, match="max_results"):
        detector.query(descriptor(1), 2**32)
    with pytest.raises(topoloc.DimensionMismatchError):
        detector.query(np.ones(DIM + 1), 4)


def test_bad_keyframes_leave_the_detector_unchanged(detector, views):
    first, second, descriptors, _ = views
    detector.add(0, 0.0, descriptor(1), first, descriptors)
    with pytest.raises(topoloc.DimensionMismatchError) as info:
        detector.add(10, 10.0, descriptor(1)[:-1], second, descriptors)
    assert info.value.status == 200
    assert len(detector) == 1
    with pytest.raises(topoloc.InvalidArgumentError) as info:
        detector.add(0, 10.0, descriptor(1), second, descriptors)  # duplicate id
    assert info.value.status == 2 and info.value.message
    assert len(detector) == 1
    with pytest.raises(topoloc.NonFiniteError):
        detector.add(10, float("nan"), descriptor(1), second, descriptors)
    with pytest.raises(topoloc.ZeroDescriptorError):
        detector.add(10, 10.0, np.zeros(DIM), second, descriptors)
    with pytest.raises(topoloc.InvalidArgumentError):
        detector.add(10, 10.0, descriptor(1), second, descriptors, world_T_body=2 * np.eye(4))
    assert len(detector) == 1
    # The detector goes on as if nothing had happened.
    assert detector.add(10, 10.0, descriptor(1), second, descriptors).accepted


def test_inconsistent_keypoint_arrays_are_refused_before_c(detector, views, monkeypatch):
    first, second, descriptors, scene = views
    detector.add(0, 0.0, descriptor(1), first, descriptors)

    def not_called(*args):
        raise AssertionError("topoloc_loop_detector_add was called")

    monkeypatch.setattr(_lib.lib, "topoloc_loop_detector_add", not_called)
    bad = [
        dict(keypoints=second, keypoint_descriptors=descriptors[:-1]),
        dict(keypoints=second[:-1], keypoint_descriptors=descriptors),
        dict(keypoints=second, keypoint_descriptors=None),
        dict(keypoints=None, keypoint_descriptors=descriptors),
        dict(keypoints=second, keypoint_descriptors=descriptors, camera_points=scene[:-1]),
        dict(keypoints=None, keypoint_descriptors=None, camera_points=scene),
        dict(keypoints=second.reshape(-1), keypoint_descriptors=descriptors),
        dict(keypoints=second, keypoint_descriptors=descriptors[:, :16]),
        dict(keypoints=second, keypoint_descriptors=descriptors.tobytes()[:-1]),
    ]
    for kwargs in bad:
        with pytest.raises(topoloc.InvalidArgumentError):
            detector.add(10, 10.0, descriptor(1), **kwargs)
    with pytest.raises(TypeError):
        detector.add(10, 10.0, descriptor(1), second, descriptors.astype(np.float32))
    with pytest.raises(topoloc.InvalidArgumentError):
        detector.add(10, 10.0, descriptor(1), second, descriptors, world_T_body=np.eye(3))
    monkeypatch.undo()
    assert len(detector) == 1
    # Descriptors as bytes and as a list of ints are accepted too.
    assert detector.add(10, 10.0, descriptor(1), second.tolist(), descriptors.tobytes()).accepted


def test_a_completed_streak_confirms_its_first_keyframes(views):
    first, second, descriptors, _ = views
    with topoloc.LoopDetector("test", "loops", DIM, **dict(OPTIONS, consistent_keyframes=3)) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors)
        assert det.confirmed() == []
        for kid in (10, 11):
            hint = det.add(kid, float(kid), descriptor(1), second, descriptors)
            assert hint.gate is topoloc.Gate.INCONSISTENT and not hint.accepted
            assert det.confirmed() == []
        assert det.add(12, 12.0, descriptor(1), second, descriptors).accepted
        confirmed = det.confirmed()
        assert [h.query_id for h in confirmed] == [10, 11]
        for h in confirmed:
            assert h.accepted and h.gate is topoloc.Gate.ACCEPTED and h.matched_id == 0
            assert h.inliers >= 30 and h.has_match
        # A failed add keeps them; the next add replaces them.
        with pytest.raises(topoloc.InvalidArgumentError):
            det.add(12, 13.0, descriptor(1), second, descriptors)
        assert [h.query_id for h in det.confirmed()] == [10, 11]
        det.add(13, 13.0, descriptor(1), second, descriptors)
        assert det.confirmed() == []
    with pytest.raises(ValueError, match="closed"):
        det.confirmed()


def test_erase(detector, views):
    first, second, descriptors, _ = views
    detector.add(0, 0.0, descriptor(1), first, descriptors)
    detector.add(10, 10.0, descriptor(1), second, descriptors)
    with pytest.raises(topoloc.InvalidArgumentError):
        detector.erase(77)
    assert len(detector) == 2
    detector.erase(10)
    assert len(detector) == 1
    assert [c.keyframe_id for c in detector.query(descriptor(1), 4)] == [0]


def test_a_new_session_finds_the_keyframes_just_lost(detector, views):
    first, second, descriptors, _ = views
    detector.add(0, 100.0, descriptor(1), first, descriptors)
    # Inside the exclusion window (5 ids) of keyframe 0.
    excluded = detector.add(3, 100.5, descriptor(1), second, descriptors)
    assert excluded.gate is topoloc.Gate.NO_CANDIDATE
    detector.begin_session()
    # The host's new map restarted its clock: an earlier time is accepted, once.
    hint = detector.add(4, 0.0, descriptor(1), second, descriptors)
    assert hint.accepted and hint.matched_id in (0, 3)
    with pytest.raises(topoloc.InvalidArgumentError):
        detector.add(5, -1.0, descriptor(1), second, descriptors)
    assert len(detector) == 3


def test_save_load_and_second_session(tmp_path, detector, views):
    first, second, descriptors, _ = views
    detector.add(0, 0.0, descriptor(1), first, descriptors)
    detector.add(10, 10.0, descriptor(1), second, descriptors)
    path = tmp_path / "loops.topomap"
    detector.save(path)
    with topoloc.Map.load(
        path, expected_kind="test", expected_model="loops", expected_dim=DIM
    ) as m:
        assert m.view_count == 2
        assert sorted(m.view_info(v).keyframe_id for v in range(m.view_count)) == [0, 10]
        assert m.keypoint_total == 2 * len(first)  # the keyframes' keypoints are saved
        again = topoloc.LoopDetector.from_map(m, **OPTIONS)
    # The map handle is not kept.
    with again:
        assert (
            len(again) == 2
            and again.dim == DIM
            and again.options == dict(topoloc.loop_options_default(), **OPTIONS)
        )
        # The same place seen again (not the same image: that is refused as SELF_MATCH).
        hint = again.add(20, 20.0, descriptor(1), first + 0.25, descriptors)
        # Verified against the saved keypoints, as live.
        assert hint.query_id == 20 and hint.has_match and hint.inliers >= 30
        assert hint.gate == topoloc.Gate.ACCEPTED and hint.matched_id in (0, 10)
        assert len(again) == 3
        assert {c.keyframe_id for c in again.query(descriptor(1), 8)} == {0, 10, 20}
    with pytest.raises(TypeError):
        topoloc.LoopDetector.from_map(str(path))


def test_save_errors(tmp_path):
    with topoloc.LoopDetector("test", "loops", DIM) as det:
        with pytest.raises(topoloc.EmptyMapError):
            det.save(tmp_path / "empty.topomap")
        det.add(0, 0.0, descriptor(1))
        with pytest.raises(topoloc.MapIOError):
            det.save(tmp_path / "missing" / "dir" / "x.topomap")


def test_keyframes_without_keypoints(detector):
    # Descriptor-only keyframes join the place graph but never close a loop.
    for i in range(3):
        hint = detector.add(10 * i, float(i), descriptor(i))
        assert hint.query_id == 10 * i and not hint.accepted and hint.inliers == 0
        assert hint.gate != topoloc.Gate.ACCEPTED
    assert len(detector) == 3


def test_close_and_context_manager(views):
    det = topoloc.LoopDetector("test", "loops", DIM)
    assert not det.closed and "keyframes=0" in repr(det)
    det.close()
    det.close()  # idempotent
    assert det.closed and "closed" in repr(det)
    with pytest.raises(ValueError, match="closed"):
        len(det)
    with pytest.raises(ValueError, match="closed"):
        det.add(0, 0.0, descriptor(1))
    with pytest.raises(ValueError, match="closed"):
        with det:
            pass
    with topoloc.LoopDetector("test", "loops", DIM) as det:
        det.add(0, 0.0, descriptor(1))
    assert det.closed
