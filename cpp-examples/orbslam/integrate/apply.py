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

import argparse
import hashlib
import os
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
# Build outputs and version control, wherever they are (upstream has no sources in such folders).
SKIPPED_DIRS = {".git", "build", "lib"}


@dataclass(frozen=True)
class Edit:
    """Inserts `text` before or after each line that contains `anchor`, or replaces `anchor`
    inside those lines. `after` first narrows the search to the lines following the first line
    that contains it. `count` is how many lines must contain the anchor."""

    path: str
    anchor: str
    text: str
    where: str  # "before", "after" or "replace"
    count: int = 1
    after: str | None = None


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


class AnchorError(Exception):
    pass


def apply_edit(text: str, edit: Edit) -> str:
    lines = text.splitlines(keepends=True)
    start = 0
    if edit.after is not None:
        starts = [i for i, line in enumerate(lines) if edit.after in line]
        if not starts:
            raise AnchorError(f"{edit.path}: no line contains {edit.after!r}")
        start = starts[0] + 1
    hits = [i for i in range(start, len(lines)) if edit.anchor in lines[i]]
    if edit.after is not None:
        hits = hits[:1]  # the first one after the narrowing line
    if len(hits) != edit.count:
        raise AnchorError(
            f"{edit.path}: {len(hits)} lines contain {edit.anchor!r}, expected {edit.count}"
            " (is this ORB-SLAM3 v1.0?)"
        )
    for i in reversed(hits):
        if edit.where == "replace":
            lines[i] = lines[i].replace(edit.anchor, edit.text)
        elif edit.where == "before":
            lines[i:i] = [edit.text]
        elif edit.where == "after":
            lines[i + 1 : i + 1] = [edit.text]
        else:
            raise ValueError(edit.where)
    return "".join(lines)


def edits_for(variant: str) -> list[Edit]:
    edits = RECIPE + BENCH
    return edits + TOPOLOC if variant == "topoloc" else edits


def desired_files(upstream: Path, variant: str) -> dict[str, bytes]:
    """The content of every file of OUT whose content differs from upstream's."""
    edits = edits_for(variant)
    out: dict[str, bytes] = {}
    for edit in edits:
        path = upstream / edit.path
        if not path.is_file():
            raise AnchorError(f"{edit.path}: not in {upstream} (is this ORB-SLAM3 v1.0?)")
        if edit.path not in out:
            out[edit.path] = path.read_bytes()
        text = out[edit.path].decode("utf-8", errors="surrogateescape")
        out[edit.path] = apply_edit(text, edit).encode("utf-8", errors="surrogateescape")
    if variant == "topoloc":
        for rel, source in REPLACED.items():
            if not (upstream / rel).is_file():
                raise AnchorError(f"{rel}: not in {upstream} (is this ORB-SLAM3 v1.0?)")
            out[rel] = source.read_bytes()
    return out


def write_if_changed(path: Path, content: bytes, mode: int | None = None) -> bool:
    if path.is_file() and path.read_bytes() == content:
        return False
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".topoloc-tmp")
    tmp.write_bytes(content)
    if mode is not None:
        os.chmod(tmp, mode)
    os.replace(tmp, path)
    return True


def lay_out(upstream: Path, out: Path, changed: dict[str, bytes]) -> int:
    """Writes OUT: upstream's files, those of `changed` with their new content."""
    written = 0
    for root, dirs, files in os.walk(upstream):
        rel_root = Path(root).relative_to(upstream)
        dirs[:] = [d for d in dirs if d not in SKIPPED_DIRS]
        for name in files:
            rel = (rel_root / name).as_posix()
            source = upstream / rel
            if source.is_symlink():
                continue
            content = changed.get(rel)
            if content is None:
                content = source.read_bytes()
            written += write_if_changed(out / rel, content, source.stat().st_mode & 0o777)
    return written


def fingerprint(variant: str, changed: dict[str, bytes]) -> str:
    digest = hashlib.sha256(variant.encode())
    for rel, content in sorted(changed.items()):
        digest.update(rel.encode() + b"\0" + content)
    return digest.hexdigest()[:16]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("upstream", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--variant", choices=["stock", "topoloc"], required=True)
    args = parser.parse_args()
    upstream = args.upstream.resolve()
    if not (upstream / "include" / "KeyFrameDatabase.h").is_file():
        print(
            f"apply.py: {upstream} is not an ORB-SLAM3 checkout (no include/KeyFrameDatabase.h)",
            file=sys.stderr,
        )
        return 2
    if args.out.resolve() == upstream:
        print(
            "apply.py: OUT must differ from UPSTREAM (the checkout is never modified)",
            file=sys.stderr,
        )
        return 2
    try:
        changed = desired_files(upstream, args.variant)  # raises before OUT is touched
        written = lay_out(upstream, args.out, changed)
    except AnchorError as e:
        print(f"apply.py: {e}", file=sys.stderr)
        return 2
    print(
        f"apply.py: {args.variant} tree in {args.out}: {written} files written "
        f"(edits {fingerprint(args.variant, changed)})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
