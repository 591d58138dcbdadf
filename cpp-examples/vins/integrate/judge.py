#!/usr/bin/python3
"""Judges a loop_fusion_node run fed by driver.py against the sequences' ground truth.

    judge.py --driver-out DIR (--pose-graph FILE | --vio-loop FILE) [--log FILE]
             [--exit-code N] [--json OUT]

--driver-out: driver.py's truth-K.txt and odometry-K.txt (TUM, published stamps). --pose-graph:
loop_fusion's pose_graph.txt (PoseGraph::savePoseGraph, one keyframe a line: index, time_stamp,
VIO x y z, PG x y z, VIO qw qx qy qz, PG qw qx qy qz, loop_index, loop_info[8], keypoints);
--vio-loop: its vio_loop.csv instead (stamp_ns,x,y,z,qw,qx,qy,qz: the PG poses only; row i is
keyframe i, which holds when no previous pose graph was loaded). Keyframes are matched to the
ground truth by stamp.

Reported: keyframes per sequence; loops, from the log's `[topoloc-bench] loop CUR OLD` lines
(global keyframe indices) and from the pose graph's loop_index column (loops that passed
findConnection and reached the optimisation), false when the two keyframes' true positions are
more than 3 m apart or their true yaws more than 30 deg apart, cross-sequence when they belong to
different sequences; ATE RMSE (m, SE(3) Umeyama, no scale: `topoloc.evaluate_trajectory`) of the odometry (at the keyframes and
at every published frame) and of the pose graph per sequence, and of the pose graph over all
sequences with one alignment (low only if the sequences were merged into one frame; the
odometry's joint figure is the unmerged reference); the median and p90 of
`[topoloc-bench] loop-detection-ms`; whether an assertion fired or the node crashed.
"""

from __future__ import annotations

import argparse
import bisect
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "python"))
import topoloc  # noqa: E402  (this checkout's package; TOPOLOC_LIBRARY names libtopoloc.so)

MAX_LOOP_DISTANCE_M = 3.0
MAX_LOOP_YAW_DEG = 30.0
STAMP_TOLERANCE_S = 1e-3
# loop_fusion's 's' command saves the pose graph, prints this and returns from main with its
# threads still running: "terminate called without an active exception", exit status 134
# (SIGABRT). That is upstream's normal end; a crash is a marker before it or another status.
SHUTDOWN_MARKER = "program shutting down..."
UPSTREAM_EXIT = (134, "terminate called without an active exception")
CRASH_MARKERS = (
    "Segmentation fault",
    "core dumped",
    "Aborted",
    "terminate called",
    "ROS_BREAK",
)


Point = tuple[float, float, float]


class Pose(NamedTuple):
    stamp: float
    position: Point
    yaw: float  # radians


@dataclass(frozen=True)
class Keyframe:
    index: int
    stamp: float
    vio: Point
    pg: Point
    loop_index: int


def yaw_of(qx: float, qy: float, qz: float, qw: float) -> float:
    return math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def read_tum(path: Path) -> list[Pose]:
    poses = []
    for line in path.read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            v = [float(x) for x in line.split()]
            poses.append(Pose(v[0], (v[1], v[2], v[3]), yaw_of(v[4], v[5], v[6], v[7])))
    return poses


def read_pose_graph(path: Path) -> list[Keyframe]:
    keyframes = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        v = line.split()
        if not v:
            continue
        if len(v) < 17:
            raise ValueError(f"{path}:{n}: {len(v)} columns, expected 26")
        f = [float(x) for x in v[:17]]
        keyframes.append(
            Keyframe(int(f[0]), f[1], (f[2], f[3], f[4]), (f[5], f[6], f[7]), int(f[16]))
        )
    return keyframes


def read_vio_loop(path: Path) -> list[Keyframe]:
    keyframes: list[Keyframe] = []
    for line in path.read_text().splitlines():
        v = [x for x in line.split(",") if x.strip()]
        if len(v) >= 4:
            p = (float(v[1]), float(v[2]), float(v[3]))
            keyframes.append(Keyframe(len(keyframes), float(v[0]) * 1e-9, p, p, -1))
    return keyframes


