#!/usr/bin/env python3
"""Judges DLoopDetector's loops (run.sh output), and topoloc's, against KITTI ground truth.

    judge.py OUT_DIR SEQUENCE [--radius-m 10] [--max-angle-deg 45] [--exclude-seconds 10]
             [--topoloc HINTS.csv --topoloc-json REPORT.json]

Reads OUT_DIR/dloop.csv (and OUT_DIR/dloop-alpha-*.csv when present), SEQUENCE/times.txt and
SEQUENCE/groundtruth_tum.txt (TUM lines `t tx ty tz qx qy qz qw`, matched to frames by
timestamp). A detected loop (status LOOP_DETECTED) is correct when the two frames' ground-truth
cameras are within the radius and their orientations within the angle. Recall is over the
keyframes that could close a loop: those with an earlier keyframe at least --exclude-seconds
older within the radius and the angle (recall_any_heading: within the radius alone). Prints JSON:
hints, precision, recall, median ms, and over the alpha sweep each alpha's figures and the recall
at 100% precision.

With --topoloc, the hints file of `topoloc loops --out` on the same sequence at the same keyframe
rate is judged by the same code on topoloc's own keyframes: their frames are the report's
`sequence.keyframe_frames` (--topoloc-json, the report of `topoloc loops --json`), checked
against the hints' `query_frame` column; the hints' `query_index` / `matched_index` are keyframe
indices among them. (A report without `keyframe_frames`, from an older topoloc, maps the keyframe
indices to frames through dloop.csv, whose keyframe count must then agree.) Its recall at 100%
precision is swept over the hints' confidence, and its median time per keyframe is read from the
report. A precision or recall without hints or possible loops is null, in topoloc's report as
here.
"""
import argparse
import csv
import glob
import json
import math
import os
import re
import sys

import numpy as np


def read_times(path):
    with open(path) as f:
        return np.array([float(x) for x in f.read().split()])


def read_truth(path, times):
    """Positions (N,3) and unit quaternions (N,4, xyzw) per frame, by nearest timestamp."""
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith("#"):
                rows.append([float(x) for x in line.split()[:8]])
    gt = np.array(rows)
    order = np.argsort(gt[:, 0])
    gt = gt[order]
    idx = np.searchsorted(gt[:, 0], times)
    idx = np.clip(idx, 1, len(gt) - 1)
    left_closer = np.abs(times - gt[idx - 1, 0]) <= np.abs(gt[idx, 0] - times)
    idx = np.where(left_closer, idx - 1, idx)
    gap = np.abs(gt[idx, 0] - times)
    if gap.max() > 0.02:
        sys.exit(f"judge.py: no ground truth within 20 ms of frame {int(gap.argmax())}")
    q = gt[idx, 4:8]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return gt[idx, 1:4], q


def read_run(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"judge.py: {path} has no rows")
    if any(None in r.values() or None in r for r in rows):
        sys.exit(f"judge.py: {path} has incomplete rows (still being written?)")
    return rows


def judge(rows, times, pos, quat, args):
    frames = np.array([int(r["frame"]) for r in rows])
    if frames.max() >= len(times):
        sys.exit("judge.py: the CSV names frames beyond times.txt")
    p, q, t = pos[frames], quat[frames], times[frames]
    max_angle = math.radians(args.max_angle_deg)

    def near(a, b, angle=max_angle):  # arrays of keyframe indices, or scalars
        d = np.linalg.norm(p[a] - p[b], axis=-1)
        dot = np.clip(np.abs(np.sum(q[a] * q[b], axis=-1)), 0.0, 1.0)
        return (d <= args.radius_m) & (2.0 * np.arccos(dot) <= angle)

    n = len(rows)
    possible = possible_any_heading = 0
    for i in range(n):
        earlier = np.nonzero(t[:i] <= t[i] - args.exclude_seconds)[0]
        if len(earlier):
            possible += int(near(np.full(len(earlier), i), earlier).any())
            possible_any_heading += int(near(np.full(len(earlier), i), earlier, math.pi).any())
    hints = correct = 0
    for i, r in enumerate(rows):
        if r["status"] != "LOOP_DETECTED":
            continue
        hints += 1
        correct += int(bool(near(i, int(r["matched_index"]))))
    ms = [float(r["ms"]) for r in rows]
    statuses = {}
    for r in rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    return {
        "keyframes": n,
        "hints": hints,
        "correct": correct,
        "possible": possible,
        "precision": correct / hints if hints else None,
        "recall": correct / possible if possible else None,
        # Recall against every place revisited within the radius whatever the heading
        # (includes revisits driven the opposite way, which an image cannot close).
        "possible_any_heading": possible_any_heading,
        "recall_any_heading": correct / possible_any_heading if possible_any_heading else None,
        "median_ms": float(np.median(ms)),
        "statuses": statuses,
    }


