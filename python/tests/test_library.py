"""The binding layer itself: versions, finding the library, struct layouts and function
signatures against the C header, status codes and error messages."""

from __future__ import annotations

import ctypes
import os
import pickle
import re
import shutil
import subprocess
import sys
from ctypes import (
    CFUNCTYPE,
    POINTER,
    c_bool,
    c_char,
    c_char_p,
    c_double,
    c_float,
    c_size_t,
    c_uint8,
    c_uint16,
    c_uint32,
    c_uint64,
    c_void_p,
)
from pathlib import Path

import pytest

import topoloc
from topoloc import _errors, _lib, _options, _version

from conftest import HEADER, PACKAGE_PARENT, REPO_ROOT

needs_header = pytest.mark.skipif(
    HEADER is None or not HEADER.is_file(), reason="not a source checkout"
)


# ---------------------------------------------------------------------------------------------
# Versions
# ---------------------------------------------------------------------------------------------


def test_version_matches_cargo_and_header():
    v = topoloc.version()
    assert re.fullmatch(r"\d+\.\d+\.\d+", v), v
    assert topoloc.__version__ == v
    if REPO_ROOT is not None:
        cargo = (REPO_ROOT / "Cargo.toml").read_text()
        m = re.search(r'^\[package\][^\[]*?^version\s*=\s*"([^"]+)"', cargo, re.M | re.S)
        assert m and m.group(1) == v
    if HEADER is not None and HEADER.is_file():
        text = HEADER.read_text()
        assert f'#define TOPOLOC_VERSION_STRING "{v}"' in text


def test_abi_version():
    assert topoloc.abi_version() == 1
    assert topoloc.ABI_VERSION == 1
    assert isinstance(topoloc.abi_version(), int)


@needs_header
def test_abi_and_mode_constants_match_header():
    text = HEADER.read_text()
    defines = dict(re.findall(r"#define (TOPOLOC_\w+) (\d+)\b", text))
    assert int(defines["TOPOLOC_ABI_VERSION"]) == _lib.ABI_VERSION
    assert int(defines["TOPOLOC_ABI_VERSION_MINOR"]) == _lib.ABI_VERSION_MINOR
    assert int(defines["TOPOLOC_MODE_FILTER"]) == topoloc.MODE_FILTER == 0
    assert int(defines["TOPOLOC_MODE_SINGLE_FRAME"]) == topoloc.MODE_SINGLE_FRAME == 1


CONSTANT_GROUPS = {
    "PIXEL": [
        "PIXEL_NONE",
        "PIXEL_GRAY8",
        "PIXEL_RGB8",
        "PIXEL_BGR8",
        "PIXEL_RGBA8",
        "PIXEL_BGRA8",
    ],
    "BACKEND": [
        "BACKEND_AUTO",
        "BACKEND_NONE",
        "BACKEND_ONNX",
        "BACKEND_VLAD_ORB",
        "BACKEND_VLAD_SIFT",
    ],
    "STAGE": ["STAGE_DESCRIBING", "STAGE_FITTING"],
    "NODE": ["NODE_END", "NODE_CORNER", "NODE_BRANCH", "NODE_INTERMEDIATE"],
    "LOCAL_FEATURES": ["LOCAL_FEATURES_ORB", "LOCAL_FEATURES_XFEAT", "LOCAL_FEATURES_CELLS"],
    "GATE": [
        "GATE_ACCEPTED",
        "GATE_NO_CANDIDATE",
        "GATE_TOO_FEW_INLIERS",
        "GATE_INCONSISTENT",
        "GATE_NO_POSE",
        "GATE_ODOMETRY",
    ],
}


@needs_header
@pytest.mark.parametrize("group", sorted(CONSTANT_GROUPS))
def test_constant_groups_match_header(group):
    text = HEADER.read_text()
    defines = {n: int(v) for n, v in re.findall(rf"#define TOPOLOC_({group}_\w+) (\d+)\b", text)}
    shim = {n: v for n, v in vars(_lib).items() if n.startswith(group + "_")}
    assert set(defines) == set(shim), (
        f"TOPOLOC_{group}_* added to or removed from the header or the shim"
    )
    assert set(defines) >= set(CONSTANT_GROUPS[group])
    for name, value in defines.items():
        assert type(shim[name]) is int and shim[name] == value, name
    assert len(set(defines.values())) == len(defines), f"duplicate TOPOLOC_{group}_* values"


def test_node_kinds_are_exported_in_code_order():
    assert [
        topoloc.NODE_END,
        topoloc.NODE_CORNER,
        topoloc.NODE_BRANCH,
        topoloc.NODE_INTERMEDIATE,
    ] == [0, 1, 2, 3]
    assert [getattr(topoloc, f"NODE_{k.upper()}") for k in topoloc._skeleton.NODE_KINDS] == [
        0,
        1,
        2,
        3,
    ]


def test_zero_constants_are_the_defaults():
    # An all-zero topoloc_image is "no image"; a zeroed backend field is "auto".
    assert _lib.PIXEL_NONE == 0
    assert _lib.BACKEND_AUTO == 0