class Truth:
    """Every sequence's ground truth, looked up by published stamp."""

    def __init__(self, sequences: list[list[Pose]]) -> None:
        entries = sorted((p.stamp, k, p) for k, seq in enumerate(sequences) for p in seq)
        self.stamps = [e[0] for e in entries]
        self.entries = [(e[1], e[2]) for e in entries]

    def find(self, stamp: float) -> tuple[int, Pose] | None:
        i = bisect.bisect_left(self.stamps, stamp)
        best = min(
            (j for j in (i - 1, i) if 0 <= j < len(self.stamps)),
            default=None,
            key=lambda j: abs(self.stamps[j] - stamp),
        )
        if best is None or abs(self.stamps[best] - stamp) > STAMP_TOLERANCE_S:
            return None
        return self.entries[best]


def ate_rmse(estimate: list[Point], truth: list[Point]) -> float | None:
    """RMSE of the position error after the SE(3) Umeyama alignment of estimate to truth (pairs
    already matched), by topoloc's evo-equivalent trajectory metrics."""
    if len(estimate) < 3:
        return None
    rows = np.zeros((len(estimate), 8))
    rows[:, 0] = np.arange(len(estimate))  # the pairs' order: already associated
    rows[:, 7] = 1.0  # identity rotations: ATE reads the positions only
    est, ref = rows.copy(), rows.copy()
    est[:, 1:4], ref[:, 1:4] = estimate, truth
    return float(topoloc.evaluate_trajectory(ref, est, alignment="se3").ate_m.rmse)


def judge_loops(
    pairs: list[tuple[int, int]], keyframes: dict[int, Keyframe], truth: Truth
) -> dict[str, Any]:
    judged = []
    for cur, old in pairs:
        entry: dict[str, Any] = {"cur": cur, "old": old}
        found = [truth.find(keyframes[i].stamp) if i in keyframes else None for i in (cur, old)]
        a, b = found
        if a is None or b is None:
            entry["false"] = None  # a keyframe missing from the pose graph or the truth
        else:
            distance = math.dist(a[1].position, b[1].position)
            dyaw = abs(math.degrees(a[1].yaw - b[1].yaw) + 180) % 360 - 180
            entry.update(
                sequences=[a[0], b[0]],
                distance_m=round(distance, 2),
                yaw_deg=round(abs(dyaw), 1),
                false=distance > MAX_LOOP_DISTANCE_M or abs(dyaw) > MAX_LOOP_YAW_DEG,
            )
        judged.append(entry)
    return {
        "count": len(judged),
        "false": sum(1 for e in judged if e["false"]),
        "unknown": sum(1 for e in judged if e["false"] is None),
        "cross_sequence": sum(1 for e in judged if len(set(e.get("sequences", [0]))) > 1),
        "pairs": judged,
    }


def parse_log(text: str) -> tuple[list[tuple[int, int]], list[float]]:
    loops, ms = [], []
    for line in text.splitlines():
        v = line.split()
        if len(v) >= 4 and v[0] == "[topoloc-bench]" and v[1] == "loop":
            loops.append((int(float(v[2])), int(float(v[3]))))
        elif len(v) >= 3 and v[0] == "[topoloc-bench]" and v[1] == "loop-detection-ms":
            ms.append(float(v[2]))
    return loops, ms


def rounded(value: float | None, digits: int = 3) -> float | None:
    return None if value is None else round(value, digits)


