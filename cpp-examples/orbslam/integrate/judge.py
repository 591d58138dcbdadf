#!/usr/bin/env python3
"""Judges the runs of run.sh against ground truth and writes OUT/table.md and OUT/judged.json.

    judge.py OUT --kitti KITTI_SEQ --tum TUM_SEQ [--topoloc BIN]

Per run (a folder of OUT with log.txt, time.txt and the trajectories ORB-SLAM3 saved):
- ATE (RMSE), ARE, RPE: `topoloc ate` (Sim(3) alignment for monocular KITTI, SE(3) for RGB-D
  TUM), cross-checked with evo's `evo_ape` (same alignment) when it is installed;
- loops and merges: the `[topoloc-bench] loop|merge T_CURRENT T_MATCHED` lines; one is false
  when the two keyframes' ground-truth positions are farther apart than the radius (KITTI 10 m,
  as the loop pairs of the K1 benchmark; TUM fr1_xyz 0.5 m);
- maps: "Creation of new map with id:" lines (the first map included), tracking failures: "Fail to
  track local map!" lines;
- place recognition per keyframe: the median and p90 of `[topoloc-bench] place-recognition-ms`
  (LoopClosing::NewDetectCommonRegions: the database query and the candidates' verification);
- peak memory: /usr/bin/time's maximum resident set size.
"""

from __future__ import annotations

import argparse
import bisect
import json
import math
import re
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

RADIUS_M = {"kitti": 10.0, "tum": 0.5}


def read_truth(path: Path) -> tuple[list[float], list[tuple[float, float, float]]]:
    times, positions = [], []
    for line in path.read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        v = line.split()
        times.append(float(v[0]))
        positions.append((float(v[1]), float(v[2]), float(v[3])))
    return times, positions


def nearest(times: list[float], t: float) -> int:
    i = bisect.bisect_left(times, t)
    if i == 0:
        return 0
    if i == len(times):
        return len(times) - 1
    return i if times[i] - t < t - times[i - 1] else i - 1


def judge_pairs(pairs, truth, radius):
    times, positions = truth
    out = []
    for current, matched in pairs:
        a, b = positions[nearest(times, current)], positions[nearest(times, matched)]
        distance = math.dist(a, b)
        out.append(
            {
                "current": current,
                "matched": matched,
                "distance_m": round(distance, 2),
                "false": distance > radius,
            }
        )
    return out


def ate(topoloc: str, estimate: Path, truth: Path, align: str) -> dict:
    result = subprocess.run(
        [topoloc, "ate", str(estimate), str(truth), "--align", align, "--json"],
        capture_output=True,
        text=True,
    )
    if result.returncode != 0:
        return {"error": result.stderr.strip()}
    return json.loads(result.stdout)


def evo_ate(estimate: Path, truth: Path, align: str) -> float | None:
    if shutil.which("evo_ape") is None:
        return None
    flags = ["-as"] if align == "sim3" else ["-a"]
    result = subprocess.run(
        ["evo_ape", "tum", str(truth), str(estimate), *flags], capture_output=True, text=True
    )
    match = re.search(r"^\s*rmse\s+([0-9.eE+-]+)", result.stdout, re.MULTILINE)
    return float(match.group(1)) if match else None


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))]


def judge_run(run_dir: Path, truth_path: Path, seq: str, topoloc: str) -> dict:
    log = (
        (run_dir / "log.txt").read_text(errors="replace") if (run_dir / "log.txt").exists() else ""
    )
    truth = read_truth(truth_path)
    found = {"loop": [], "merge": []}
    ms = []
    for line in log.splitlines():
        v = line.split()
        if len(v) == 4 and v[0] == "[topoloc-bench]" and v[1] in found:
            found[v[1]].append((float(v[2]), float(v[3])))
        elif len(v) == 3 and v[0] == "[topoloc-bench]" and v[1] == "place-recognition-ms":
            ms.append(float(v[2]))
    loops = judge_pairs(found["loop"], truth, RADIUS_M[seq])
    merges = judge_pairs(found["merge"], truth, RADIUS_M[seq])
    time_report = (run_dir / "time.txt").read_text() if (run_dir / "time.txt").exists() else ""
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", time_report)
    wall = re.search(r"Elapsed \(wall clock\) time.*: (.+)", time_report)
    estimate = run_dir / ("KeyFrameTrajectory.txt" if seq == "kitti" else "CameraTrajectory.txt")
    align = "sim3" if seq == "kitti" else "se3"
    result = {
        "failed": (run_dir / "failed.txt").read_text().strip()
        if (run_dir / "failed.txt").exists()
        else None,
        "loops": len(loops),
        "false_loops": sum(p["false"] for p in loops),
        "merges": len(merges),
        "false_merges": sum(p["false"] for p in merges),
        "loop_pairs": loops,
        "merge_pairs": merges,
        "maps": log.count("Creation of new map with id:"),
        "tracking_failures": log.count("Fail to track local map!"),
        "keyframes_checked": len(ms),
        "place_recognition_ms_median": round(statistics.median(ms), 2) if ms else None,
        "place_recognition_ms_p90": round(percentile(ms, 0.9), 2) if ms else None,
        "peak_rss_mb": round(int(rss.group(1)) / 1024) if rss else None,
        "wall": wall.group(1).strip() if wall else None,
        "trajectory": estimate.name,
        "align": align,
    }
    if estimate.exists() and estimate.stat().st_size > 0:
        result["ate"] = ate(topoloc, estimate, truth_path, align)
        result["evo_ate_rmse"] = evo_ate(estimate, truth_path, align)
    return result


def fmt(value, digits=3):
    if value is None:
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def table(results: dict) -> str:
    lines = [
        "| run | ATE m (evo) | RPE m | poses | loops (false) | merges (false) | maps | track fails | PR ms/KF median (p90) | peak MB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        a = r.get("ate") or {}
        ate_text = (
            f"{fmt(a['ate_m']['rmse'])} ({fmt(r.get('evo_ate_rmse'))})" if "ate_m" in a else "-"
        )
        rpe = a["rpe_m"]["rmse"] if "rpe_m" in a else None
        lines.append(
            f"| {name} | {ate_text} | {fmt(rpe, 4)} | {fmt(a.get('pairs'))} | {r['loops']} ({r['false_loops']}) "
            f"| {r['merges']} ({r['false_merges']}) | {r['maps']} | {r['tracking_failures']} "
            f"| {fmt(r['place_recognition_ms_median'], 1)} ({fmt(r['place_recognition_ms_p90'], 1)}) | {fmt(r['peak_rss_mb'])} |"
        )
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--kitti", type=Path, required=True)
    parser.add_argument("--tum", type=Path, required=True)
    parser.add_argument("--topoloc", default="topoloc")
    args = parser.parse_args()
    truths = {"kitti": args.kitti / "groundtruth_tum.txt", "tum": args.tum / "groundtruth.txt"}
    results = {}
    for run_dir in sorted(p for p in args.out.iterdir() if p.is_dir() and (p / "log.txt").exists()):
        seq = run_dir.name.split("-")[0]
        if seq not in truths:
            continue
        results[run_dir.name] = judge_run(run_dir, truths[seq], seq, args.topoloc)
    if not results:
        print(f"judge.py: no run folder in {args.out}", file=sys.stderr)
        return 2
    (args.out / "judged.json").write_text(json.dumps(results, indent=1) + "\n")
    text = table(results)
    (args.out / "table.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
