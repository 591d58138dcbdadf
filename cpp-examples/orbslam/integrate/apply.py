#!/usr/bin/env python3
"""Lays out an ORB-SLAM3 v1.0 tree with topoloc's keyframe database (or a stock one for the
baseline), from an upstream checkout that it never modifies.

    apply.py UPSTREAM OUT --variant stock|topoloc

UPSTREAM  an ORB-SLAM3 v1.0 checkout (github.com/UZ-SLAMLab/ORB_SLAM3, tag v1.0)
OUT       the tree to build; created, or brought up to date in place
--variant stock: the build recipe and the benchmark's log lines only (the baseline);
          topoloc: the same plus the integration of ../README.md

Every edit names an anchor, a short line of the upstream code, and the number of times it
must occur; a tree where an anchor is missing or occurs a different number of times is
refused (exit status 2) with the file and the anchor, and OUT is left as it was. Files are
written only when their content changes, so a second run rebuilds nothing.

The edits (no upstream code is copied here beyond the anchors):
- recipe (both variants): C++14 instead of C++11 (Pangolin 0.8's headers need it); the
  settings print skips the second camera's calibration of rectified stereo (v1.0 reads an
  unset pointer there); the examples run without the viewer (headless).
- bench (both variants): one log line per keyframe with the time place recognition took, and
  one per loop or merge with the two keyframes' timestamps (run.sh parses them).
- topoloc: the grey image kept on Frame and KeyFrame; topoloc's KeyFrameDatabase (the files of
  orbslam3/); the database built from the settings file; its Save/Load beside a saved atlas;
  System::Shutdown waits for the local mapping and loop closing threads, then shuts topoloc
  down; the CMake lines (C++17 for the database's source, topoloc's package).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "common"))
from anchored_edits import (  # noqa: E402  (the shared module sits beside the examples)
    Edit,
    Integration,
    main,
)

UPSTREAM_NAME = "ORB-SLAM3 v1.0"


BENCH_INCLUDE = "#include <chrono>  // topoloc bench\n#include <string>  // topoloc bench\n"


def bench_line(kind: str, current: str, matched: str) -> str:
    return (
        f'                        std::cout << "[topoloc-bench] {kind} " << std::to_string({current}->mTimeStamp)'
        f" << ' ' << std::to_string({matched}->mTimeStamp) << std::endl;  // topoloc bench\n"
    )


RECIPE = [
    Edit(
        "CMakeLists.txt",
        '"${CMAKE_CXX_FLAGS} -std=c++11"',
        '"${CMAKE_CXX_FLAGS} -std=c++14"',
        "replace",
    ),
    Edit(
        "src/Settings.cc",
        "for(size_t i = 0; i < settings.originalCalib2_->size(); i++){",
        "for(size_t i = 0; settings.cameraType_ != Settings::Rectified && i < settings.originalCalib2_->size(); i++){",
        "replace",
    ),
    Edit(
        "Examples/Monocular/mono_kitti.cc",
        "ORB_SLAM3::System::MONOCULAR,true);",
        "ORB_SLAM3::System::MONOCULAR,false);",
        "replace",
    ),
    Edit(
        "Examples/RGB-D/rgbd_tum.cc",
        "ORB_SLAM3::System::RGBD,true);",
        "ORB_SLAM3::System::RGBD,false);",
        "replace",
    ),
]

BENCH = [
    Edit("src/LoopClosing.cc", '#include "LoopClosing.h"', BENCH_INCLUDE, "after"),
    Edit(
        "src/LoopClosing.cc",
        "bool bFindedRegion = NewDetectCommonRegions();",
        "            const auto topolocBenchStart = std::chrono::steady_clock::now();  // topoloc bench\n",
        "before",
    ),
    Edit(
        "src/LoopClosing.cc",
        "bool bFindedRegion = NewDetectCommonRegions();",
        '            std::cout << "[topoloc-bench] place-recognition-ms " << std::chrono::duration<double, '
        "std::milli>(std::chrono::steady_clock::now() - topolocBenchStart).count() << std::endl;  // topoloc bench\n",
        "after",
    ),
    Edit(
        "src/LoopClosing.cc",
        'Verbose::PrintMess("*Merge detected", Verbose::VERBOSITY_QUIET);',
        bench_line("merge", "mpCurrentKF", "mpMergeMatchedKF"),
        "after",
    ),
    Edit(
        "src/LoopClosing.cc",
        'Verbose::PrintMess("*Loop detected", Verbose::VERBOSITY_QUIET);',
        bench_line("loop", "mpCurrentKF", "mpLoopMatchedKF"),
        "after",
    ),
]

TOPOLOC = [
    Edit(
        "include/Frame.h",
        "public:",
        "    cv::Mat mImGray;  // grey image, for topoloc's keyframe database\n",
        "after",
        after="class Frame",
    ),
    Edit(
        "include/KeyFrame.h",
        "public:",
        "    cv::Mat mImGray;  // grey image, for topoloc's keyframe database\n",
        "after",
        after="class KeyFrame",
    ),
    Edit(
        "src/Frame.cc",
        "{",
        "    mImGray = frame.mImGray;  // topoloc\n",
        "after",
        after="Frame::Frame(const Frame &frame)",
    ),
    Edit(
        "src/KeyFrame.cc",
        "{",
        "    mImGray = F.mImGray;  // topoloc\n",
        "after",
        after="KeyFrame::KeyFrame(Frame &F, Map *pMap, KeyFrameDatabase *pKFDB)",
    ),
    Edit(
        "src/Tracking.cc",
        "mCurrentFrame.mNameFile = filename;",
        "    mCurrentFrame.mImGray = mImGray.clone();  // topoloc\n",
        "before",
        count=3,
    ),
    Edit(
        "src/System.cc",
        "new KeyFrameDatabase(*mpVocabulary);",
        "new KeyFrameDatabase(strSettingsFile);",
        "replace",
        count=3,
    ),
    Edit(
        "src/System.cc",
        'pathSaveFileName = pathSaveFileName.append(".osa");',
        '        mpKeyFrameDatabase->Save(pathSaveFileName + ".topoloc");  // topoloc\n',
        "after",
    ),
    Edit(
        "src/System.cc",
        "mpAtlas->PostLoad();",
        '        mpKeyFrameDatabase->Load(pathLoadFileName + ".topoloc");  // topoloc\n',
        "before",
    ),
    Edit(
        "src/System.cc",
        "mpLoopCloser->RequestFinish();",
        "    while(!mpLocalMapper->isFinished() || !mpLoopCloser->isFinished())  // topoloc\n"
        "        usleep(5000);  // topoloc\n",
        "after",
        after="void System::Shutdown()",
    ),
    Edit(
        "src/System.cc",
        "#ifdef REGISTER_TIMES",
        "    mpKeyFrameDatabase->Shutdown();  // topoloc\n\n",
        "before",
        after="SaveAtlas(FileType::BINARY_FILE);",
    ),
    Edit(
        "CMakeLists.txt",
        "# Build examples",
        "# topoloc's keyframe database (topoloc's cpp-examples/orbslam/integrate)\n"
        "find_package(Topoloc CONFIG REQUIRED)\n"
        "target_include_directories(${PROJECT_NAME} PRIVATE ${TOPOLOC_ORBSLAM_DIR})\n"
        "set_source_files_properties(src/KeyFrameDatabase.cc PROPERTIES COMPILE_FLAGS -std=c++17)\n"
        "target_link_libraries(${PROJECT_NAME} Topoloc::topoloc)\n"
        "if(TOPOLOC_ORBSLAM_ASAN)  # integrate.sh --asan: the C++17 database under AddressSanitizer\n"
        "  set_source_files_properties(src/KeyFrameDatabase.cc PROPERTIES COMPILE_FLAGS\n"
        '    "-std=c++17 -fsanitize=address -fno-omit-frame-pointer")\n'
        "  target_link_options(${PROJECT_NAME} PUBLIC -fsanitize=address)\n"
        "endif()\n\n",
        "before",
    ),
]

# Files of OUT replaced by topoloc's (relative path in OUT -> file of this folder).
REPLACED = {
    "include/KeyFrameDatabase.h": HERE / "orbslam3" / "KeyFrameDatabase.h",
    "src/KeyFrameDatabase.cc": HERE / "orbslam3" / "KeyFrameDatabase.cc",
}


def edits_for(variant: str) -> list[Edit]:
    edits = RECIPE + BENCH
    return edits + TOPOLOC if variant == "topoloc" else edits


INTEGRATION = Integration(
    upstream_name=UPSTREAM_NAME,
    marker="include/KeyFrameDatabase.h",
    edits={variant: edits_for(variant) for variant in ("stock", "topoloc")},
    replaced={"topoloc": REPLACED},
    added={},
)


if __name__ == "__main__":
    sys.exit(main(INTEGRATION, __doc__.split("\n\n")[0]))