def test_library_path_is_the_loaded_file():
    assert Path(topoloc.library_path).is_file()
    if "TOPOLOC_LIBRARY" not in os.environ and REPO_ROOT is not None:
        # In a source checkout without an override, the freshly built library is used.
        assert Path(topoloc.library_path).name.startswith("libtopoloc")


# ---------------------------------------------------------------------------------------------
# Struct layouts against the library and the header
# ---------------------------------------------------------------------------------------------

DEFAULT_FUNCTIONS = {
    "topoloc_view_info": "topoloc_view_info_init",
    "topoloc_view_attributes": "topoloc_view_attributes_init",
    "topoloc_keyframe_options": "topoloc_keyframe_options_init",
    "topoloc_localizer_options": "topoloc_localizer_options_init",
    "topoloc_frame": "topoloc_frame_init",
    "topoloc_result": "topoloc_result_init",
    "topoloc_map_load_options": "topoloc_map_load_options_init",
    "topoloc_image_map_options": "topoloc_image_map_options_init",
    "topoloc_skeleton_options": "topoloc_skeleton_options_init",
    "topoloc_describer_options": "topoloc_describer_options_init",
    "topoloc_keyframe_describer_options": "topoloc_keyframe_describer_options_init",
    "topoloc_loop_options": "topoloc_loop_options_init",
    "topoloc_loop_keyframe": "topoloc_loop_keyframe_init",
    "topoloc_loop_hint": "topoloc_loop_hint_init",
    "topoloc_trajectory_options": "topoloc_trajectory_options_init",
    "topoloc_trajectory_report": "topoloc_trajectory_report_init",
}

#: Structs the library never fills with defaults: plain data the caller writes (array elements,
#: or ``topoloc_image``, embedded in ``topoloc_frame`` and zero for "no image").
NO_DEFAULT_FUNCTION = {
    "topoloc_keyframe",
    "topoloc_candidate",
    "topoloc_image",
    "topoloc_loop_candidate",
    "topoloc_loop_candidate_check",
    "topoloc_depth_image",
    "topoloc_error_stats",
}


@pytest.mark.parametrize("struct_name", sorted(DEFAULT_FUNCTIONS))
def test_struct_size_matches_library_default(struct_name):
    cls = _lib.STRUCTS[struct_name]
    fill = getattr(_lib.lib, DEFAULT_FUNCTIONS[struct_name])
    assert _options.library_struct_size(cls, fill) == ctypes.sizeof(cls)


def test_struct_size_written_by_view_info_and_process(corridor):
    # topoloc_view_info has no _default(): the library writes its sizeof when it fills one.
    info, keep = _options.scratch_struct(_lib.topoloc_view_info)
    info.struct_size = ctypes.sizeof(_lib.topoloc_view_info)
    assert _lib.lib.topoloc_map_view_info(corridor.map._h, 0, ctypes.byref(info)) == 0
    assert ctypes.cast(keep, POINTER(c_size_t))[0] == ctypes.sizeof(_lib.topoloc_view_info)
    # topoloc_result: process writes struct_size = the library's sizeof.
    loc = topoloc.Localizer(corridor.map)
    loc.process(corridor.query(0), 0.0)
    assert loc._result.struct_size == ctypes.sizeof(_lib.topoloc_result)


def test_struct_size_below_minimum_is_refused(corridor):
    info = _lib.topoloc_view_info()
    info.struct_size = 8
    status = _lib.lib.topoloc_map_view_info(corridor.map._h, 0, ctypes.byref(info))
    assert status == topoloc.StructSizeError.STATUS
    with pytest.raises(topoloc.StructSizeError, match="struct_size"):
        _errors.check(status)


def test_defaults_are_the_library_defaults():
    raw = _options.defaults(_lib.topoloc_localizer_options, _lib.lib.topoloc_localizer_options_init)
    d = topoloc.localizer_options_default()
    assert d["mode"] == "filter"
    # Every real option (each named as its field) reads back exactly as the library stores it.
    reals = [name for name, value in d.items() if isinstance(value, float)]
    assert "temperature" in reals and "off_map_margin" in reals
    for name in reals:
        assert d[name] == pytest.approx(getattr(raw, name), abs=0, rel=0), name
    assert d["top_k"] == raw.top_k >= 1
    assert 0 < d["temperature"] < 1
    assert d["metric_particles"] == raw.metric_particles >= 1
    assert d["metric_temperature"] == raw.metric_temperature > 0
    assert d["metric_seed"] == raw.metric_seed == 0
    for name in ("camera_fx", "camera_fy", "camera_cx", "camera_cy"):
        assert d[name] == getattr(raw, name) == 0.0, name  # no camera: no pose fixes
    assert d["pose_min_inliers"] == raw.pose_min_inliers == 30
    assert d["verify_off_map_inliers"] == raw.verify_off_map_inliers == -1.0  # the kind's
    assert d["verify_off_map_inlier_scale"] == raw.verify_off_map_inlier_scale == 4.0
    # Every field of the struct is an option (the expected_descriptor_* ones by shorter names).
    renamed = {
        "expected_descriptor_kind": "expected_kind",
        "expected_descriptor_model": "expected_model",
    }
    assert set(d) == {renamed.get(name, name) for name, _ in raw._fields_} - {"struct_size"}
    kf = topoloc.keyframe_options_default()
    raw_kf = _options.defaults(
        _lib.topoloc_keyframe_options, _lib.lib.topoloc_keyframe_options_init
    )
    assert kf["place_spacing_m"] == raw_kf.place_spacing_m > 0
    assert kf["max_views_per_place"] == raw_kf.max_views_per_place >= 1


