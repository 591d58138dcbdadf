"""Low-level ctypes layer: finds and loads ``libtopoloc``, mirrors the C structs of
``include/topoloc.h`` and declares the signature of every C function.

Library search order (the first that exists and loads wins):

1. the ``TOPOLOC_LIBRARY`` environment variable: a path to the shared library (if it is set, it
   must work: the bindings do not silently fall back to another copy);
2. next to this package: ``topoloc/libtopoloc.so*`` (``.dylib`` / ``topoloc.dll`` elsewhere);
3. in a source checkout: ``<repo>/target/release/libtopoloc.so`` (and the same under
   ``$CARGO_TARGET_DIR``), where ``<repo>`` is the first parent directory holding ``Cargo.toml``;
4. the system: ``ctypes.util.find_library("topoloc")``.

If nothing loads, :class:`LibraryNotFoundError` (an ``ImportError``) lists every place tried.
After loading, ``topoloc_abi_version()`` must equal :data:`ABI_VERSION`, the ABI these bindings
were written for, or :class:`AbiVersionError` (also an ``ImportError``) is raised.

Everything here is private API; use the classes of the :mod:`topoloc` package.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
from ctypes import (
    CFUNCTYPE,
    POINTER,
    Structure,
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
from typing import List, Mapping, Optional, Sequence, Tuple

#: ABI version these bindings were written for (``TOPOLOC_ABI_VERSION`` of the header).
ABI_VERSION = 1

#: ABI minor version these bindings were written for (``TOPOLOC_ABI_VERSION_MINOR``): they use
#: items up to "ABI 1.N" of the header.
ABI_VERSION_MINOR = 18

#: Environment variable naming the shared library to load.
ENV_VAR = "TOPOLOC_LIBRARY"

#: ``TOPOLOC_PCA_I8`` / ``TOPOLOC_PCA_F32`` (ABI 1.14): how a built map stores its PCA rows.
PCA_I8 = 0
PCA_F32 = 1

#: ``TOPOLOC_MODE_FILTER`` / ``TOPOLOC_MODE_SINGLE_FRAME`` / ``TOPOLOC_MODE_METRIC`` (ABI 1.3).
MODE_FILTER = 0
MODE_SINGLE_FRAME = 1
MODE_METRIC = 2
#: ``TOPOLOC_MODE_GRNN`` (ABI 1.16): the learned graph recurrent network.
MODE_GRNN = 3

#: ``TOPOLOC_PIXEL_*``: pixel formats of ``topoloc_image`` (8 bits per channel, interleaved).
PIXEL_NONE = 0
PIXEL_GRAY8 = 1
PIXEL_RGB8 = 2
PIXEL_BGR8 = 3
PIXEL_RGBA8 = 4
PIXEL_BGRA8 = 5

#: ``TOPOLOC_BACKEND_*``: describing backends (localizer ``image_backend``, map ``backend``).
BACKEND_AUTO = 0
BACKEND_NONE = 1
BACKEND_ONNX = 2
BACKEND_VLAD_ORB = 3
BACKEND_VLAD_SIFT = 4

#: ``TOPOLOC_STAGE_*``: build stages reported to a progress callback.
STAGE_DESCRIBING = 0
STAGE_FITTING = 1

#: ``TOPOLOC_NODE_*``: kinds of the places of a skeleton graph.
NODE_END = 0
NODE_CORNER = 1
NODE_BRANCH = 2
NODE_INTERMEDIATE = 3

#: ``TOPOLOC_GATE_*`` (ABI 1.5): the gate that decided a loop hint.
GATE_ACCEPTED = 0
GATE_NO_CANDIDATE = 1
GATE_TOO_FEW_INLIERS = 2
GATE_INCONSISTENT = 3
GATE_NO_POSE = 4
GATE_ODOMETRY = 5
#: ``TOPOLOC_GATE_SELF_MATCH`` (ABI 1.17): the candidate is the query's own image.
GATE_SELF_MATCH = 6

#: ``TOPOLOC_PAIR_ESTIMATOR_*`` (ABI 1.17): the estimator of a keyframe pair's geometric check.
PAIR_ESTIMATOR_RANSAC = 0
PAIR_ESTIMATOR_MAGSAC = 1
PAIR_ESTIMATOR_USAC_FAST = 2

#: ``TOPOLOC_TRANSLATION_*`` (ABI 1.17): what a loop hint's translation holds.
TRANSLATION_NONE = 0
TRANSLATION_DIRECTION = 1
TRANSLATION_METRIC = 2

#: ``TOPOLOC_LOCAL_FEATURES_*`` (ABI 1.15): local features of image maps and keyframe describers.
LOCAL_FEATURES_ORB = 1
LOCAL_FEATURES_XFEAT = 2
LOCAL_FEATURES_CELLS = 3

#: ``TOPOLOC_ALIGN_*`` (ABI 1.11): how a trajectory estimate is aligned to its reference.
ALIGN_NONE = 0
ALIGN_SE3 = 1
ALIGN_SIM3 = 2

#: ``TOPOLOC_TRAJECTORY_*`` (ABI 1.11): trajectory file formats.
TRAJECTORY_DETECT = 0
TRAJECTORY_TUM = 1
TRAJECTORY_KITTI = 2
TRAJECTORY_EUROC = 3

TOPOLOC_OK = 0
TOPOLOC_ERR_BUFFER_TOO_SMALL = 3


class LibraryNotFoundError(ImportError):
    """The topoloc shared library could not be found or loaded.

    ``tried`` lists ``(location, reason)`` pairs in search order.
    """

    def __init__(self, message: str, tried: Sequence[Tuple[str, str]] = ()) -> None:
        super().__init__(message)
        self.tried: List[Tuple[str, str]] = list(tried)


class AbiVersionError(ImportError):
    """The loaded library implements another C ABI version than these bindings."""

    def __init__(self, message: str, found: int, expected: int, path: str) -> None:
        super().__init__(message)
        self.found = found
        self.expected = expected
        self.path = path


# --------------------------------------------------------------------------------------------
# Opaque handles and structs (mirroring include/topoloc.h field by field)
# --------------------------------------------------------------------------------------------


class topoloc_map(Structure):
    """Opaque ``topoloc_map`` (only used through pointers)."""


class topoloc_map_builder(Structure):
    """Opaque ``topoloc_map_builder``."""


class topoloc_localizer(Structure):
    """Opaque ``topoloc_localizer``."""


MapPtr = POINTER(topoloc_map)
BuilderPtr = POINTER(topoloc_map_builder)


class topoloc_graph(Structure):
    """Opaque ``topoloc_graph``."""


class topoloc_loop_detector(Structure):
    """Opaque ``topoloc_loop_detector`` (ABI 1.5)."""


LocalizerPtr = POINTER(topoloc_localizer)
GraphPtr = POINTER(topoloc_graph)
LoopDetectorPtr = POINTER(topoloc_loop_detector)


class topoloc_describer(Structure):
    """Opaque ``topoloc_describer`` (ABI 1.12)."""


DescriberPtr = POINTER(topoloc_describer)


class topoloc_keyframe_describer(Structure):
    """Opaque ``topoloc_keyframe_describer`` (ABI 1.15)."""


KeyframeDescriberPtr = POINTER(topoloc_keyframe_describer)


class topoloc_view_attributes(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("has_keyframe_id", c_bool),
        ("keyframe_id", c_uint64),
        ("world_T_camera", POINTER(c_double)),
        ("image", c_char_p),
    ]


class topoloc_keyframe_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("place_spacing_m", c_double),
        ("novelty_similarity", c_float),
        ("neighbour_radius_m", c_double),
        ("max_views_per_place", c_uint32),
    ]


class topoloc_keyframe(Structure):
    _fields_ = [
        ("id", c_uint64),
        ("descriptor", POINTER(c_float)),
        ("descriptor_len", c_size_t),
        ("world_T_camera", POINTER(c_double)),
    ]


class topoloc_image_map_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("backend", c_uint32),
        ("dim", c_uint32),
        ("views_per_place", c_uint32),
        ("threads", c_uint32),
        ("onnx_model_path", c_char_p),
        ("onnx_runtime_path", c_char_p),
        ("onnx_taps", c_char_p),
        ("grid_rows", c_uint32),
        ("grid_cols", c_uint32),
        ("vlad_clusters", c_uint32),
        ("vlad_dense", c_bool),
        ("poses_tum_path", c_char_p),
        ("place_spacing_m", c_double),
        ("pca_precision", c_uint32),  # ABI 1.14
        ("verification_keypoints", c_uint32),  # ABI 1.15
        ("local_features", c_uint32),
        ("xfeat_model_path", c_char_p),
    ]


#: ``topoloc_progress_fn``:
#: ``bool (*)(void *user_data, uint32_t stage, size_t done, size_t total)``.
topoloc_progress_fn = CFUNCTYPE(c_bool, c_void_p, c_uint32, c_size_t, c_size_t)
#: ``topoloc_log_fn`` (ABI 1.13): level, target, message, user_data.
topoloc_log_fn = CFUNCTYPE(None, c_uint32, c_char_p, c_char_p, c_void_p)


class topoloc_image(Structure):
    _fields_ = [
        ("data", POINTER(c_uint8)),
        ("data_len", c_size_t),
        ("width", c_uint32),
        ("height", c_uint32),
        ("stride", c_size_t),
        ("format", c_uint32),
    ]


class topoloc_localizer_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("mode", c_uint32),
        ("temperature", c_float),
        ("stay_probability", c_float),
        ("jump_probability", c_float),
        ("off_map_probability", c_float),
        ("off_map_similarity", c_float),
        ("off_map_margin", c_float),
        ("top_k", c_uint32),
        ("expected_descriptor_kind", c_char_p),
        ("expected_descriptor_model", c_char_p),
        ("image_backend", c_uint32),
        ("onnx_model_path", c_char_p),
        ("onnx_runtime_path", c_char_p),
        ("verify_candidates", c_uint32),
        ("verify_views_per_candidate", c_uint32),
        ("verify_inlier_weight", c_float),
        ("metric_particles", c_uint32),
        ("metric_temperature", c_float),
        ("metric_seed", c_uint64),
        ("camera_fx", c_double),
        ("camera_fy", c_double),
        ("camera_cx", c_double),
        ("camera_cy", c_double),
        ("pose_min_inliers", c_uint32),
        # ABI 1.9: off-map evidence from verification.
        ("verify_off_map_inliers", c_double),
        ("verify_off_map_inlier_scale", c_double),
        # ABI 1.16: the learned estimator.
        ("grnn_model_path", c_char_p),
    ]


class topoloc_frame(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("timestamp", c_double),
        ("descriptor", POINTER(c_float)),
        ("descriptor_len", c_size_t),
        ("odometry", POINTER(c_double)),
        ("image", topoloc_image),
    ]


class topoloc_candidate(Structure):
    _fields_ = [
        ("place", c_uint32),
        ("view", c_uint32),
        ("probability", c_float),
        ("similarity", c_float),
    ]


class topoloc_result(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("frame_index", c_uint64),
        ("place", c_uint32),
        ("view", c_uint32),
        ("confidence", c_float),
        ("similarity", c_float),
        ("off_map_probability", c_float),
        ("off_map", c_bool),
        ("candidates", POINTER(topoloc_candidate)),
        ("candidates_capacity", c_size_t),
        ("candidates_len", c_size_t),
        ("verified", c_bool),
        ("inliers", c_uint32),
        ("has_pose_fix", c_bool),
        ("pose_fix_view", c_uint32),
        ("pose_fix_inliers", c_uint32),
        ("world_T_camera", c_double * 16),
    ]


class topoloc_map_load_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("expected_descriptor_kind", c_char_p),
        ("expected_descriptor_model", c_char_p),
        ("expected_descriptor_dim", c_uint32),
    ]


class topoloc_view_info(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("place", c_uint32),
        ("has_keyframe_id", c_bool),
        ("keyframe_id", c_uint64),
        ("has_pose", c_bool),
        ("world_T_camera", c_double * 16),
    ]


class topoloc_skeleton_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("use_z_band", c_bool),
        ("z_min_m", c_double),
        ("z_max_m", c_double),
        ("min_clearance_m", c_double),
        ("merge_radius_m", c_double),
        ("max_edge_m", c_double),
        ("corner_angle_deg", c_double),
        ("corner_scale_m", c_double),
        ("min_spur_m", c_double),
    ]


class topoloc_loop_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("candidates", c_uint32),
        ("exclude_recent_ids", c_uint64),
        ("exclude_recent_s", c_double),
        ("min_inliers", c_uint32),
        ("consistent_keyframes", c_uint32),
        ("odometry_gate", c_bool),
        ("odometry_max_rotation_deg", c_double),
        ("odometry_max_translation_m", c_double),
        ("fx", c_double),
        ("fy", c_double),
        ("cx", c_double),
        ("cy", c_double),
        ("novelty_similarity", c_float),
        ("place_spacing_m", c_double),
        ("neighbour_radius_m", c_double),
        # ABI 1.6
        ("candidate_id_gap", c_uint64),
        # ABI 1.7
        ("odometry_max_translation_per_m", c_double),
        ("pose_reprojection_px", c_double),
        # ABI 1.8
        ("odometry_search_m", c_double),
        ("odometry_candidates", c_uint32),
        # ABI 1.15
        ("max_match_pace", c_double),
        ("match_pace_slack_s", c_double),
        # ABI 1.17
        ("refine_keyframes", c_uint32),
        ("pose_min_inliers", c_uint32),
        ("pair_estimator", c_uint32),
        ("pair_iterations", c_uint32),
        ("pair_min_cosine", c_float),
        ("cells_pair_estimator", c_uint32),
        ("cells_pair_iterations", c_uint32),
        ("cells_pair_min_cosine", c_float),
    ]


class topoloc_loop_keyframe(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("id", c_uint64),
        ("timestamp", c_double),
        ("descriptor", POINTER(c_float)),
        ("descriptor_len", c_size_t),
        ("world_T_body", POINTER(c_double)),
        ("body_T_camera", POINTER(c_double)),
        ("keypoint_count", c_size_t),
        ("keypoints", POINTER(c_float)),
        ("keypoint_descriptors", POINTER(c_uint8)),
        ("camera_points", POINTER(c_float)),
    ]


class topoloc_loop_hint(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("query_id", c_uint64),
        ("query_place", c_uint32),
        ("has_match", c_bool),
        ("accepted", c_bool),
        ("gate", c_uint32),
        ("matched_id", c_uint64),
        ("place", c_uint32),
        ("inliers", c_uint32),
        ("confidence", c_float),
        ("has_pose", c_bool),
        ("scale_known", c_bool),
        ("matched_T_query", c_double * 16),
        ("covariance", c_double * 36),
        # ABI 1.17
        ("translation", c_uint32),
    ]


class topoloc_loop_candidate(Structure):
    _fields_ = [
        ("keyframe_id", c_uint64),
        ("place", c_uint32),
        ("similarity", c_float),
    ]


class topoloc_keyframe_describer_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("local_features", c_uint32),
        ("backend", c_uint32),
        ("onnx_model_path", c_char_p),
        ("onnx_runtime_path", c_char_p),
        ("xfeat_model_path", c_char_p),
        ("xfeat_max_pixels", c_uint32),
        ("threads", c_uint32),
    ]


class topoloc_depth_image(Structure):
    _fields_ = [
        ("values", POINTER(c_uint16)),
        ("values_len", c_size_t),
        ("units_per_metre", c_double),
    ]


class topoloc_loop_candidate_check(Structure):
    _fields_ = [
        ("keyframe_id", c_uint64),
        ("place", c_uint32),
        ("similarity", c_float),
        ("inliers", c_uint32),
        ("confidence", c_float),
    ]


class topoloc_describer_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("backend", c_uint32),
        ("onnx_model_path", c_char_p),
        ("onnx_runtime_path", c_char_p),
        ("threads", c_uint32),
    ]


class topoloc_trajectory_options(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("alignment", c_uint32),
        ("max_diff_s", c_double),
        ("offset_s", c_double),
        ("rpe_delta", c_uint32),
    ]


class topoloc_error_stats(Structure):
    _fields_ = [
        ("rmse", c_double),
        ("mean", c_double),
        ("median", c_double),
        ("std", c_double),
        ("min", c_double),
        ("max", c_double),
    ]


class topoloc_trajectory_report(Structure):
    _fields_ = [
        ("struct_size", c_size_t),
        ("pairs", c_size_t),
        ("scale", c_double),
        ("alignment", c_double * 16),
        ("ate_m", topoloc_error_stats),
        ("are_deg", topoloc_error_stats),
        ("rpe_m", topoloc_error_stats),
        ("rpe_deg", topoloc_error_stats),
        ("estimate_length_m", c_double),
        ("reference_length_m", c_double),
        ("length_ratio", c_double),
    ]


#: Every struct of the header, by C name.
STRUCTS = {
    cls.__name__: cls
    for cls in (
        topoloc_view_attributes,
        topoloc_keyframe_options,
        topoloc_keyframe,
        topoloc_image_map_options,
        topoloc_image,
        topoloc_localizer_options,
        topoloc_frame,
        topoloc_candidate,
        topoloc_result,
        topoloc_map_load_options,
        topoloc_view_info,
        topoloc_skeleton_options,
        topoloc_describer_options,
        topoloc_keyframe_describer_options,
        topoloc_depth_image,
        topoloc_loop_candidate_check,
        topoloc_loop_options,
        topoloc_loop_keyframe,
        topoloc_loop_hint,
        topoloc_loop_candidate,
        topoloc_trajectory_options,
        topoloc_error_stats,
        topoloc_trajectory_report,
    )
}

#: Opaque handle types, by C name.
HANDLES = {
    cls.__name__: cls
    for cls in (
        topoloc_map,
        topoloc_map_builder,
        topoloc_localizer,
        topoloc_graph,
        topoloc_loop_detector,
        topoloc_describer,
        topoloc_keyframe_describer,
    )
}

# --------------------------------------------------------------------------------------------
# Function signatures: name -> (restype, argtypes), in header order
# --------------------------------------------------------------------------------------------

status_t = c_uint32
_p = POINTER

SIGNATURES = {
    "topoloc_map_builder_new": (status_t, [c_char_p, c_char_p, c_uint32, _p(BuilderPtr)]),
    "topoloc_map_builder_free": (None, [BuilderPtr]),
    "topoloc_map_builder_add_place": (status_t, [BuilderPtr, _p(c_double), _p(c_uint32)]),
    "topoloc_view_attributes_init": (status_t, [_p(topoloc_view_attributes), c_size_t]),
    "topoloc_map_builder_add_view": (
        status_t,
        [BuilderPtr, c_uint32, _p(c_float), c_size_t, _p(topoloc_view_attributes), _p(c_uint32)],
    ),
    "topoloc_map_builder_add_edge": (status_t, [BuilderPtr, c_uint32, c_uint32, c_float]),
    "topoloc_map_builder_build": (status_t, [BuilderPtr, _p(MapPtr)]),
    "topoloc_keyframe_options_init": (status_t, [_p(topoloc_keyframe_options), c_size_t]),
    "topoloc_map_from_keyframes": (
        status_t,
        [
            c_char_p,
            c_char_p,
            c_uint32,
            _p(topoloc_keyframe),
            c_size_t,
            _p(topoloc_keyframe_options),
            _p(MapPtr),
        ],
    ),
    "topoloc_image_map_options_init": (status_t, [_p(topoloc_image_map_options), c_size_t]),
    "topoloc_map_build_from_image_files": (
        status_t,
        [
            _p(c_char_p),
            c_size_t,
            _p(topoloc_image_map_options),
            topoloc_progress_fn,
            c_void_p,
            _p(MapPtr),
        ],
    ),
    "topoloc_map_build_from_images": (
        status_t,
        [
            _p(topoloc_image),
            c_size_t,
            _p(topoloc_image_map_options),
            topoloc_progress_fn,
            c_void_p,
            _p(MapPtr),
        ],
    ),
    "topoloc_localizer_options_init": (status_t, [_p(topoloc_localizer_options), c_size_t]),
    "topoloc_localizer_new": (status_t, [MapPtr, _p(topoloc_localizer_options), _p(LocalizerPtr)]),
    "topoloc_localizer_free": (None, [LocalizerPtr]),
    "topoloc_localizer_reset": (status_t, [LocalizerPtr]),
    "topoloc_frame_init": (status_t, [_p(topoloc_frame), c_size_t]),
    "topoloc_result_init": (status_t, [_p(topoloc_result), c_size_t]),
    "topoloc_localizer_process": (status_t, [LocalizerPtr, _p(topoloc_frame), _p(topoloc_result)]),
    "topoloc_map_load_options_init": (status_t, [_p(topoloc_map_load_options), c_size_t]),
    "topoloc_map_load": (status_t, [c_char_p, _p(topoloc_map_load_options), _p(MapPtr)]),
    "topoloc_map_load_from_memory": (
        status_t,
        [_p(c_uint8), c_size_t, _p(topoloc_map_load_options), _p(MapPtr)],
    ),
    "topoloc_map_save": (status_t, [MapPtr, c_char_p]),
    "topoloc_map_free": (None, [MapPtr]),
    "topoloc_map_place_count": (status_t, [MapPtr, _p(c_size_t)]),
    "topoloc_map_view_count": (status_t, [MapPtr, _p(c_size_t)]),
    "topoloc_map_edge_count": (status_t, [MapPtr, _p(c_size_t)]),
    "topoloc_map_descriptor_dim": (status_t, [MapPtr, _p(c_uint32)]),
    "topoloc_map_descriptor_kind": (status_t, [MapPtr, _p(c_char), c_size_t, _p(c_size_t)]),
    "topoloc_map_descriptor_model": (status_t, [MapPtr, _p(c_char), c_size_t, _p(c_size_t)]),
    "topoloc_map_neighbours": (status_t, [MapPtr, c_uint32, _p(c_uint32), c_size_t, _p(c_size_t)]),
    "topoloc_map_place_views": (status_t, [MapPtr, c_uint32, _p(c_uint32), c_size_t, _p(c_size_t)]),
    "topoloc_map_place_position": (status_t, [MapPtr, c_uint32, _p(c_double), _p(c_bool)]),
    "topoloc_map_edge": (status_t, [MapPtr, c_size_t, _p(c_uint32), _p(c_uint32), _p(c_float)]),
    "topoloc_view_info_init": (status_t, [_p(topoloc_view_info), c_size_t]),
    "topoloc_map_view_info": (status_t, [MapPtr, c_uint32, _p(topoloc_view_info)]),
    "topoloc_map_view_image": (status_t, [MapPtr, c_uint32, _p(c_char), c_size_t, _p(c_size_t)]),
    "topoloc_map_view_descriptor": (status_t, [MapPtr, c_uint32, _p(c_float), c_size_t]),
    # Map keypoints (ABI 1.6)
    "topoloc_map_keypoint_total": (status_t, [MapPtr, _p(c_size_t)]),
    "topoloc_map_view_keypoints": (
        status_t,
        [MapPtr, c_uint32, _p(c_float), c_size_t, _p(c_size_t)],
    ),
    "topoloc_map_with_keypoint_points": (status_t, [MapPtr, _p(c_float), c_size_t, _p(MapPtr)]),
    "topoloc_skeleton_options_init": (status_t, [_p(topoloc_skeleton_options), c_size_t]),
    "topoloc_graph_from_occupancy": (
        status_t,
        [
            _p(c_size_t),
            c_double,
            _p(c_double),
            _p(c_uint8),
            c_size_t,
            _p(topoloc_skeleton_options),
            _p(GraphPtr),
        ],
    ),
    "topoloc_graph_free": (None, [GraphPtr]),
    "topoloc_graph_place_count": (status_t, [GraphPtr, _p(c_size_t)]),
    "topoloc_graph_edge_count": (status_t, [GraphPtr, _p(c_size_t)]),
    "topoloc_graph_place": (status_t, [GraphPtr, c_uint32, _p(c_double), _p(c_uint32)]),
    "topoloc_graph_edge": (
        status_t,
        [GraphPtr, c_size_t, _p(c_uint32), _p(c_uint32), _p(c_double)],
    ),
    "topoloc_graph_skeleton": (status_t, [GraphPtr, _p(c_uint32), c_size_t, _p(c_size_t)]),
    # Describers (ABI 1.12)
    "topoloc_describer_options_init": (status_t, [_p(topoloc_describer_options), c_size_t]),
    "topoloc_describer_new": (status_t, [MapPtr, _p(topoloc_describer_options), _p(DescriberPtr)]),
    "topoloc_describer_free": (None, [DescriberPtr]),
    "topoloc_describer_dim": (status_t, [DescriberPtr, _p(c_size_t)]),
    "topoloc_describer_describe": (
        status_t,
        [DescriberPtr, _p(topoloc_image), _p(c_float), c_size_t, _p(c_size_t)],
    ),
    # Loop closure (ABI 1.5)
    "topoloc_loop_options_init": (status_t, [_p(topoloc_loop_options), c_size_t]),
    "topoloc_loop_detector_new": (
        status_t,
        [c_char_p, c_char_p, c_uint32, _p(topoloc_loop_options), _p(LoopDetectorPtr)],
    ),
    "topoloc_loop_detector_from_map": (
        status_t,
        [MapPtr, _p(topoloc_loop_options), _p(LoopDetectorPtr)],
    ),
    "topoloc_loop_detector_free": (None, [LoopDetectorPtr]),
    "topoloc_loop_keyframe_init": (status_t, [_p(topoloc_loop_keyframe), c_size_t]),
    "topoloc_loop_hint_init": (status_t, [_p(topoloc_loop_hint), c_size_t]),
    "topoloc_loop_detector_add": (
        status_t,
        [LoopDetectorPtr, _p(topoloc_loop_keyframe), _p(topoloc_loop_hint)],
    ),
    "topoloc_loop_detector_query": (
        status_t,
        [
            LoopDetectorPtr,
            _p(c_float),
            c_size_t,
            _p(topoloc_loop_candidate),
            c_size_t,
            _p(c_size_t),
        ],
    ),
    "topoloc_loop_detector_erase": (status_t, [LoopDetectorPtr, c_uint64]),
    "topoloc_loop_detector_begin_session": (status_t, [LoopDetectorPtr]),
    "topoloc_loop_detector_save": (status_t, [LoopDetectorPtr, c_char_p]),
    "topoloc_loop_detector_len": (status_t, [LoopDetectorPtr, _p(c_size_t)]),
    # ABI 1.17
    "topoloc_loop_detector_next_id": (status_t, [LoopDetectorPtr, _p(c_uint64)]),
    # Confirmed loop hints (ABI 1.10)
    "topoloc_loop_detector_confirmed_count": (status_t, [LoopDetectorPtr, _p(c_size_t)]),
    "topoloc_loop_detector_confirmed": (
        status_t,
        [LoopDetectorPtr, c_size_t, _p(topoloc_loop_hint)],
    ),
    # Image keyframes and ranked candidates (ABI 1.15)
    "topoloc_keyframe_describer_options_init": (
        status_t,
        [_p(topoloc_keyframe_describer_options), c_size_t],
    ),
    "topoloc_keyframe_describer_new": (
        status_t,
        [MapPtr, _p(topoloc_keyframe_describer_options), _p(KeyframeDescriberPtr)],
    ),
    "topoloc_keyframe_describer_free": (None, [KeyframeDescriberPtr]),
    "topoloc_keyframe_describer_local_features": (
        status_t,
        [KeyframeDescriberPtr, _p(c_uint32)],
    ),
    "topoloc_loop_detector_add_image": (
        status_t,
        [
            LoopDetectorPtr,
            KeyframeDescriberPtr,
            _p(topoloc_loop_keyframe),
            _p(topoloc_image),
            _p(topoloc_depth_image),
            _p(topoloc_loop_hint),
        ],
    ),
    "topoloc_loop_detector_candidates": (
        status_t,
        [LoopDetectorPtr, _p(topoloc_loop_candidate_check), c_size_t, _p(c_size_t)],
    ),
    # Trajectory metrics (ABI 1.11)
    "topoloc_trajectory_options_init": (status_t, [_p(topoloc_trajectory_options), c_size_t]),
    "topoloc_trajectory_report_init": (status_t, [_p(topoloc_trajectory_report), c_size_t]),
    "topoloc_trajectory_evaluate": (
        status_t,
        [
            _p(c_double),
            _p(c_double),
            c_size_t,
            _p(c_double),
            _p(c_double),
            c_size_t,
            _p(topoloc_trajectory_options),
            _p(topoloc_trajectory_report),
        ],
    ),
    "topoloc_trajectory_evaluate_files": (
        status_t,
        [
            c_char_p,
            c_char_p,
            c_uint32,
            _p(topoloc_trajectory_options),
            _p(topoloc_trajectory_report),
        ],
    ),
    "topoloc_version": (c_char_p, []),
    "topoloc_abi_version": (c_uint32, []),
    "topoloc_abi_version_minor": (c_uint32, []),
    "topoloc_status_str": (c_char_p, [c_uint32]),
    "topoloc_status_name": (c_char_p, [c_uint32]),
    "topoloc_last_error_message": (status_t, [_p(c_char), c_size_t, _p(c_size_t)]),
    "topoloc_set_log_callback": (status_t, [topoloc_log_fn, c_uint32, c_void_p]),
}

# --------------------------------------------------------------------------------------------
# Finding and loading the library
# --------------------------------------------------------------------------------------------

_PACKAGE_DIR = Path(__file__).resolve().parent


def _library_file_names() -> Tuple[str, List[str]]:
    """(file name built by cargo, glob patterns for copies placed next to the package)."""
    if sys.platform == "darwin":
        return "libtopoloc.dylib", ["libtopoloc*.dylib"]
    if sys.platform == "win32":
        return "topoloc.dll", ["topoloc*.dll"]
    return "libtopoloc.so", ["libtopoloc.so*"]


def _find_checkout_root(start: Path) -> Optional[Path]:
    for directory in [start, *start.parents]:
        if (directory / "Cargo.toml").is_file():
            return directory
    return None


def candidate_locations(
    environ: Optional[Mapping[str, str]] = None,
    package_dir: Optional[Path] = None,
    use_system: bool = True,
) -> List[Tuple[str, str]]:
    """Ordered ``(kind, location)`` pairs to try; ``kind`` is ``"env"``, ``"package"``,
    ``"checkout"`` or ``"system"``. Locations that do not exist are included (so that an error
    can list them), except for the system search, which is only listed when it finds something.
    """
    environ = os.environ if environ is None else environ
    package_dir = _PACKAGE_DIR if package_dir is None else Path(package_dir)
    cargo_name, patterns = _library_file_names()
    out: List[Tuple[str, str]] = []

    env_path = environ.get(ENV_VAR)
    if env_path:
        # Absolute, so that a bare file name means "this file here", not a dlopen search.
        return [("env", os.path.abspath(os.path.expanduser(env_path)))]

    found_next_to_package = sorted(
        {str(p) for pattern in patterns for p in package_dir.glob(pattern)}
    )
    if found_next_to_package:
        # Prefer the unversioned name, then the shortest (libtopoloc.so before libtopoloc.so.0.1.0).
        found_next_to_package.sort(key=lambda p: (len(p), p))
        out.extend(("package", p) for p in found_next_to_package)
    else:
        out.append(("package", str(package_dir / patterns[0])))

    root = _find_checkout_root(package_dir)
    target_dirs: List[Path] = []
    if environ.get("CARGO_TARGET_DIR"):
        target_dirs.append(Path(environ["CARGO_TARGET_DIR"]))
    if root is not None:
        target_dirs.append(root / "target")
    for target in target_dirs:
        out.append(("checkout", str(target / "release" / cargo_name)))
    if root is None and not target_dirs:
        out.append(("checkout", f"(no Cargo.toml above {package_dir}: not a source checkout)"))

    if use_system:
        name = ctypes.util.find_library("topoloc")
        out.append(
            ("system", name if name else "ctypes.util.find_library('topoloc') found nothing")
        )
    return out


def _check_abi(lib: ctypes.CDLL, path: str, expected: int = ABI_VERSION) -> None:
    """Raises :class:`AbiVersionError` unless the library's ABI version is ``expected``."""
    fn = lib.topoloc_abi_version
    fn.restype = c_uint32
    fn.argtypes = []
    found = int(fn())
    if found != expected:
        raise AbiVersionError(
            f"the topoloc library at {path} implements C ABI version {found}, but these Python "
            f"bindings were written for ABI version {expected}; install bindings matching the "
            f"library (or point {ENV_VAR} at a matching library)",
            found=found,
            expected=expected,
            path=path,
        )


