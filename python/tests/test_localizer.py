"""Localization: answers checked against numpy, filter vs single-frame, candidates, reset,
errors that leave the state unchanged, options, lifetimes and threads."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import topoloc

from conftest import KIND, MODEL, build_corridor, rot_z, unit

# Explicit options so that the expectations do not depend on tuned library defaults.
OPTIONS = dict(
    temperature=0.03,
    stay_probability=0.7,
    jump_probability=0.01,
    off_map_probability=0.01,
    off_map_similarity=0.2,
)


def _check_candidates(r: topoloc.Result, places: int, top_k: int):
    c = r.candidates
    assert len(c) == min(top_k, places)
    probs = [x.probability for x in c]
    assert probs == sorted(probs, reverse=True)
    assert len({x.place for x in c}) == len(c)
    assert all(0.0 <= p <= 1.0 for p in probs)
    assert sum(probs) <= 1.0 + 1e-5
    assert (c[0].place, c[0].view, c[0].probability, c[0].similarity) == (
        r.place,
        r.view,
        r.confidence,
        r.similarity,
    )
    for x in c:
        assert x.view // 2 == x.place  # corridor: views 2p, 2p+1 belong to place p


def test_single_frame_finds_the_place_of_noisy_view_copies(corridor):
    with topoloc.Localizer(corridor.map, mode="single_frame", top_k=4, **OPTIONS) as loc:
        order = [7, 2, 11, 0, 5, 5, 9, 3]  # any order: frames are independent
        for i, place in enumerate(order):
            q = corridor.query(place, view=i % 2)
            r = loc.process(q, timestamp=100.0 - i)  # decreasing timestamps are fine here
            exp_place, exp_view, exp_sim = corridor.expected_single_frame(q)
            assert exp_place == place  # the fixture's noise is small enough
            assert (r.place, r.view) == (exp_place, exp_view)
            assert r.similarity == pytest.approx(exp_sim, abs=1e-5)
            assert r.frame_index == i
            assert r.confidence > 0.9
            assert not r.off_map
            _check_candidates(r, corridor.places, 4)
            # Each candidate's similarity is that of its view to the query.
            for c in r.candidates:
                expected = float(unit(corridor.views[c.view]) @ unit(q.astype(np.float64)))
                assert c.similarity == pytest.approx(expected, abs=1e-5)


def test_filter_follows_a_walk_and_resolves_ambiguity(corridor):
    # Walk places 0..3 with clear frames, then an ambiguous frame that looks slightly more like
    # far-away place 9 than like place 4. Single-frame picks 9; the filter, which knows the robot
    # was at place 3 a moment ago, picks its neighbour 4.
    v4, v9 = corridor.views[8], corridor.views[18]
    ambiguous = (0.47 * v4 + 0.53 * v9).astype(np.float32)
    assert corridor.expected_single_frame(ambiguous)[0] == 9

    filt = topoloc.Localizer(corridor.map, mode="filter", **OPTIONS)
    single = topoloc.Localizer(corridor.map, mode="single_frame", **OPTIONS)
    for t, place in enumerate(range(4)):
        q = corridor.query(place)
        rf, rs = filt.process(q, t), single.process(q, t)
        assert rf.place == rs.place == place
    rf = filt.process(ambiguous, 4.0)
    rs = single.process(ambiguous, 4.0)
    assert rs.place == 9
    assert rf.place == 4
    assert rf.frame_index == rs.frame_index == 4
    # The filter's belief reflects the prior: place 9 is not even a close second.
    p9 = [c.probability for c in rf.candidates if c.place == 9]
    assert not p9 or p9[0] < 0.1 * rf.confidence
    _check_candidates(rf, corridor.places, 5)


def test_filter_with_odometry(corridor):
    loc = topoloc.Localizer(corridor.map, **OPTIONS)
    r0 = loc.process(corridor.query(2), 0.0, odometry=np.eye(4))
    r1 = loc.process(corridor.query(3), 1.0, odometry=rot_z(0.0, (2.0, 0.0, 0.0)))
    r2 = loc.process(corridor.query(3), 1.5, odometry=rot_z(0.3).tolist())  # nested lists are fine
    assert (r0.place, r1.place, r2.place) == (2, 3, 3)
    assert r2.frame_index == 2


def test_metric_mode_follows_a_walk_with_odometry(corridor):
    """Metric mode moves its particles by the odometry (2 m per frame along x, as the
    corridor's places are spaced); the same seed gives the same answers."""

    queries = [corridor.query(p, noise=0.3) for p in range(6)]

    def walk(loc):
        out = [loc.process(queries[0], 0.0)]
        for p in range(1, 6):
            out.append(loc.process(queries[p], float(p), odometry=rot_z(0.0, (2.0, 0.0, 0.0))))
        return out

    loc = topoloc.Localizer(corridor.map, mode="metric", metric_particles=500, metric_seed=3)
    assert loc.options["mode"] == "metric" and loc.options["metric_particles"] == 500
    assert loc.options["metric_seed"] == 3
    results = walk(loc)
    assert [r.place for r in results] == [0, 1, 2, 3, 4, 5]
    assert all(0 < r.confidence <= 1 for r in results)
    again = walk(
        topoloc.Localizer(corridor.map, mode="metric", metric_particles=500, metric_seed=3)
    )
    assert [(r.place, r.confidence) for r in again] == [(r.place, r.confidence) for r in results]


def test_grnn_mode_checks_its_model_and_map_before_loading_the_runtime(small_map, tmp_path):
    """The learned mode (ABI 1.16): a missing model file is named, a map without edges is
    refused; both before ONNX Runtime is loaded (python/train/smoke.py runs the whole path)."""
    assert topoloc.localizer_options_default()["grnn_model_path"] is None
    missing = tmp_path / "grnn.onnx"
    with pytest.raises(topoloc.BackendUnavailableError, match=r"grnn\.onnx"):
        topoloc.Localizer(small_map, mode="grnn", grnn_model_path=missing)
    with topoloc.MapBuilder("toy", None, 4) as b:
        b.add_place()
        b.add_view(0, np.ones(4))
        bare = b.build()
    with bare, pytest.raises(topoloc.InvalidOptionError, match="no graph"):
        topoloc.Localizer(bare, mode="grnn", grnn_model_path=missing)


def test_metric_mode_needs_positions_and_poses(small_map):
    with pytest.raises(topoloc.InvalidOptionError, match="position"):
        topoloc.Localizer(small_map, mode="metric")
    with pytest.raises(topoloc.InvalidOptionError, match="metric_seed"):
        topoloc.Localizer(small_map, mode="metric", metric_seed=-1)


def test_off_map_frames(corridor):
    # A descriptor orthogonal to every view scores 0 everywhere: the robot is off the map.
    views = corridor.views.astype(np.float64)
    q = corridor.rng.standard_normal(corridor.dim)
    q -= views.T @ np.linalg.lstsq(views.T, q, rcond=None)[0]
    assert np.abs(unit(views) @ unit(q)).max() < 1e-6
    loc = topoloc.Localizer(corridor.map, **OPTIONS)
    first = loc.process(corridor.query(4), 0.0)
    assert not first.off_map and first.off_map_probability < 0.01
    off = [loc.process(q, 1.0 + i) for i in range(3)]
    assert all(r.off_map for r in off)
    assert all(r.off_map_probability > 0.5 for r in off)
    assert all(r.confidence < 0.5 for r in off)  # confidence includes the on-map probability
    back = [loc.process(corridor.query(5), 4.0 + i) for i in range(3)]
    assert not back[-1].off_map and back[-1].place == 5
    # off_map_probability = 0 disables the off-map state.
    never = topoloc.Localizer(corridor.map, **dict(OPTIONS, off_map_probability=0.0))
    for i in range(3):
        r = never.process(q, float(i))
        assert r.off_map is False and r.off_map_probability == 0.0


def test_top_k_larger_than_the_map(small_map):
    loc = topoloc.Localizer(small_map, top_k=50, **OPTIONS)
    r = loc.process([0, 1, 0, 0], 0.0)
    assert len(r.candidates) == 3
    assert sorted(c.place for c in r.candidates) == [0, 1, 2]
    assert r.place == 1
    loc1 = topoloc.Localizer(small_map, top_k=1, **OPTIONS)
    assert [c.place for c in loc1.process([0, 0, 1, 0], 0.0).candidates] == [2]


def test_descriptor_inputs(small_map):
    loc = topoloc.Localizer(small_map, mode="single_frame", **OPTIONS)
    expected = loc.process(np.array([0, 0, 1, 0], dtype=np.float32), 0.0)
    inputs = [
        [0, 0, 1, 0],
        (0, 0, 2, 0),
        np.array([0, 0, 1, 0], dtype=np.float64),
        np.array([0, 0, 5, 0], dtype=np.int64),
        np.asfortranarray(np.array([[0.0, 9.0], [0.0, 9.0], [1.0, 9.0], [0.0, 9.0]]))[
            :, 0
        ],  # strided column
    ]
    for q in inputs:
        r = loc.process(q, 0.0)
        assert (r.place, r.view) == (expected.place, expected.view) == (2, 2)
        assert r.similarity == pytest.approx(expected.similarity, abs=1e-6)
    strided = np.zeros(8, dtype=np.float32)
    strided[4] = 1.0  # every other element -> [0, 0, 1, 0]
    assert loc.process(strided[::2], 0.0).place == 2


def test_reset(corridor):
    loc = topoloc.Localizer(corridor.map, **OPTIONS)
    fresh = topoloc.Localizer(corridor.map, **OPTIONS)
    qs = [corridor.query(p) for p in (0, 1, 2, 6)]
    for t, q in enumerate(qs):
        loc.process(q, 10.0 + t)
    with pytest.raises(topoloc.TimestampError):
        loc.process(qs[0], 0.0)
    loc.reset()
    # After reset: frame 0 again, any timestamp, and the same answer as a new localizer.
    a = loc.process(qs[3], 0.0)
    b = fresh.process(qs[3], 0.0)
    assert a.frame_index == 0
    assert a == b


def test_errors_leave_the_state_unchanged(corridor):
    """An erroneous frame changes nothing: a twin localizer that never saw the bad frames gives
    identical results, and frame_index continues without a gap."""
    loc = topoloc.Localizer(corridor.map, **OPTIONS)
    twin = topoloc.Localizer(corridor.map, **OPTIONS)
    good = [corridor.query(p) for p in (0, 1, 1, 2, 3, 4)]
    bad_pose = np.eye(4)
    bad_pose[0, 0] = 2.0
    nan_pose = np.eye(4)
    nan_pose[1, 3] = np.nan
    bad_frames = [
        (topoloc.DimensionMismatchError, lambda t: loc.process(np.ones(63), t)),
        (topoloc.DimensionMismatchError, lambda t: loc.process(np.ones((8, 8)), t)),
        (topoloc.DimensionMismatchError, lambda t: loc.process([], t)),
        (topoloc.NonFiniteError, lambda t: loc.process(np.full(64, np.nan), t)),
        (topoloc.NonFiniteError, lambda t: loc.process(np.r_[np.ones(63), np.inf], t)),
        (topoloc.ZeroDescriptorError, lambda t: loc.process(np.zeros(64), t)),
        (topoloc.TimestampError, lambda t: loc.process(good[0], t - 5.0)),
        (topoloc.NonFiniteError, lambda t: loc.process(good[0], float("nan"))),
        (topoloc.InvalidArgumentError, lambda t: loc.process(good[0], t, odometry=bad_pose)),
        (topoloc.InvalidArgumentError, lambda t: loc.process(good[0], t, odometry=np.eye(3))),
        (topoloc.NonFiniteError, lambda t: loc.process(good[0], t, odometry=nan_pose)),
    ]
    t = 0.0
    for i, q in enumerate(good):
        a, b = loc.process(q, t), twin.process(q, t)
        assert a == b
        assert a.frame_index == i
        for err_cls, call in bad_frames:
            with pytest.raises(err_cls) as info:
                call(t + 0.5)
            assert info.value.message  # the library (or the shim) explains it
        t += 1.0
    # The timestamp error message names both times.
    with pytest.raises(topoloc.TimestampError, match="earlier"):
        loc.process(good[0], t - 10.0)
    final_a, final_b = loc.process(good[-1], t), twin.process(good[-1], t)
    assert final_a == final_b and final_a.frame_index == len(good)


def test_equal_timestamps_are_allowed(corridor):
    loc = topoloc.Localizer(corridor.map, **OPTIONS)
    assert loc.process(corridor.query(1), 5.0).frame_index == 0
    assert loc.process(corridor.query(1), 5.0).frame_index == 1


@pytest.mark.parametrize(
    "kwargs",
    [
        {"temperature": 0.0},
        {"temperature": -0.1},
        {"temperature": float("nan")},
        {"stay_probability": 1.5},
        {"jump_probability": -0.1},
        {"jump_probability": 0.6, "off_map_probability": 0.4},
        {"off_map_similarity": 2.0},
        {"off_map_margin": float("inf")},
        {"top_k": 0},
        {"top_k": -1},
        {"mode": "bogus"},
        {"mode": "metric", "metric_particles": 0},
        {"mode": "metric", "metric_temperature": 0.0},
        {"mode": 7},
    ],
)
def test_invalid_options(small_map, kwargs):
    with pytest.raises(topoloc.InvalidOptionError) as info:
        topoloc.Localizer(small_map, **kwargs)
    assert info.value.status == 204
    assert info.value.message


def test_options_and_defaults(small_map):
    loc = topoloc.Localizer(small_map)
    assert loc.options == topoloc.localizer_options_default()
    loc = topoloc.Localizer(
        small_map, mode="single_frame", temperature=0.5, top_k=2, expected_kind="toy"
    )
    o = loc.options
    assert o["mode"] == "single_frame" and o["top_k"] == 2 and o["expected_kind"] == "toy"
    assert o["temperature"] == 0.5
    assert o["stay_probability"] == topoloc.localizer_options_default()["stay_probability"]
    assert (
        topoloc.Localizer(small_map, mode=topoloc.MODE_SINGLE_FRAME).options["mode"]
        == "single_frame"
    )


def test_descriptor_mismatch_at_localizer_creation(corridor):
    for kwargs in (
        {"expected_kind": "dinov2"},
        {"expected_model": "other"},
        {"expected_kind": KIND, "expected_model": "x"},
    ):
        with pytest.raises(topoloc.DescriptorMismatchError) as info:
            topoloc.Localizer(corridor.map, **kwargs)
        assert MODEL in info.value.message
    loc = topoloc.Localizer(corridor.map, expected_kind=KIND, expected_model=MODEL)
    assert loc.process(corridor.query(3), 0.0).place == 3


def test_localizer_rejects_a_closed_map_and_non_maps(small_map):
    with pytest.raises(TypeError):
        topoloc.Localizer("not a map")
    c = build_corridor(places=3)
    c.map.close()
    with pytest.raises(ValueError, match="closed"):
        topoloc.Localizer(c.map)


def test_localizer_outlives_its_map():
    c = build_corridor(places=6)
    loc = topoloc.Localizer(c.map, **OPTIONS)
    q = c.query(4)
    before = topoloc.Localizer(c.map, **OPTIONS).process(q, 0.0)
    c.map.close()
    after = loc.process(q, 0.0)
    assert after == before and after.place == 4


def test_localizer_context_manager_and_close(small_map):
    with topoloc.Localizer(small_map) as loc:
        assert loc.process([1, 0, 0, 0], 0.0).place == 0
    assert loc.closed
    with pytest.raises(ValueError, match="closed"):
        loc.process([1, 0, 0, 0], 1.0)
    with pytest.raises(ValueError, match="closed"):
        loc.reset()
    loc.close()  # idempotent
    # The map is still open: the localizer only closed its own handle.
    assert not small_map.closed and small_map.place_count == 3


def test_concurrent_use_of_one_localizer_is_refused(small_map):
    loc = topoloc.Localizer(small_map)
    loc._busy.acquire()  # as if another thread were inside process()
    try:
        with pytest.raises(RuntimeError, match="another thread"):
            loc.process([1, 0, 0, 0], 0.0)
    finally:
        loc._busy.release()
    assert loc.process([1, 0, 0, 0], 0.0).frame_index == 0


def test_many_localizers_share_one_map_across_threads(corridor):
    rng = np.random.default_rng(11)
    walk = [int(p) for p in np.clip(np.cumsum(rng.integers(-1, 2, size=60)) + 5, 0, 11)]
    queries = [corridor.query(p) for p in walk]

    def run():
        with topoloc.Localizer(corridor.map, **OPTIONS) as loc:
            return [loc.process(q, float(t)) for t, q in enumerate(queries)]

    reference = run()
    assert sum(r.place == p for r, p in zip(reference, walk)) >= 58
    results = [None] * 6

    def worker(i):
        results[i] = run()

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(r == reference for r in results)
