"""Options: every call that fills a C options struct does it through one table (Python name ->
C field and converter), takes its options by keyword only, leaves their defaults to the
library's ``_init`` function, and documents them by pointing at the C struct."""

from __future__ import annotations

import inspect
import re

import numpy as np
import pytest

import topoloc
from topoloc import _describer, _lib, _localizer, _loops, _map, _skeleton, _trajectory

#: (call, its option table, the C struct its docstring names, its other keyword-only arguments)
CALLS = [
    (topoloc.Localizer.__init__, _localizer.LOCALIZER_OPTIONS, "topoloc_localizer_options", set()),
    (topoloc.Describer.__init__, _describer.DESCRIBER_OPTIONS, "topoloc_describer_options", set()),
    (topoloc.Map.load, _map.LOAD_OPTIONS, "topoloc_map_load_options", set()),
    (topoloc.Map.from_bytes, _map.LOAD_OPTIONS, None, set()),
    (
        topoloc.Map.build_from_images,
        _map.IMAGE_MAP_OPTIONS,
        "topoloc_image_map_options",
        {"pixel_format", "progress"},
    ),
    (topoloc.Map.build_from_image_files, _map.IMAGE_MAP_OPTIONS, None, {"progress"}),
    (topoloc.map_from_keyframes, _map.KEYFRAME_OPTIONS, "topoloc_keyframe_options", set()),
    (topoloc.skeleton_graph, _skeleton.SKELETON_OPTIONS, "topoloc_skeleton_options", set()),
    (
        topoloc.evaluate_trajectory,
        _trajectory.TRAJECTORY_OPTIONS,
        "topoloc_trajectory_options",
        set(),
    ),
    (topoloc.evaluate_trajectory_files, _trajectory.TRAJECTORY_OPTIONS, None, set()),
]
TABLES = {
    "topoloc_localizer_options": _localizer.LOCALIZER_OPTIONS,
    "topoloc_describer_options": _describer.DESCRIBER_OPTIONS,
    "topoloc_map_load_options": _map.LOAD_OPTIONS,
    "topoloc_image_map_options": _map.IMAGE_MAP_OPTIONS,
    "topoloc_keyframe_options": _map.KEYFRAME_OPTIONS,
    "topoloc_skeleton_options": _skeleton.SKELETON_OPTIONS,
    "topoloc_trajectory_options": _trajectory.TRAJECTORY_OPTIONS,
    "topoloc_loop_options": _loops.LOOP_OPTIONS,
}


def _ids(calls):
    return [call.__qualname__ for call, *_ in calls]


@pytest.mark.parametrize("call, table, struct, others", CALLS, ids=_ids(CALLS))
def test_options_are_keyword_only_and_the_tables(call, table, struct, others):
    params = inspect.signature(call).parameters.values()
    keyword_only = {p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY}
    assert keyword_only - others == set(table)
    assert not {p.name for p in params if p.kind is not inspect.Parameter.KEYWORD_ONLY} & set(table)


@pytest.mark.parametrize("call, table, struct, others", CALLS, ids=_ids(CALLS))
def test_option_defaults_are_left_to_the_library(call, table, struct, others):
    params = inspect.signature(call).parameters
    assert {name: params[name].default for name in table} == dict.fromkeys(table)


#: What a docstring restating an option's default or range looks like.
RESTATED = re.compile(
    r"\((?:the )?default\b|, the default\b|\bdefaults? (?:to|is) |\d\.\.=?\d|>= ?\d"
)


@pytest.mark.parametrize("call, table, struct, others", CALLS, ids=_ids(CALLS))
def test_option_docs_point_to_the_c_struct(call, table, struct, others):
    doc = call.__doc__ or ""
    if call.__name__ == "__init__":
        doc += getattr(topoloc, call.__qualname__.split(".")[0]).__doc__
    doc = " ".join(doc.split())
    if struct is not None:
        assert struct in doc, f"{call.__qualname__} does not name {struct}"
    assert not RESTATED.findall(doc), f"{call.__qualname__} restates a default or range"
    assert "ORB matches" not in doc