def _filled_by_init(cls, init):
    """A ``cls`` whose bytes are all 0xAB before the library's ``_init`` fills it."""
    out = cls()
    ctypes.memset(ctypes.byref(out), 0xAB, ctypes.sizeof(cls))
    _errors.check(init(ctypes.byref(out), ctypes.sizeof(cls)))
    return out


def test_image_fields_of_the_library_defaults():
    frame = _filled_by_init(_lib.topoloc_frame, _lib.lib.topoloc_frame_init)
    assert frame.struct_size == ctypes.sizeof(_lib.topoloc_frame)
    img = frame.image
    assert (img.format, img.width, img.height, img.stride, img.data_len) == (
        _lib.PIXEL_NONE,
        0,
        0,
        0,
        0,
    )
    assert not img.data
    opts = _filled_by_init(_lib.topoloc_localizer_options, _lib.lib.topoloc_localizer_options_init)
    assert opts.image_backend == _lib.BACKEND_AUTO
    assert opts.onnx_model_path is None and opts.onnx_runtime_path is None
    io = _filled_by_init(_lib.topoloc_image_map_options, _lib.lib.topoloc_image_map_options_init)
    assert io.struct_size == ctypes.sizeof(_lib.topoloc_image_map_options)
    assert io.backend in (_lib.BACKEND_AUTO, _lib.BACKEND_ONNX)
    for name in ("onnx_model_path", "onnx_runtime_path", "onnx_taps", "poses_tum_path"):
        assert getattr(io, name) is None, name
    assert io.dim >= 1 and io.views_per_place >= 1 and io.grid_rows >= 1 and io.grid_cols >= 1
    assert io.vlad_clusters >= 1 and 0 < io.place_spacing_m < 1e6


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def _header_integer_typedefs() -> dict:
    """``typedef uint32_t topoloc_mode;`` and its kind, read from the header: alias -> type."""
    if HEADER is None or not HEADER.is_file():
        return {}
    return {
        alias: base
        for base, alias in re.findall(
            r"^typedef (u?int\d+_t) (topoloc_\w+);", HEADER.read_text(), re.M
        )
    }


def _ctype_for(c_type: str):
    """ctypes type the shim must use for a C type written in the header.

    ``const char *`` is ``c_char_p`` (a string in), ``char *`` is ``POINTER(c_char)`` (a buffer
    out), ``void *`` is ``c_void_p``; every further ``*`` wraps a ``POINTER``, so
    ``const char *const *`` (an array of strings) is ``POINTER(c_char_p)``. A ``const`` after a
    ``*`` qualifies the pointer itself and does not change the ctypes type."""
    t = c_type.strip().replace("struct ", "")
    m = re.fullmatch(r"(const\s+)?(\w+)\s*((?:\*\s*(?:const\b\s*)?)*)", t)
    assert m, f"unparsed C type {c_type!r}"
    const, base, pointers = bool(m.group(1)), m.group(2), m.group(3)
    stars = pointers.count("*")
    if base == "char" and stars >= 1:
        ty = c_char_p if const else POINTER(c_char)
        for _ in range(stars - 1):
            ty = POINTER(ty)
        return ty
    if base == "void" and stars >= 1:
        ty = c_void_p
        for _ in range(stars - 1):
            ty = POINTER(ty)
        return ty
    table = {
        "size_t": c_size_t,
        "bool": c_bool,
        "uint64_t": c_uint64,
        "uint32_t": c_uint32,
        "uint16_t": c_uint16,
        "uint8_t": c_uint8,
        "float": c_float,
        "double": c_double,
        "topoloc_status": c_uint32,
        "topoloc_progress_fn": _lib.topoloc_progress_fn,
        "topoloc_log_fn": _lib.topoloc_log_fn,
        "void": None,
    }
    table.update(_lib.STRUCTS)
    table.update(_lib.HANDLES)
    # Integer typedefs of the header (topoloc_mode, topoloc_backend, ...) are their base type.
    for alias, aliased in _header_integer_typedefs().items():
        table[alias] = table[aliased]
    ty = table[base]
    for _ in range(stars):
        ty = POINTER(ty)
    return ty


def _split_decl(decl: str):
    """'const double *world_T_camera' -> ('const double *', 'world_T_camera', None);
    'double world_T_camera[16]' -> ('double', 'world_T_camera', 16)."""
    m = re.fullmatch(r"\s*(.*?[\s*])(\w+)\s*(?:\[(\d+)\])?\s*", decl, re.S)
    assert m, decl
    return m.group(1).strip(), m.group(2), int(m.group(3)) if m.group(3) else None