def topoloc_keyframe_frames(report, keyframe_rows):
    """The frame of each of topoloc's keyframes: the report's own list, else (an older topoloc)
    dloop.csv's, which must have as many keyframes."""
    frames = report.get("sequence", {}).get("keyframe_frames")
    if frames is not None:
        if len(frames) != report["keyframes"]:
            sys.exit("judge.py: the topoloc report's keyframe_frames and keyframes disagree")
        return [int(f) for f in frames]
    if report["keyframes"] != len(keyframe_rows):
        sys.exit(
            f"judge.py: topoloc kept {report['keyframes']} keyframes, run.sh "
            f"{len(keyframe_rows)}, and its report lists no keyframe_frames: run both at the "
            "same --keyframe-rate"
        )
    return [int(k["frame"]) for k in keyframe_rows]


def judge_topoloc(hints_path, report_path, keyframe_rows, times, pos, quat, args):
    """topoloc's hints judged as DLoopDetector's rows are, on topoloc's keyframes: the hint
    file's keyframe indices are positions among them."""
    with open(report_path) as f:
        report = json.load(f)
    frames = topoloc_keyframe_frames(report, keyframe_rows)
    hints = {}
    with open(hints_path) as f:
        for r in csv.DictReader(f):
            q = int(r["query_index"])
            if q >= len(frames):
                sys.exit(f"judge.py: {hints_path} names keyframe {q} of {len(frames)}")
            if r.get("query_frame") not in (None, "") and int(r["query_frame"]) != frames[q]:
                sys.exit(
                    f"judge.py: {hints_path}: keyframe {q} is frame {r['query_frame']}, "
                    f"the report says {frames[q]}"
                )
            hints[q] = (int(r["matched_index"]), float(r["confidence"]))
    rows = [
        {
            "frame": frame,
            "status": "LOOP_DETECTED" if i in hints else "NONE",
            "matched_index": hints[i][0] if i in hints else "",
            "ms": report["keyframe_ms_median"],
        }
        for i, frame in enumerate(frames)
    ]
    out = judge(rows, times, pos, quat, args)
    out.pop("statuses")
    # Recall at 100% precision over the confidence: the best recall among thresholds that keep
    # only correct hints.
    judged = [judge(
        [dict(r, status="NONE") if r["status"] == "LOOP_DETECTED" and hints[i][1] < c else r
         for i, r in enumerate(rows)], times, pos, quat, args)
        for c in sorted({c for _, c in hints.values()})]
    full = [j["recall"] or 0.0 for j in judged if j["hints"] and j["correct"] == j["hints"]]
    out["recall_at_full_precision"] = max(full) if full else 0.0
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("sequence")
    ap.add_argument("--radius-m", type=float, default=10.0)
    ap.add_argument("--max-angle-deg", type=float, default=45.0)
    ap.add_argument("--exclude-seconds", type=float, default=10.0)
    ap.add_argument("--topoloc", help="hints CSV of `topoloc loops --out` on the same keyframes")
    ap.add_argument("--topoloc-json", help="report of that run (`topoloc loops --json`)")
    args = ap.parse_args()
    if bool(args.topoloc) != bool(args.topoloc_json):
        sys.exit("judge.py: --topoloc and --topoloc-json go together")

    times = read_times(os.path.join(args.sequence, "times.txt"))
    pos, quat = read_truth(os.path.join(args.sequence, "groundtruth_tum.txt"), times)
    out = {
        "radius_m": args.radius_m,
        "max_angle_deg": args.max_angle_deg,
        "exclude_seconds": args.exclude_seconds,
    }
    main_csv = os.path.join(args.out_dir, "dloop.csv")
    if os.path.exists(main_csv):
        keyframe_rows = read_run(main_csv)
        out.update(judge(keyframe_rows, times, pos, quat, args))
        if args.topoloc:
            out["topoloc"] = judge_topoloc(
                args.topoloc, args.topoloc_json, keyframe_rows, times, pos, quat, args
            )
    elif args.topoloc:
        sys.exit(f"judge.py: --topoloc needs {main_csv} for the keyframes' frames")
    sweep = []
    for path in glob.glob(os.path.join(args.out_dir, "dloop-alpha-*.csv")):
        m = re.search(r"dloop-alpha-(.+)\.csv$", path)
        res = judge(read_run(path), times, pos, quat, args)
        res.pop("statuses")
        sweep.append({"alpha": float(m.group(1)), **res})
    if sweep:
        sweep.sort(key=lambda s: s["alpha"])
        full = [s["recall"] or 0.0 for s in sweep if s["hints"] and s["correct"] == s["hints"]]
        out["alpha_sweep"] = sweep
        out["recall_at_full_precision"] = max(full) if full else 0.0
    if "hints" not in out and not sweep:
        sys.exit(f"judge.py: no dloop.csv or dloop-alpha-*.csv in {args.out_dir}")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