def judge(args: argparse.Namespace) -> dict[str, Any]:
    truths: list[list[Pose]] = []
    odometries: list[list[Pose]] = []
    while (args.driver_out / f"truth-{len(truths)}.txt").exists():
        truths.append(read_tum(args.driver_out / f"truth-{len(truths)}.txt"))
        odometries.append(read_tum(args.driver_out / f"odometry-{len(odometries)}.txt"))
    if not truths:
        raise ValueError(f"no truth-0.txt in {args.driver_out}")
    truth = Truth(truths)
    odometry_by_stamp = Truth(odometries)
    keyframes = (
        read_pose_graph(args.pose_graph) if args.pose_graph else read_vio_loop(args.vio_loop)
    )
    by_index = {kf.index: kf for kf in keyframes}

    # (sequence, pose graph position, odometry position, true position) per keyframe found
    per_kf: list[tuple[int, Point, Point, Point]] = []
    unmatched = 0
    for kf in keyframes:
        t, o = truth.find(kf.stamp), odometry_by_stamp.find(kf.stamp)
        if t is None or o is None:
            unmatched += 1
            continue
        per_kf.append((t[0], kf.pg, o[1].position, t[1].position))

    sequences = []
    for k, (seq_truth, seq_odometry) in enumerate(zip(truths, odometries)):
        rows = [r for r in per_kf if r[0] == k]
        sequences.append(
            {
                "frames": len(seq_truth),
                "keyframes": len(rows),
                "ate_odometry_keyframes_m": rounded(
                    ate_rmse([r[2] for r in rows], [r[3] for r in rows])
                ),
                "ate_odometry_all_frames_m": rounded(
                    ate_rmse(
                        [p.position for p in seq_odometry],
                        [p.position for p in seq_truth],
                    )
                ),
                "ate_pose_graph_m": rounded(ate_rmse([r[1] for r in rows], [r[3] for r in rows])),
            }
        )

    log = args.log.read_text(errors="replace") if args.log else ""
    log_loops, ms = parse_log(log)
    graph_loops = [(kf.index, kf.loop_index) for kf in keyframes if kf.loop_index >= 0]
    before, shut_down, after = log.partition(SHUTDOWN_MARKER)
    crash_markers = [m for m in CRASH_MARKERS if m in before]
    upstream_end = bool(shut_down) and after.strip() in ("", UPSTREAM_EXIT[1])
    exit_ok = args.exit_code in (None, 0) or (upstream_end and args.exit_code == UPSTREAM_EXIT[0])
    return {
        "keyframes": len(keyframes),
        "keyframes_unmatched": unmatched,
        "sequences": sequences,
        "ate_joint_pose_graph_m": rounded(ate_rmse([r[1] for r in per_kf], [r[3] for r in per_kf])),
        "ate_joint_odometry_m": rounded(ate_rmse([r[2] for r in per_kf], [r[3] for r in per_kf])),
        "loops_log": judge_loops(log_loops, by_index, truth),
        "loops_pose_graph": judge_loops(graph_loops, by_index, truth),
        "loop_detection_ms": {
            "keyframes": len(ms),
            "median": rounded(float(np.median(ms)), 2) if ms else None,
            "p90": rounded(float(np.percentile(ms, 90)), 2) if ms else None,
        },
        "assertion": "Assertion" in log,
        "exit_code": args.exit_code,
        "shut_down_by_command": upstream_end,
        "crashed": not exit_ok or bool(crash_markers),
        "crash_markers": crash_markers,
    }


def summary(r: dict[str, Any]) -> str:
    def fmt(v: Any) -> str:
        return "-" if v is None else str(v)

    lines = [f"keyframes {r['keyframes']} (unmatched to truth: {r['keyframes_unmatched']})"]
    for k, s in enumerate(r["sequences"]):
        lines.append(
            f"  seq {k}: {s['keyframes']}/{s['frames']} frames as keyframes, ATE m: "
            f"odometry {fmt(s['ate_odometry_keyframes_m'])} "
            f"(all frames {fmt(s['ate_odometry_all_frames_m'])}), "
            f"pose graph {fmt(s['ate_pose_graph_m'])}"
        )
    lines.append(
        f"  joint ATE m (one alignment): pose graph {fmt(r['ate_joint_pose_graph_m'])}, "
        f"odometry (unmerged) {fmt(r['ate_joint_odometry_m'])}"
    )
    for name in ("loops_log", "loops_pose_graph"):
        lo = r[name]
        lines.append(
            f"{name}: {lo['count']} (false {lo['false']}, unknown {lo['unknown']}, "
            f"cross-sequence {lo['cross_sequence']})"
        )
    ms = r["loop_detection_ms"]
    lines.append(
        f"loop detection ms/keyframe: median {fmt(ms['median'])}, p90 {fmt(ms['p90'])} "
        f"({ms['keyframes']} keyframes)"
    )
    lines.append(
        f"assertion: {r['assertion']}, crashed: {r['crashed']} (exit code {fmt(r['exit_code'])}"
        f"{', ' + ', '.join(r['crash_markers']) if r['crash_markers'] else ''})"
    )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--driver-out", type=Path, required=True)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--pose-graph", type=Path, help="loop_fusion's pose_graph.txt")
    source.add_argument("--vio-loop", type=Path, help="loop_fusion's vio_loop.csv")
    parser.add_argument("--log", type=Path, help="the node's stdout and stderr")
    parser.add_argument("--exit-code", type=int, help="the node's exit code")
    parser.add_argument("--json", type=Path, help="where to write the report")
    args = parser.parse_args()
    try:
        result = judge(args)
    except (OSError, ValueError) as e:
        print(f"judge.py: {e}", file=sys.stderr)
        return 2
    print(summary(result))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
