"""Trains the GRNN (model.py) on worlds extracted by dataset.py, on the CPU; export.py turns the
checkpoint into the ONNX file topoloc runs.

    /usr/bin/python3 python/train/train.py --data DIR --train 'train-*.npz,tr-t-*.npz' \\
        --validate 'tr-a-*.npz' --out grnn.pt [--epochs 60] [--seed 1]

A sample is a sequence of 10-20 consecutive frames of one trajectory (`--frames`); a batch is
`--batch` sequences of one world (they share its graph). The loss is the negative
log-likelihood of the ground-truth place (the view posterior summed over the place's views;
`--loss view`: of the ground-truth view), on frames where a place is visible, averaged; the
state starts at zero for each sequence. The seed's optimiser: Adam, weight decay 1e-3, lr 1e-4
times 0.7 every 20 epochs, batch 32 sequences; an epoch is `--batches` batches.
Validation reports MNA (the most probable place is the true place) and OHA (it is the true
place or a graph neighbour) over whole trajectories run frame by frame.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import dataset  # noqa: E402
from model import GRNN, Sizes  # noqa: E402


class Graph:
    """A world's tensors, built once."""

    def __init__(self, world: dataset.World) -> None:
        self.world = world
        self.nodes = torch.from_numpy(world.view_descriptors)
        self.view_place = torch.from_numpy(world.view_place)
        self.edges = torch.from_numpy(
            dataset.micro_edges(world.view_place, world.view_slot, world.place_edges)
        )
        n_places = int(world.view_place.max()) + 1
        self.places = n_places
        self.adjacent = np.eye(n_places, dtype=bool)
        for p, q in world.place_edges:
            self.adjacent[p, q] = self.adjacent[q, p] = True


def load_worlds(data: Path, patterns: str) -> list[Graph]:
    paths = sorted({p for pattern in patterns.split(",") for p in data.glob(pattern)})
    if not paths:
        raise SystemExit(f"train: no dataset matches {patterns!r} in {data}")
    return [Graph(dataset.load(p)) for p in paths]


def sample_batch(
    graph: Graph, batch: int, frames: tuple[int, int], rng: np.random.Generator
) -> tuple[Tensor, Tensor, Tensor]:
    """Frames (L, B, D), target views (L, B) and the visible mask (L, B) of `batch` sequences."""
    length = int(rng.integers(frames[0], frames[1] + 1))
    trajectories = [t for t in graph.world.trajectories if len(t.view) >= length]
    seqs = []
    for _ in range(batch):
        t = trajectories[int(rng.integers(len(trajectories)))]
        start = int(rng.integers(0, len(t.view) - length + 1))
        seqs.append((t, start))
    d = np.stack([t.frames[s : s + length] for t, s in seqs], axis=1)
    v = np.stack([t.view[s : s + length] for t, s in seqs], axis=1)
    m = np.stack([t.visible[s : s + length] & (t.view[s : s + length] >= 0) for t, s in seqs], 1)
    return torch.from_numpy(d), torch.from_numpy(np.maximum(v, 0)), torch.from_numpy(m)


def place_probabilities(graph: Graph, logits: Tensor) -> Tensor:
    """(B, P): the view posterior summed over each place's views."""
    views = torch.softmax(logits, dim=1)
    return torch.zeros(logits.shape[0], graph.places).index_add(1, graph.view_place, views)


def sequence_loss(
    model: GRNN, graph: Graph, frames: Tensor, views: Tensor, mask: Tensor, by_place: bool
) -> Tensor:
    """Mean negative log-likelihood of the true view (or, `by_place`, of the true view's
    place) over the visible frames of the batch."""
    state = torch.zeros(frames.shape[1], graph.nodes.shape[0], model.sizes.state)
    total = torch.zeros(())
    count = mask.sum().clamp(min=1)
    for k in range(frames.shape[0]):
        logits, state = model(graph.nodes, graph.edges, frames[k], state)
        if by_place:
            places = place_probabilities(graph, logits)
            truth = graph.view_place[views[k]]
            losses = -torch.log(places.gather(1, truth[:, None]).squeeze(1) + 1e-9)
        else:
            losses = torch.nn.functional.cross_entropy(logits, views[k], reduction="none")
        total = total + (losses * mask[k]).sum()
    return total / count


@torch.no_grad()
def evaluate(model: GRNN, graphs: list[Graph]) -> dict[str, float]:
    """MNA and OHA over every trajectory, run frame by frame from a zero state."""
    model.eval()
    hits = one_hop = total = 0
    for g in graphs:
        for t in g.world.trajectories:
            state = torch.zeros(1, g.nodes.shape[0], model.sizes.state)
            for k in range(len(t.view)):
                frame = torch.from_numpy(t.frames[k : k + 1])
                logits, state = model(g.nodes, g.edges, frame, state)
                if not t.visible[k] or t.place[k] < 0:
                    continue
                place = int(place_probabilities(g, logits)[0].argmax())
                hits += place == t.place[k]
                one_hop += bool(g.adjacent[place, t.place[k]])
                total += 1
    model.train()
    return {"mna": hits / max(total, 1), "oha": one_hop / max(total, 1), "frames": total}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--train", default="train-*.npz,tr-t-*.npz")
    parser.add_argument("--validate", default="tr-a-*.npz")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--epochs", type=int, default=60)
    parser.add_argument("--batches", type=int, default=20, help="batches per epoch")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--frames", default="10-20")
    parser.add_argument("--lr", type=float, default=1e-4)
    parser.add_argument("--weight-decay", type=float, default=1e-3)
    parser.add_argument("--hidden", type=int, default=512)
    parser.add_argument("--neighbour", type=int, default=128)
    parser.add_argument("--state", type=int, default=512)
    parser.add_argument("--no-temporal", action="store_true")
    parser.add_argument(
        "--loss", choices=["place", "view"], default="place", help="likelihood of the place or view"
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(args.seed)
    lo, _, hi = args.frames.partition("-")
    frames = (int(lo), int(hi or lo))
    train = load_worlds(args.data, args.train)
    validate = load_worlds(args.data, args.validate) if args.validate else []
    sizes = Sizes(args.hidden, args.neighbour, args.state, 0.2, not args.no_temporal)
    model = GRNN(sizes)
    optimiser = torch.optim.Adam(model.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    schedule = torch.optim.lr_scheduler.StepLR(optimiser, step_size=20, gamma=0.7)
    started = time.monotonic()
    for epoch in range(args.epochs):
        losses = []
        for _ in range(args.batches):
            graph = train[int(rng.integers(len(train)))]
            d, v, m = sample_batch(graph, args.batch, frames, rng)
            loss = sequence_loss(model, graph, d, v, m, args.loss == "place")
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            losses.append(float(loss))
        schedule.step()
        line = f"epoch {epoch + 1}: loss {np.mean(losses):.3f}"
        if validate and ((epoch + 1) % 10 == 0 or epoch + 1 == args.epochs):
            scores = evaluate(model, validate)
            line += f", validation MNA {scores['mna']:.3f} OHA {scores['oha']:.3f}"
        print(f"{line} ({time.monotonic() - started:.0f} s)", flush=True)
    torch.save({"sizes": asdict(sizes), "state_dict": model.state_dict()}, args.out)
    print(f"train: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
