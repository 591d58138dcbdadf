#!/usr/bin/env python3
"""Lays out a VINS-Fusion tree whose loop_fusion uses topoloc's loop detector (or a stock one
for the baseline), from an upstream checkout that it never modifies.

    apply.py UPSTREAM OUT --variant stock|topoloc

UPSTREAM  a VINS-Fusion checkout (github.com/HKUST-Aerial-Robotics/VINS-Fusion, master be55a93)
OUT       the tree to build (a catkin workspace's src/); created, or brought up to date in place
--variant stock: the build recipe and the benchmark's log lines only (the baseline);
          topoloc: the same plus the integration of ../README.md

Every edit names an anchor, a short line of the upstream code, and the number of times it must
occur; a tree that does not match is refused (exit status 2) with the file and the anchor, and
OUT is left as it was (see ../../common/anchored_edits.py). Files are written only when their
content changes, so a second run rebuilds nothing.

The edits (no upstream code is copied here beyond the anchors):
- recipe (both variants): C++17 instead of C++11 in camera_models and loop_fusion (Ceres 2.1
  and topoloc's header need it); OpenCV's C constants, gone from OpenCV 4's C++ headers,
  renamed to their C++ names.
- bench (both variants): per keyframe, one log line with the time loop detection and
  verification took; one per loop with the two keyframe indices (run.sh parses them).
- topoloc: the DBoW2 database and `findConnection` replaced by `TopolocLoop` (loop_fusion/
  topoloc_loop.{h,cpp} and the adapter, copied into src/), the detector made from the config's
  `topoloc_map`, the estimated extrinsics passed on, the keyframe image kept until loop
  detection, the loops topoloc confirms on earlier keyframes recorded with the current one;
  the CMake lines (topoloc's package, the new source).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
COMMON = HERE.parent.parent / "common"
sys.path.insert(0, str(COMMON))
from anchored_edits import (  # noqa: E402  (the shared module sits beside the examples)
    Edit,
    Integration,
    main,
)

UPSTREAM_NAME = "VINS-Fusion master be55a93"
ADD_KEYFRAME = "void PoseGraph::addKeyFrame(KeyFrame* cur_kf, bool flag_detect_loop)"
CHESSBOARD = "camera_models/src/chessboard/Chessboard.cc"

# OpenCV C constant -> its C++ name, with the files and the number of lines that use it.
OPENCV_RENAMES = [
    ("camera_models/src/calib/CameraCalibration.cc", "CV_AA", "cv::LINE_AA", 3),
    ("camera_models/src/calib/CameraCalibration.cc", "CV_GRAY2RGB", "cv::COLOR_GRAY2RGB", 1),
    ("camera_models/src/intrinsic_calib.cc", "CV_AA", "cv::LINE_AA", 1),
    (CHESSBOARD, "CV_GRAY2BGR", "cv::COLOR_GRAY2BGR", 1),
    (CHESSBOARD, "CV_BGR2GRAY", "cv::COLOR_BGR2GRAY", 2),
    (CHESSBOARD, "CV_CALIB_CB_ADAPTIVE_THRESH", "cv::CALIB_CB_ADAPTIVE_THRESH", 2),
    (CHESSBOARD, "CV_CALIB_CB_FAST_CHECK", "cv::CALIB_CB_FAST_CHECK", 2),
    (CHESSBOARD, "CV_CALIB_CB_FILTER_QUADS", "cv::CALIB_CB_FILTER_QUADS", 2),
    (CHESSBOARD, "CV_CALIB_CB_NORMALIZE_IMAGE", "cv::CALIB_CB_NORMALIZE_IMAGE", 3),
    (CHESSBOARD, "CV_ADAPTIVE_THRESH_MEAN_C", "cv::ADAPTIVE_THRESH_MEAN_C", 1),
    # Also turns CV_THRESH_BINARY_INV into cv::THRESH_BINARY_INV.
    (CHESSBOARD, "CV_THRESH_BINARY", "cv::THRESH_BINARY", 4),
    (CHESSBOARD, "CV_SHAPE_CROSS", "cv::MORPH_CROSS", 1),
    (CHESSBOARD, "CV_SHAPE_RECT", "cv::MORPH_RECT", 1),
    (CHESSBOARD, "CV_RGB(255,255,255)", "cv::Scalar(255,255,255)", 1),
    (CHESSBOARD, "CV_TERMCRIT_EPS", "cv::TermCriteria::EPS", 1),
    (CHESSBOARD, "CV_TERMCRIT_ITER", "cv::TermCriteria::MAX_ITER", 1),
    (CHESSBOARD, "CV_RETR_CCOMP", "cv::RETR_CCOMP", 3),
    (CHESSBOARD, "CV_CHAIN_APPROX_SIMPLE", "cv::CHAIN_APPROX_SIMPLE", 3),
    ("loop_fusion/src/ThirdParty/DVision/BRIEF.cpp", "CV_RGB2GRAY", "cv::COLOR_RGB2GRAY", 1),
    ("loop_fusion/src/keyframe.cpp", "CV_GRAY2RGB", "cv::COLOR_GRAY2RGB", 4),
    ("loop_fusion/src/keyframe.cpp", "CV_FONT_HERSHEY_SIMPLEX", "cv::FONT_HERSHEY_SIMPLEX", 2),
    ("loop_fusion/src/pose_graph.cpp", "CV_FONT_HERSHEY_SIMPLEX", "cv::FONT_HERSHEY_SIMPLEX", 5),
]

RECIPE = [
    Edit(f"{package}/CMakeLists.txt", '"-std=c++11"', '"-std=c++17"', "replace")
    for package in ("camera_models", "loop_fusion")
] + [Edit(path, old, new, "replace", count) for path, old, new, count in OPENCV_RENAMES]

BENCH = [
    Edit(
        "loop_fusion/src/pose_graph.cpp",
        "int loop_index = -1;",
        "    TicToc topoloc_bench_t;  // topoloc bench\n",
        "before",
        after=ADD_KEYFRAME,
    ),
    Edit(
        "loop_fusion/src/pose_graph.cpp",
        "\tm_keyframelist.lock();",
        '    printf("[topoloc-bench] loop-detection-ms %f\\n", topoloc_bench_t.toc());'
        "  // topoloc bench\n",
        "before",
        after=ADD_KEYFRAME,
    ),
]

STOCK_BENCH = [
    Edit(
        "loop_fusion/src/pose_graph.cpp",
        "earliest_loop_index = loop_index;",
        '            printf("[topoloc-bench] loop %d %d\\n", cur_kf->index, loop_index);'
        "  // topoloc bench\n",
        "after",
        after=ADD_KEYFRAME,
    ),
]

GRAPH = "loop_fusion/src/pose_graph.cpp"
TOPOLOC = [
    Edit(
        "loop_fusion/src/pose_graph.h",
        '#include "keyframe.h"',
        '#include "topoloc_loop.h"  // topoloc\n',
        "after",
    ),
    Edit(
        "loop_fusion/src/pose_graph.h",
        "BriefVocabulary* voc;",
        "\tstd::unique_ptr<topoloc_vins::LoopDetector> loops;  // topoloc\n"
        "\tfriend struct TopolocLoop;  // topoloc\n",
        "after",
    ),
    Edit(
        GRAPH,
        "voc = new BriefVocabulary(voc_path);",
        "TopolocLoop::load(*this, voc_path);",
        "replace",
    ),
    Edit(GRAPH, "db.setVocabulary(*voc, false, 0);", "// topoloc: no DBoW2 database", "replace"),
    # addKeyFrame and loadKeyFrame (a reloaded pose graph's keyframes have no image: topoloc
    # refuses them with a log line).
    Edit(
        GRAPH,
        "detectLoop(cur_kf, cur_kf->index);",
        "TopolocLoop::detect(*this, cur_kf);",
        "replace",
        2,
    ),
    Edit(GRAPH, "addKeyFrameIntoVoc(cur_kf);", "TopolocLoop::detect(*this, cur_kf);", "replace", 2),
    Edit(
        GRAPH,
        "cur_kf->findConnection(old_kf)",
        "TopolocLoop::connect(*this, cur_kf, loop_index)",
        "replace",
        2,
    ),
    Edit(
        GRAPH,
        "optimize_buf.push(cur_kf->index);",
        "// topoloc: TopolocLoop::record queues the optimisation",
        "replace",
        2,
    ),
    Edit(
        GRAPH,
        "\tm_keyframelist.lock();",
        "    TopolocLoop::record(*this, cur_kf, loop_index);  // topoloc\n",
        "before",
        after=ADD_KEYFRAME,
    ),
    Edit(
        "loop_fusion/src/keyframe.cpp",
        "image.release();",
        "(void)0;  // topoloc: released after loop detection (TopolocLoop::detect)",
        "replace",
        after="computeBRIEFPoint();",
    ),
    Edit(
        "loop_fusion/src/pose_graph_node.cpp",
        'pkg_path + "/../support_files/brief_k10L6.bin"',
        '(std::string)fsSettings["topoloc_map"]',
        "replace",
    ),
    Edit(
        "loop_fusion/src/pose_graph_node.cpp",
        "pose_msg->pose.pose.orientation.z).toRotationMatrix();",
        "    TopolocLoop::set_extrinsics(posegraph, tic, qic);  // topoloc\n",
        "after",
        after="void extrinsic_callback(",
    ),
    Edit(
        "loop_fusion/CMakeLists.txt",
        "add_executable(loop_fusion_node",
        "# topoloc's loop detector (topoloc's cpp-examples/vins/integrate)\n"
        "find_package(Topoloc CONFIG REQUIRED)\n",
        "before",
    ),
    Edit(
        "loop_fusion/CMakeLists.txt",
        "src/ThirdParty/VocabularyBinary.cpp",
        "    src/topoloc_loop.cpp\n",
        "after",
    ),
    Edit(
        "loop_fusion/CMakeLists.txt",
        "${CERES_LIBRARIES})",
        "${CERES_LIBRARIES} Topoloc::topoloc)",
        "replace",
    ),
]

# Our files added to OUT (path in OUT -> file of this repository).
ADDED = {
    "loop_fusion/src/topoloc_loop.h": HERE / "loop_fusion" / "topoloc_loop.h",
    "loop_fusion/src/topoloc_loop.cpp": HERE / "loop_fusion" / "topoloc_loop.cpp",
    "loop_fusion/src/topoloc/vins/topoloc_vins.hpp": HERE.parent / "topoloc_vins.hpp",
    "loop_fusion/src/topoloc/common/adapter_support.hpp": COMMON / "adapter_support.hpp",
}


def edits_for(variant: str) -> list[Edit]:
    return RECIPE + BENCH + (TOPOLOC if variant == "topoloc" else STOCK_BENCH)


INTEGRATION = Integration(
    upstream_name=UPSTREAM_NAME,
    marker="loop_fusion/src/pose_graph.cpp",
    edits={variant: edits_for(variant) for variant in ("stock", "topoloc")},
    replaced={},
    added={"topoloc": ADDED},
)


if __name__ == "__main__":
    sys.exit(main(INTEGRATION, __doc__.split("\n\n")[0]))