def _header_structs():
    text = _strip_comments(HEADER.read_text())
    out = {}
    for name, body in re.findall(r"typedef struct (\w+) \{(.*?)\} \1;", text, re.S):
        fields = []
        for decl in body.split(";"):
            if decl.strip():
                c_type, field, array = _split_decl(decl)
                ty = _ctype_for(c_type)
                fields.append((field, ty * array if array else ty))
        out[name] = fields
    return out


def _header_functions():
    text = _strip_comments(HEADER.read_text())
    out = {}
    for ret, name, params in re.findall(r"^([\w \*]+?)\s*\b(topoloc_\w+)\(([^)]*)\);", text, re.M):
        args = []
        if params.strip() not in ("", "void"):
            for p in params.split(","):
                c_type, _, _ = _split_decl(p)
                args.append(_ctype_for(c_type))
        out[name] = (_ctype_for(ret), args)
    return out


@needs_header
def test_every_header_struct_is_mirrored_exactly():
    structs = _header_structs()
    assert set(structs) == set(_lib.STRUCTS), "structs added to or removed from the header"
    for name, fields in structs.items():
        shim = _lib.STRUCTS[name]._fields_
        assert [f for f, _ in shim] == [f for f, _ in fields], f"{name}: field names/order differ"
        for (field, ty), (_, shim_ty) in zip(fields, shim):
            if isinstance(ty, type) and issubclass(ty, ctypes.Array):
                assert issubclass(shim_ty, ctypes.Array)
                assert shim_ty._type_ is ty._type_ and shim_ty._length_ == ty._length_, (
                    f"{name}.{field}"
                )
            else:
                assert shim_ty is ty, f"{name}.{field}: header {ty}, shim {shim_ty}"


@needs_header
def test_every_header_function_is_declared():
    functions = _header_functions()
    assert len(functions) >= 38
    assert set(functions) == set(_lib.SIGNATURES), "functions added to or removed from the header"
    for name, (restype, argtypes) in functions.items():
        fn = getattr(_lib.lib, name)
        assert fn.restype is restype, f"{name}: restype {fn.restype}, header {restype}"
        assert list(fn.argtypes) == argtypes, f"{name}: argtypes differ from the header"


@pytest.mark.parametrize(
    "c_type, expected",
    [
        ("const char *", c_char_p),
        ("char *", POINTER(c_char)),
        ("const char *const *", POINTER(c_char_p)),
        ("char *const *", POINTER(POINTER(c_char))),
        ("void *", c_void_p),
        ("void", None),
        ("const struct topoloc_image *", POINTER(_lib.topoloc_image)),
        ("struct topoloc_image", _lib.topoloc_image),
        ("struct topoloc_map **", POINTER(_lib.MapPtr)),
        ("const double *", POINTER(c_double)),
        ("topoloc_progress_fn", _lib.topoloc_progress_fn),
        ("topoloc_status", c_uint32),
    ],
)
def test_c_type_mapping_of_the_checks(c_type, expected):
    # The drift checks above are only as good as this mapping.
    assert _ctype_for(c_type) is expected


#: Fields of the extended structs as first released (ABI 1): later versions only append.
ABI1_FIELDS = {
    "topoloc_localizer_options": [
        "struct_size",
        "mode",
        "temperature",
        "stay_probability",
        "jump_probability",
        "off_map_probability",
        "off_map_similarity",
        "off_map_margin",
        "top_k",
        "expected_descriptor_kind",
        "expected_descriptor_model",
    ],
    "topoloc_frame": ["struct_size", "timestamp", "descriptor", "descriptor_len", "odometry"],
}

#: Fields appended to them for images.
IMAGE_FIELDS = {
    "topoloc_localizer_options": [
        ("image_backend", c_uint32),
        ("onnx_model_path", c_char_p),
        ("onnx_runtime_path", c_char_p),
    ],
    "topoloc_frame": [("image", _lib.topoloc_image)],  # embedded by value, not a pointer
}

#: Fields appended after those for geometric verification (ABI 1.2).
VERIFICATION_FIELDS = {
    "topoloc_localizer_options": [
        ("verify_candidates", c_uint32),
        ("verify_views_per_candidate", c_uint32),
        ("verify_inlier_weight", c_float),
    ],
    "topoloc_frame": [],
}

#: Fields appended after those for metric mode (ABI 1.3).
METRIC_FIELDS = {
    "topoloc_localizer_options": [
        ("metric_particles", c_uint32),
        ("metric_temperature", c_float),
        ("metric_seed", c_uint64),
    ],
    "topoloc_frame": [],
}

#: Fields appended after those for pose fixes (ABI 1.6).
POSE_FIX_FIELDS = {
    "topoloc_localizer_options": [
        ("camera_fx", c_double),
        ("camera_fy", c_double),
        ("camera_cx", c_double),
        ("camera_cy", c_double),
        ("pose_min_inliers", c_uint32),
    ],
    "topoloc_frame": [],
}

#: Fields appended after those for off-map evidence from verification (ABI 1.9).
OFF_MAP_FIELDS = {
    "topoloc_localizer_options": [
        ("verify_off_map_inliers", c_double),
        ("verify_off_map_inlier_scale", c_double),
    ],
    "topoloc_frame": [],
}

