"""Contracts of the loop API that a new host trips over (issue 46), in Python: a session saved
with odometry poses closes loops after a reload; the ABI 1.17 options and what a hint's
translation holds; a keyframe's own image is refused as a self-match; values of the wrong type
(a string flag or timestamp, a complex descriptor) raise ``TypeError`` instead of being
converted silently; ``for_descriptors_of``. Mirrors tests/c/test_loop_contracts.c."""

from __future__ import annotations

import numpy as np
import pytest
from test_loops import DIM, OPTIONS, descriptor, two_views

import topoloc

CAMERA = dict(fx=300.0, fy=300.0, cx=160.0, cy=120.0)


def pose_of(x: float, y: float, z: float, yaw_deg: float) -> np.ndarray:
    """A 4x4 pose: a yaw of ``yaw_deg`` about z and a translation."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    return np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1]], dtype=np.float64)


@pytest.fixture
def views():
    return two_views()


def test_a_session_saved_with_poses_closes_loops_after_a_reload(tmp_path, views):
    first, second, descriptors, _ = views
    path = tmp_path / "session.topomap"
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS, **CAMERA) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors, world_T_body=pose_of(0, 0, 0, 0))
        det.save(path)
    with topoloc.Map.load(path) as m:
        again = topoloc.LoopDetector.from_map(m, **OPTIONS, **CAMERA)
    with again:
        assert again.next_id == 1  # the new run's ids go on past the map's
        # The new run's odometry is in its own world frame, 500 m and 90 degrees away: the
        # map's keyframes are an earlier session's, not compared by the odometry gate.
        hint = again.add(
            1, 0.0, descriptor(1), second, descriptors, world_T_body=pose_of(500, -200, 3, 90)
        )
    assert hint.has_match and hint.matched_id == 0 and hint.inliers >= 30
    assert hint.gate is topoloc.Gate.ACCEPTED and hint.accepted and hint.has_pose
    assert hint.translation is topoloc.Translation.DIRECTION and not hint.scale_known


def test_a_hint_says_what_its_translation_holds(views):
    first, second, descriptors, scene = views
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors)
        hint = det.add(10, 10.0, descriptor(1), second, descriptors)
    assert hint.accepted and not hint.has_pose and hint.translation is topoloc.Translation.NONE
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS, **CAMERA) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors)
        hint = det.add(10, 10.0, descriptor(1), second, descriptors)
    assert hint.accepted and hint.translation is topoloc.Translation.DIRECTION
    assert np.linalg.norm(hint.matched_T_query[:3, 3]) == pytest.approx(1.0, abs=1e-9)
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS, **CAMERA) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors, camera_points=scene)
        hint = det.add(10, 10.0, descriptor(1), second, descriptors)
    assert hint.accepted and hint.scale_known and hint.translation is topoloc.Translation.METRIC


def test_a_keyframe_whose_own_image_is_held_is_a_self_match(views, caplog):
    first, _, descriptors, _ = views
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors)
        with caplog.at_level("WARNING", logger="topoloc"):
            hint = det.add(10, 10.0, descriptor(1), first, descriptors)
        assert hint.has_match and hint.matched_id == 0 and not hint.accepted
        assert hint.gate is topoloc.Gate.SELF_MATCH
        # Moved by a quarter pixel: the same place seen again, accepted.
        again = det.add(20, 20.0, descriptor(1), first + 0.25, descriptors)
        assert again.accepted and again.gate is topoloc.Gate.ACCEPTED
    assert any("same image" in r.getMessage() for r in caplog.records)


def test_the_verification_options_of_abi_1_17():
    with topoloc.LoopDetector(
        "test",
        "loops",
        DIM,
        refine_keyframes=0,
        pose_min_inliers=40,
        pair_estimator="MAGSAC",
        pair_iterations=500,
        pair_min_cosine=0.5,
        cells_pair_estimator=topoloc._lib.PAIR_ESTIMATOR_RANSAC,
        cells_pair_iterations=200,
        cells_pair_min_cosine=0.9,
    ) as det:
        opts = det.options
    assert opts["refine_keyframes"] == 0 and opts["pose_min_inliers"] == 40
    assert opts["pair_estimator"] == "magsac" and opts["pair_iterations"] == 500
    assert opts["pair_min_cosine"] == pytest.approx(0.5)
    assert opts["cells_pair_estimator"] == "ransac" and opts["cells_pair_iterations"] == 200
    assert opts["cells_pair_min_cosine"] == pytest.approx(0.9)
    for bad in (
        dict(refine_keyframes=65),
        dict(pose_min_inliers=0),
        dict(pair_estimator="lmeds"),
        dict(pair_estimator=7),
        dict(pair_iterations=0),
        dict(pair_min_cosine=1.5),
        dict(cells_pair_min_cosine=float("nan")),
    ):
        with pytest.raises(topoloc.InvalidOptionError):
            topoloc.LoopDetector("test", "loops", DIM, **bad)


def test_the_largest_id_gap_returns(views):
    # Once the first verified add walked every id of the gap: it never returned.
    first, second, descriptors, _ = views
    options = dict(OPTIONS, candidate_id_gap=2**64 - 1)
    with topoloc.LoopDetector("test", "loops", DIM, **options) as det:
        det.add(0, 0.0, descriptor(1), first, descriptors)
        assert det.add(10, 10.0, descriptor(1), second, descriptors).accepted


def test_values_of_the_wrong_type_are_refused_not_converted(views):
    first, _, descriptors, _ = views
    # bool("false") is True: a string flag would have turned the gate on.
    for flag in ("false", "", 0, 1):
        with pytest.raises(TypeError, match="odometry_gate must be a bool"):
            topoloc.LoopDetector("test", "loops", DIM, odometry_gate=flag)
    with topoloc.LoopDetector("test", "loops", DIM, odometry_gate=np.bool_(False)) as det:
        assert det.options["odometry_gate"] is False
        with pytest.raises(TypeError, match="timestamp"):
            det.add(0, "0.0", descriptor(1))
        with pytest.raises(TypeError, match="descriptor"):
            det.add(0, 0.0, descriptor(1) + 1j)
        with pytest.raises(TypeError, match="world_T_body"):
            det.add(0, 0.0, descriptor(1), world_T_body=np.eye(4) + 0j)
        assert len(det) == 0
        det.add(0, np.float64(0.0), descriptor(1).astype(np.float64), first, descriptors)
        assert len(det) == 1


def test_bounds_lengths_and_ids_are_refused_as_documented(views):
    first, _, descriptors, _ = views
    # Bounds of a gate that is off are still checked.
    for bad in (float("nan"), -1.0):
        with pytest.raises(topoloc.InvalidOptionError):
            topoloc.LoopDetector(
                "test", "loops", DIM, odometry_gate=False, odometry_max_translation_m=bad
            )
    with topoloc.LoopDetector("test", "loops", DIM, **OPTIONS) as det:
        with pytest.raises(topoloc.DimensionMismatchError):
            det.add(0, 0.0, np.ones(100_000, dtype=np.float32))
        det.add(0, 0.0, descriptor(1), first, descriptors)
        det.add(1, 1.0, descriptor(2), first + 0.5, descriptors)
        det.erase(1)
        # Ids increase past an erased one.
        assert det.next_id == 2
        with pytest.raises(topoloc.InvalidArgumentError):
            det.add(1, 2.0, descriptor(2))
        det.add(2, 2.0, descriptor(2))
        assert len(det) == 2
        det.add(2**64 - 1, 3.0, descriptor(3))
        with pytest.raises(topoloc.InvalidArgumentError, match="no id can follow"):
            _ = det.next_id


def test_for_descriptors_of_takes_a_maps_identity():
    with topoloc.MapBuilder("vlad-orb", "model/v1", DIM) as b:
        b.add_view(b.add_place(), descriptor(1))
        m = b.build()
    with topoloc.LoopDetector.for_descriptors_of(m, **OPTIONS) as det:
        assert det.dim == DIM and len(det) == 0 and det.next_id == 0
        assert det.options == dict(topoloc.loop_options_default(), **OPTIONS)
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.LoopDetector.for_descriptors_of(m, candidates=0)
