"""Training data for the learned spatio-temporal model (GRNN, issue 35): generated worlds from
`topoloc simulate`, described once with each world's own map describer, cached as .npz.

    /usr/bin/python3 python/train/dataset.py --split train --worlds 0-2 \\
        --conditions bright,dim,night --out DIR

For every world and light condition it runs `topoloc simulate` (the map is always captured in
bright light; the query frames under the condition), then writes DIR/<split>-w<K>-<condition>.npz:

- `view_descriptors` (V, D) float32: the map's views, the micro nodes of the seed's graph;
- `view_place` (V,) int64, `view_slot` (V,) int64: each view's place and its index among the
  place's views (its yaw bin);
- `place_edges` (E, 2) int64: the map's graph;
- per trajectory i: `frames_i` (T, D) float32, the query frames' descriptors (the map's describer);
  `view_i`, `place_i` (T,) int64, the ground-truth view and place; `visible_i` (T,) bool.

Needs Debian's python3 (numpy) and the topoloc package of this checkout (`python/topoloc`, with
TOPOLOC_LIBRARY naming libtopoloc.so); the CLI at target/release/topoloc.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "python"))
import topoloc  # noqa: E402  (the package of this checkout)

SPLITS = ("train", "tr-t", "tr-a", "test")
CONDITIONS = ("bright", "dim", "night", "colour_shift", "noise", "motion_blur")


@dataclass
class World:
    """One world's map as the model sees it, and its query trajectories."""

    view_descriptors: NDArray[np.float32]
    view_place: NDArray[np.int64]
    view_slot: NDArray[np.int64]
    place_edges: NDArray[np.int64]
    trajectories: list[Trajectory]


@dataclass
class Trajectory:
    """A query trajectory: per frame its descriptor and ground truth."""

    frames: NDArray[np.float32]
    view: NDArray[np.int64]
    place: NDArray[np.int64]
    visible: NDArray[np.bool_]


def micro_edges(
    view_place: NDArray[np.int64], view_slot: NDArray[np.int64], place_edges: NDArray[np.int64]
) -> NDArray[np.int64]:
    """The micro-node graph, (2, M) int64 directed edges source -> target without self loops:
    every two views of one place, and the views of the same slot (yaw bin) of two places joined
    by an edge. The Rust estimator builds the same graph from the map."""
    sources: list[NDArray[np.int64]] = []
    targets: list[NDArray[np.int64]] = []
    order = np.argsort(view_place, kind="stable")
    places, starts = np.unique(view_place[order], return_index=True)
    bounds = [*starts.tolist(), len(order)]
    views_of = {int(p): order[bounds[i] : bounds[i + 1]] for i, p in enumerate(places)}
    for views in views_of.values():
        a, b = np.meshgrid(views, views, indexing="ij")
        keep = a != b
        sources.append(a[keep])
        targets.append(b[keep])
    for p, q in place_edges:
        vp, vq = views_of.get(int(p)), views_of.get(int(q))
        if vp is None or vq is None:
            continue
        slots_q = {int(view_slot[v]): v for v in vq}
        for v in vp:
            w = slots_q.get(int(view_slot[v]))
            if w is not None:
                sources += [np.array([v, w])]
                targets += [np.array([w, v])]
    if not sources:
        return np.zeros((2, 0), dtype=np.int64)
    return np.stack([np.concatenate(sources), np.concatenate(targets)]).astype(np.int64)


def read_map(path: Path) -> tuple[topoloc.Map, World]:
    """The map at `path` and its graph (no trajectories yet)."""
    m = topoloc.Map.load(path)
    view_place = np.empty(m.view_count, dtype=np.int64)
    view_slot = np.empty(m.view_count, dtype=np.int64)
    for place in range(m.place_count):
        for slot, view in enumerate(m.place_views(place)):
            view_place[view], view_slot[view] = place, slot
    pairs, _ = m.edges()
    world = World(m.view_descriptors(), view_place, view_slot, pairs.astype(np.int64), [])
    return m, world


def read_trajectory(folder: Path, describer: topoloc.Describer) -> Trajectory:
    """Describes every frame of a `simulate` trajectory folder; reads its nodes.csv."""
    import cv2  # Debian's python3-opencv: only the extraction needs it

    with open(folder / "nodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    frames = np.empty((len(rows), describer.dim), dtype=np.float32)
    for i in range(len(rows)):
        image = cv2.imread(str(folder / "images" / f"{i:06d}.png"), cv2.IMREAD_COLOR)
        if image is None:
            raise FileNotFoundError(folder / "images" / f"{i:06d}.png")
        frames[i] = describer.describe(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
    return Trajectory(
        frames,
        np.array([int(r["view"]) for r in rows], dtype=np.int64),
        np.array([int(r["place"]) for r in rows], dtype=np.int64),
        np.array([r["visible"] == "1" for r in rows], dtype=bool),
    )


def save(world: World, path: Path) -> None:
    arrays: dict[str, NDArray[np.generic]] = {
        "view_descriptors": world.view_descriptors,
        "view_place": world.view_place,
        "view_slot": world.view_slot,
        "place_edges": world.place_edges,
    }
    for i, t in enumerate(world.trajectories):
        arrays |= {f"frames_{i}": t.frames, f"view_{i}": t.view, f"place_{i}": t.place}
        arrays[f"visible_{i}"] = t.visible
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
    os.replace(tmp, path)


def load(path: Path) -> World:
    """A world saved by `save`."""
    with np.load(path) as z:
        count = sum(1 for k in z.files if k.startswith("frames_"))
        trajectories = [
            Trajectory(z[f"frames_{i}"], z[f"view_{i}"], z[f"place_{i}"], z[f"visible_{i}"])
            for i in range(count)
        ]
        return World(
            z["view_descriptors"], z["view_place"], z["view_slot"], z["place_edges"], trajectories
        )


def extract(
    topoloc_cli: Path, split: str, world: int, condition: str, trajectories: int, out: Path
) -> Path:
    """Simulates world `world` of `split` under `condition`, describes it, saves the .npz."""
    path = out / f"{split}-w{world}-{condition}.npz"
    if path.exists():
        return path
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [
                str(topoloc_cli),
                "simulate",
                "--split",
                split,
                "--world",
                str(world),
                "--condition",
                condition,
                "--trajectories",
                str(trajectories),
                "--out",
                tmp,
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        m, w = read_map(Path(tmp) / "map.topoloc")
        with topoloc.Describer(m) as describer:
            w.trajectories = [
                read_trajectory(Path(tmp) / f"traj-{i:03d}", describer) for i in range(trajectories)
            ]
        save(w, path)
    return path


def parse_range(text: str) -> list[int]:
    """`0-2` or `0,3,5`."""
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--split", choices=SPLITS, required=True)
    parser.add_argument("--worlds", type=parse_range, default=[0, 1, 2])
    parser.add_argument("--conditions", default="bright,dim,night")
    parser.add_argument("--trajectories", type=int, default=2)
    parser.add_argument("--topoloc", type=Path, default=ROOT / "target" / "release" / "topoloc")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    conditions = args.conditions.split(",")
    unknown = [c for c in conditions if c not in CONDITIONS]
    if unknown:
        parser.error(f"unknown conditions {unknown} (of {', '.join(CONDITIONS)})")
    args.out.mkdir(parents=True, exist_ok=True)
    for world in args.worlds:
        for condition in conditions:
            path = extract(args.topoloc, args.split, world, condition, args.trajectories, args.out)
            print(f"dataset: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