#: Fields appended after those for the learned estimator (ABI 1.16).
GRNN_FIELDS = {
    "topoloc_localizer_options": [("grnn_model_path", c_char_p)],
    "topoloc_frame": [],
}

#: Fields of topoloc_result from ``candidates_len`` on, in order: verification (ABI 1.2), then
#: pose fixes (ABI 1.6). Their types are checked with every field's by
#: test_every_header_struct_is_mirrored_exactly.
RESULT_VERIFICATION_FIELDS = ["candidates_len", "verified", "inliers"]
RESULT_POSE_FIX_FIELDS = ["has_pose_fix", "pose_fix_view", "pose_fix_inliers", "world_T_camera"]
RESULT_TAIL_FIELDS = RESULT_VERIFICATION_FIELDS + RESULT_POSE_FIX_FIELDS


@needs_header
def test_image_structs_are_in_the_layout_checks():
    structs = _header_structs()
    for name in ("topoloc_image", "topoloc_image_map_options"):
        assert name in structs and name in _lib.STRUCTS, name
        assert len(structs[name]) >= 6, f"{name}: header parse found {structs[name]}"
    image = dict(structs["topoloc_image"])
    assert image["data"] is POINTER(c_uint8) and image["format"] is c_uint32
    assert dict(structs["topoloc_image_map_options"])["struct_size"] is c_size_t
    assert structs["topoloc_image_map_options"][0][0] == "struct_size"  # versioned by its size
    for name, old in ABI1_FIELDS.items():
        fields = structs[name]
        assert [f for f, _ in fields[: len(old)]] == old, f"{name}: an ABI 1 field moved"
        images = len(old) + len(IMAGE_FIELDS[name])
        assert fields[len(old) : images] == IMAGE_FIELDS[name], (
            f"{name}: image fields not appended as expected"
        )
        verification = images + len(VERIFICATION_FIELDS[name])
        assert fields[images:verification] == VERIFICATION_FIELDS[name], (
            f"{name}: verification fields not appended"
        )
        metric = verification + len(METRIC_FIELDS[name])
        assert fields[verification:metric] == METRIC_FIELDS[name], (
            f"{name}: metric fields not appended"
        )
        pose = metric + len(POSE_FIX_FIELDS[name])
        assert fields[metric:pose] == POSE_FIX_FIELDS[name], f"{name}: pose fix fields not appended"
        off_map = pose + len(OFF_MAP_FIELDS[name])
        assert fields[pose:off_map] == OFF_MAP_FIELDS[name], f"{name}: off-map fields not appended"
        assert fields[off_map:] == GRNN_FIELDS[name], f"{name}: GRNN fields not appended"
    result = [f for f, _ in structs["topoloc_result"]]
    assert result[-len(RESULT_TAIL_FIELDS) :] == RESULT_TAIL_FIELDS, "result: fields not appended"


@needs_header
def test_every_default_macro_is_checked():
    text = HEADER.read_text()
    macros = dict(
        re.findall(
            r"#define (topoloc_\w+)_default\(p\) (topoloc_\w+_init)\(\(p\), sizeof \*\(p\)\)", text
        )
    )
    assert "topoloc_image_map_options" in macros
    assert macros == DEFAULT_FUNCTIONS
    assert not NO_DEFAULT_FUNCTION & set(DEFAULT_FUNCTIONS)
    assert NO_DEFAULT_FUNCTION | set(DEFAULT_FUNCTIONS) == set(_lib.STRUCTS)


@needs_header
def test_image_build_functions_match_header():
    functions = _header_functions()
    options, progress = POINTER(_lib.topoloc_image_map_options), _lib.topoloc_progress_fn
    tail = [c_size_t, options, progress, c_void_p, POINTER(_lib.MapPtr)]
    expected = {
        "topoloc_map_build_from_image_files": (c_uint32, [POINTER(c_char_p), *tail]),
        "topoloc_map_build_from_images": (c_uint32, [POINTER(_lib.topoloc_image), *tail]),
        "topoloc_image_map_options_init": (c_uint32, [options, c_size_t]),
    }
    for name, (restype, argtypes) in expected.items():
        assert functions[name] == (restype, argtypes), name
        fn = getattr(_lib.lib, name)
        assert fn.restype is restype and list(fn.argtypes) == argtypes, name


def _header_callbacks():
    """Function-pointer typedefs of the header: name -> (return type, [parameter types])."""
    text = _strip_comments(HEADER.read_text())
    out = {}
    for ret, name, params in re.findall(
        r"typedef\s+([\w \*]+?)\s*\(\s*\*\s*(\w+)\s*\)\s*\(([^)]*)\);", text
    ):
        out[name] = (_ctype_for(ret), [_ctype_for(_split_decl(p)[0]) for p in params.split(",")])
    return out


#: The callback typedefs of the header, their ctypes prototypes and their C signatures.
CALLBACKS = {
    "topoloc_progress_fn": (
        _lib.topoloc_progress_fn,
        (c_bool, [c_void_p, c_uint32, c_size_t, c_size_t]),
    ),
    "topoloc_log_fn": (_lib.topoloc_log_fn, (None, [c_uint32, c_char_p, c_char_p, c_void_p])),
}