@pytest.mark.parametrize("struct_name", sorted(TABLES))
def test_every_field_of_the_struct_is_one_option(struct_name):
    table = TABLES[struct_name]
    assert table.struct is _lib.STRUCTS[struct_name]
    fields = [f for option in table.options.values() for f in option.fields]
    assert sorted(fields) == sorted(
        name for name, _ in table.struct._fields_ if name != "struct_size"
    )


@pytest.mark.parametrize("struct_name", sorted(TABLES))
def test_a_filled_struct_reads_back_its_defaults(struct_name):
    table = TABLES[struct_name]
    assert table.read(table.fill({})) == table.default_values()


def test_the_public_default_dicts_are_the_tables():
    assert topoloc.localizer_options_default() == _localizer.LOCALIZER_OPTIONS.default_values()
    assert topoloc.loop_options_default() == _loops.LOOP_OPTIONS.default_values()
    assert topoloc.keyframe_options_default() == _map.KEYFRAME_OPTIONS.default_values()
    assert topoloc.skeleton_options_default() == _skeleton.SKELETON_OPTIONS.default_values()


def test_options_given_positionally_are_refused(small_map):
    with pytest.raises(TypeError):
        topoloc.Localizer(small_map, "single_frame")
    with pytest.raises(TypeError):
        topoloc.Map.build_from_images([np.zeros((8, 8), np.uint8)] * 2, "vlad-orb")
    with pytest.raises(TypeError):
        topoloc.map_from_keyframes("toy", None, 4, np.eye(4), None, None, 2.0)
    with pytest.raises(TypeError):
        topoloc.Map.from_bytes(b"", "toy")
    reference = np.array([[float(t), t, 0, 0, 0, 0, 0, 1] for t in range(5)])
    with pytest.raises(TypeError):
        topoloc.evaluate_trajectory(reference, reference, "se3")


def test_unknown_option_names_are_refused_with_a_suggestion():
    with pytest.raises(TypeError, match=r"'min_inlier' -> 'min_inliers'") as info:
        topoloc.LoopDetector("test", "loops", 8, min_inlier=30)
    assert "loop detector option" in str(info.value) and "odometry_candidates" in str(info.value)
    with pytest.raises(TypeError, match="unexpected localizer option"):
        _localizer.LOCALIZER_OPTIONS.fill({"temprature": 0.5})


def test_bad_values_raise_the_tables_typed_error(small_map):
    with pytest.raises(topoloc.InvalidOptionError, match="top_k"):
        topoloc.Localizer(small_map, top_k=-1)
    with pytest.raises(topoloc.InvalidOptionError, match="'filter', 'single_frame', 'metric'"):
        topoloc.Localizer(small_map, mode="smoothing")
    with pytest.raises(TypeError, match="temperature must be a real number"):
        topoloc.Localizer(small_map, temperature="warm")
    with pytest.raises(TypeError, match="top_k must be an integer"):
        topoloc.Localizer(small_map, top_k=2.5)
    with pytest.raises(topoloc.InvalidArgumentError, match="max_views_per_place"):
        topoloc.map_from_keyframes("toy", None, 4, np.eye(4), max_views_per_place=-2)
    with pytest.raises(topoloc.InvalidArgumentError, match="backend"):
        topoloc.Map.build_from_images([np.zeros((8, 8), np.uint8)] * 2, backend="cuda")
    with pytest.raises(topoloc.InvalidArgumentError, match="z_band"):
        topoloc.skeleton_graph(np.zeros((4, 4, 4), bool), 0.1, z_band=(0.0, 1.0, 2.0))


def test_enum_options_take_names_codes_and_either_separator(small_map):
    with topoloc.Localizer(small_map, mode="single-frame", image_backend="NONE") as loc:
        assert loc.options["mode"] == "single_frame" and loc.options["image_backend"] == "none"
    with topoloc.Localizer(small_map, mode=topoloc.MODE_METRIC - 1) as loc:
        assert loc.options["mode"] == "single_frame"