def _declare(lib: ctypes.CDLL) -> None:
    for name, (restype, argtypes) in SIGNATURES.items():
        fn = getattr(lib, name)  # AttributeError: a function of the header is missing
        fn.restype = restype
        fn.argtypes = argtypes


def load_library(
    environ: Optional[Mapping[str, str]] = None,
    package_dir: Optional[Path] = None,
    use_system: bool = True,
) -> Tuple[ctypes.CDLL, str]:
    """Finds, loads and checks the library; returns ``(CDLL, location)``.

    Raises :class:`LibraryNotFoundError` listing every location tried, or
    :class:`AbiVersionError`.
    """
    tried: List[Tuple[str, str]] = []
    candidates = candidate_locations(environ, package_dir, use_system)
    for kind, location in candidates:
        if kind != "system" and not Path(location).is_file():
            tried.append((location, "not found"))
            continue
        if kind == "system" and location.startswith("ctypes.util"):
            tried.append(("system library search", "nothing found"))
            continue
        try:
            lib = ctypes.CDLL(location)
        except OSError as e:
            tried.append((location, f"failed to load: {e}"))
            continue
        if not hasattr(lib, "topoloc_abi_version"):
            tried.append((location, "loaded, but it has no topoloc_abi_version: not libtopoloc"))
            continue
        _check_abi(lib, location)
        try:
            _declare(lib)
        except AttributeError as e:
            raise LibraryNotFoundError(
                f"the topoloc library at {location} lacks a function of the C header ({e}); it is "
                "older than these bindings: rebuild it with `cargo build --release --lib`",
                [*tried, (location, "missing functions")],
            ) from None
        return lib, location

    lines = "\n".join(f"  - {loc}: {why}" for loc, why in tried)
    env_hint = ""
    if candidates and candidates[0][0] == "env":
        env_hint = f"{ENV_VAR} is set, so no other location was searched. "
    raise LibraryNotFoundError(
        "could not load the topoloc shared library. Tried, in order:\n"
        f"{lines}\n"
        f"{env_hint}Fix: build it with `cargo build --release --lib` in the topoloc repository "
        f"(giving target/release/{_library_file_names()[0]}), copy it next to the topoloc package, "
        f"or set {ENV_VAR}=/path/to/{_library_file_names()[0]}.",
        tried,
    )


lib, library_path = load_library()