@needs_header
def test_callback_typedefs_match_ctypes():
    callbacks = _header_callbacks()
    assert set(callbacks) == set(CALLBACKS), "callback typedefs added to or removed from the header"
    for name, (fn, signature) in CALLBACKS.items():
        restype, argtypes = callbacks[name]
        assert (restype, argtypes) == signature, name
        assert fn._restype_ is restype, name
        assert list(fn._argtypes_) == argtypes, name
        assert fn._flags_ == CFUNCTYPE(c_bool)._flags_, (
            name
        )  # C calling convention, errno not swapped


@needs_header
def test_progress_fn_signature_compiles_against_header(tmp_path):
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler")
    c_names = {c_bool: "bool", c_void_p: "void *", c_uint32: "uint32_t", c_size_t: "size_t"}
    fn = _lib.topoloc_progress_fn
    params = ", ".join(f"{c_names[t]} a{i}" for i, t in enumerate(fn._argtypes_))
    src = tmp_path / "progress.c"
    src.write_text(
        '#include "topoloc.h"\n'
        f"static {c_names[fn._restype_]} cb({params}) {{ return 1; }}\n"
        "topoloc_progress_fn f = cb;\n"
    )
    proc = subprocess.run(
        [
            cc,
            "-std=c11",
            "-Werror",
            "-Wall",
            "-Wno-unused-parameter",
            "-c",
            "-I",
            str(HEADER.parent),
            str(src),
            "-o",
            str(tmp_path / "progress.o"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr


def test_every_signature_is_applied_to_the_library():
    for name, (restype, argtypes) in _lib.SIGNATURES.items():
        fn = getattr(_lib.lib, name)
        assert fn.restype is restype
        assert list(fn.argtypes) == list(argtypes)


@needs_header
def test_struct_offsets_match_a_c_compiler(tmp_path):
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler")
    lines = []
    for name, cls in _lib.STRUCTS.items():
        lines.append(f'printf("{name} size %zu\\n", sizeof({name}));')
        for field, _ in cls._fields_:
            lines.append(f'printf("{name}.{field} %zu\\n", offsetof({name}, {field}));')
    src = tmp_path / "layout.c"
    src.write_text(
        '#include <stdio.h>\n#include <stddef.h>\n#include "topoloc.h"\nint main(void) {\n'
        + "\n".join(lines)
        + "\nreturn 0;\n}\n"
    )
    exe = tmp_path / "layout"
    subprocess.run([cc, "-std=c11", "-I", str(HEADER.parent), str(src), "-o", str(exe)], check=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    measured = dict(line.rsplit(" ", 1) for line in out.splitlines())
    for name, cls in _lib.STRUCTS.items():
        assert int(measured[f"{name} size"]) == ctypes.sizeof(cls), name
        for field, _ in cls._fields_:
            assert int(measured[f"{name}.{field}"]) == getattr(cls, field).offset, f"{name}.{field}"


# ---------------------------------------------------------------------------------------------
# Status codes and error messages
# ---------------------------------------------------------------------------------------------


@needs_header
def test_status_codes_match_header():
    text = _strip_comments(HEADER.read_text())
    enum = re.search(r"enum topoloc_status[^{]*\{(.*?)\};", text, re.S).group(1)
    header_codes = {int(v): n for n, v in re.findall(r"(TOPOLOC_\w+) = (\d+)", enum)}
    assert header_codes == _errors.STATUS_NAMES


def test_status_names_match_the_librarys_table():
    """The library's own status table (topoloc_status_name) names exactly the codes these
    bindings know, with the same names, so a code added in Rust cannot be missed here."""
    library = {code: topoloc.status_name(code) for code in range(0, 1000)}
    library = {code: name for code, name in library.items() if name is not None}
    assert library == _errors.STATUS_NAMES
    assert topoloc.status_name(7) is None


def test_every_library_status_has_a_class_and_every_class_a_status():
    """Exception classes are matched to the library's statuses by C name (STATUS_NAME): every
    status the loaded library names, TOPOLOC_OK aside, has its class, with the library's code
    as STATUS; and every class names a status the library knows."""
    library = {code: topoloc.status_name(code) for code in range(0, 1000)}
    library = {code: name for code, name in library.items() if name is not None}
    classes = [
        cls
        for cls in vars(_errors).values()
        if isinstance(cls, type)
        and issubclass(cls, topoloc.TopolocError)
        and cls is not topoloc.TopolocError
    ]
    by_name = {cls.STATUS_NAME: cls for cls in classes}
    assert len(by_name) == len(classes), "two classes name the same status"
    assert set(by_name) == set(library.values()) - {"TOPOLOC_OK"}
    for code, name in library.items():
        if code == 0:
            continue
        cls = _errors.error_class_for_status(code)
        assert (cls.STATUS_NAME, cls.STATUS) == (name, code)
        assert cls is by_name[name]
    assert _errors.error_class_for_status(0) is topoloc.TopolocError


def test_abi_minor_version():
    assert topoloc.abi_version_minor() >= _lib.ABI_VERSION_MINOR == 18


EXPECTED_CLASSES = {
    1: "NullArgumentError",
    2: "InvalidArgumentError",
    3: "BufferTooSmallError",
    4: "StructSizeError",
    5: "InvalidUTF8Error",
    6: "ConcurrentUseError",
    100: "MapIOError",
    101: "NotAMapError",
    102: "TruncatedMapError",
    103: "CorruptMapError",
    104: "UnsupportedVersionError",
    105: "DescriptorMismatchError",
    106: "EmptyMapError",
    107: "InvalidMapError",
    108: "UnknownPlaceError",
    109: "UnknownViewError",
    200: "DimensionMismatchError",
    201: "NonFiniteError",
    202: "ZeroDescriptorError",
    203: "TimestampError",
    204: "InvalidOptionError",
    300: "InvalidImageError",
    301: "UninformativeImageError",
    302: "BackendUnavailableError",
    303: "ModelError",
    304: "NoDescriberError",
    305: "CancelledError",
    900: "PanicError",
}


def test_every_status_has_an_expected_class():
    assert set(EXPECTED_CLASSES) == set(_errors.STATUS_NAMES) - {0}
    assert sorted(EXPECTED_CLASSES.values()) == sorted(
        n for n in _errors.__all__ if n.endswith("Error") and n != "TopolocError"
    )


@pytest.mark.parametrize("status", sorted(EXPECTED_CLASSES))
def test_each_status_maps_to_its_class(status):
    cls = _errors.error_class_for_status(status)
    assert cls.__name__ == EXPECTED_CLASSES[status]
    assert cls is getattr(topoloc, EXPECTED_CLASSES[status])
    assert issubclass(cls, topoloc.TopolocError) and cls is not topoloc.TopolocError
    e = _errors.error_from_status(status, "details here")
    assert type(e) is cls and e.status == status and e.message == "details here"
    assert "details here" in str(e) and _errors.STATUS_NAMES[status] in str(e)
    copy = pickle.loads(pickle.dumps(e))
    assert type(copy) is cls and copy.status == status and copy.message == "details here"
    assert topoloc.status_str(status) not in ("", "unknown status code")


def test_unknown_status_gives_base_class():
    e = _errors.error_from_status(777, "future error")
    assert type(e) is topoloc.TopolocError
    assert e.status == 777
    assert topoloc.status_str(777) == "unknown status code"
    assert topoloc.status_str(0) == "ok"


def test_python_exception_hierarchy():
    assert issubclass(topoloc.DimensionMismatchError, ValueError)
    assert issubclass(topoloc.InvalidOptionError, ValueError)
    assert issubclass(topoloc.UnknownPlaceError, IndexError)
    assert issubclass(topoloc.UnknownViewError, IndexError)
    assert not issubclass(topoloc.MapIOError, OSError)
    # Image errors: a bad or blank image is a bad argument value.
    assert topoloc.InvalidImageError.__bases__ == (topoloc.TopolocError, ValueError)
    assert topoloc.UninformativeImageError.__bases__ == (topoloc.TopolocError, ValueError)
    # Backend, model, describer and cancellation errors are not argument errors.
    for cls in (
        topoloc.BackendUnavailableError,
        topoloc.ModelError,
        topoloc.NoDescriberError,
        topoloc.CancelledError,
    ):
        assert cls.__bases__ == (topoloc.TopolocError,), cls
        assert not issubclass(cls, (ValueError, OSError, ImportError)), cls
    # topoloc.CancelledError is an ordinary Exception, unrelated to asyncio's BaseException.
    import asyncio

    assert issubclass(topoloc.CancelledError, Exception)
    assert not issubclass(topoloc.CancelledError, asyncio.CancelledError)
    assert topoloc.CancelledError is not asyncio.CancelledError


def test_error_message_is_read_from_the_library(tmp_path):
    # A long path gives a message longer than any fixed first-guess buffer.
    long_dir = tmp_path / ("d" * 200) / ("e" * 200)
    missing = long_dir / "missing.topomap"
    with pytest.raises(topoloc.MapIOError) as info:
        topoloc.Map.load(missing)
    assert info.value.status == 100
    assert str(missing) in info.value.message
    # The message stays readable (thread-local, not cleared by reading it).
    assert _version.last_error_message() == info.value.message
    assert _version.last_error_message() == info.value.message


def test_last_error_is_per_thread():
    import threading

    with pytest.raises(topoloc.MapIOError) as info:
        topoloc.Map.load("/nonexistent/in/main/thread")
    seen = []
    t = threading.Thread(target=lambda: seen.append(_version.last_error_message()))
    t.start()
    t.join()
    assert seen == [""]
    assert _version.last_error_message() == info.value.message


# ---------------------------------------------------------------------------------------------
# Finding the library
# ---------------------------------------------------------------------------------------------


def test_env_variable_wins_and_is_not_silently_ignored(tmp_path):
    missing = tmp_path / "nope" / "libtopoloc.so"
    assert _lib.candidate_locations({"TOPOLOC_LIBRARY": str(missing)}) == [("env", str(missing))]
    with pytest.raises(topoloc.LibraryNotFoundError) as info:
        _lib.load_library({"TOPOLOC_LIBRARY": str(missing)})
    msg = str(info.value)
    assert isinstance(info.value, ImportError)
    assert str(missing) in msg
    assert "cargo build --release" in msg and "TOPOLOC_LIBRARY" in msg
    assert info.value.tried == [(str(missing), "not found")]


def test_env_variable_pointing_at_a_non_library(tmp_path):
    bogus = tmp_path / "libtopoloc.so"
    bogus.write_text("not an ELF file")
    with pytest.raises(topoloc.LibraryNotFoundError) as info:
        _lib.load_library({"TOPOLOC_LIBRARY": str(bogus)})
    assert "failed to load" in str(info.value)


def test_relative_env_path_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    os.symlink(topoloc.library_path, tmp_path / "libtopoloc.so")
    monkeypatch.chdir(tmp_path)
    assert _lib.candidate_locations({"TOPOLOC_LIBRARY": "libtopoloc.so"}) == [
        ("env", str(tmp_path / "libtopoloc.so"))
    ]
    lib, where = _lib.load_library({"TOPOLOC_LIBRARY": "libtopoloc.so"})
    assert where == str(tmp_path / "libtopoloc.so") and lib.topoloc_abi_version() == 1


def test_env_variable_loads_the_given_library():
    lib, where = _lib.load_library({"TOPOLOC_LIBRARY": topoloc.library_path})
    assert where == topoloc.library_path
    assert lib.topoloc_abi_version() == 1
    assert lib.topoloc_version().decode() == topoloc.version()


def test_nothing_found_lists_every_location(tmp_path):
    pkg = tmp_path / "site-packages" / "topoloc"
    pkg.mkdir(parents=True)
    with pytest.raises(topoloc.LibraryNotFoundError) as info:
        _lib.load_library({}, package_dir=pkg, use_system=False)
    msg = str(info.value)
    assert str(pkg / "libtopoloc.so*") in msg
    assert "not a source checkout" in msg
    assert "cargo build --release --lib" in msg and "TOPOLOC_LIBRARY=" in msg
    assert len(info.value.tried) == 2


def test_library_next_to_the_package_is_found(tmp_path):
    pkg = tmp_path / "topoloc"
    pkg.mkdir()
    copy = pkg / "libtopoloc.so"
    os.symlink(topoloc.library_path, copy)
    lib, where = _lib.load_library({}, package_dir=pkg, use_system=False)
    assert where == str(copy)
    assert lib.topoloc_abi_version() == 1


def test_library_in_a_checkout_is_found(tmp_path):
    repo = tmp_path / "repo"
    pkg = repo / "python" / "topoloc"
    pkg.mkdir(parents=True)
    (repo / "Cargo.toml").write_text("[package]\nname = 'topoloc'\n")
    built = repo / "target" / "release" / "libtopoloc.so"
    built.parent.mkdir(parents=True)
    os.symlink(topoloc.library_path, built)
    kinds = [k for k, _ in _lib.candidate_locations({}, package_dir=pkg, use_system=False)]
    assert kinds == ["package", "checkout"]
    _, where = _lib.load_library({}, package_dir=pkg, use_system=False)
    assert where == str(built)
    # CARGO_TARGET_DIR is searched before <repo>/target.
    locations = _lib.candidate_locations(
        {"CARGO_TARGET_DIR": "/elsewhere"}, package_dir=pkg, use_system=False
    )
    assert locations[1] == ("checkout", "/elsewhere/release/libtopoloc.so")
    assert locations[2] == ("checkout", str(built))


def test_abi_mismatch_is_refused():
    class FakeFunction:
        restype = argtypes = None

        def __call__(self):
            return 2

    class FakeLib:
        topoloc_abi_version = FakeFunction()

    with pytest.raises(topoloc.AbiVersionError) as info:
        _lib._check_abi(FakeLib(), "/fake/libtopoloc.so")
    assert isinstance(info.value, ImportError)
    assert info.value.found == 2 and info.value.expected == 1
    assert "ABI version 2" in str(info.value) and "ABI version 1" in str(info.value)
    _lib._check_abi(_lib.lib, topoloc.library_path)  # the real one passes


def test_import_fails_cleanly_without_the_library(tmp_path):
    env = dict(
        os.environ, TOPOLOC_LIBRARY=str(tmp_path / "missing.so"), PYTHONPATH=str(PACKAGE_PARENT)
    )
    proc = subprocess.run(
        [sys.executable, "-c", "import topoloc"],
        env=env,
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert proc.returncode != 0
    assert "LibraryNotFoundError" in proc.stderr
    assert str(tmp_path / "missing.so") in proc.stderr


def test_import_with_env_override_in_a_fresh_interpreter(tmp_path):
    env = dict(os.environ, TOPOLOC_LIBRARY=topoloc.library_path, PYTHONPATH=str(PACKAGE_PARENT))
    code = "import topoloc; print(topoloc.library_path); print(topoloc.abi_version())"
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == [topoloc.library_path, "1"]
