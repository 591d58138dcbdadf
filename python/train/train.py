"""Trains the GRNN (model.py) on worlds extracted by dataset.py, on the CPU; export.py turns the
checkpoint into the ONNX file topoloc runs.

    /usr/bin/python3 python/train/train.py --data DIR --train 'train-*.npz,tr-t-*.npz' \\
        --validate 'tr-a-w3-*.npz' --out grnn.pt [--epochs 60] [--seed 1]

A sample is a sequence of 10-20 consecutive frames of one trajectory (`--frames`), run frame by
frame through the candidate windows of window.py from a zero state; a batch is `--batch`
sequences of one world. The loss is the negative log-likelihood of the ground-truth place (the
view posterior summed over the place's views) on frames where a place is visible and in the
window, averaged. The seed's optimiser: Adam, weight decay 1e-3, lr 1e-4
times 0.7 every 20 epochs, batch 32 sequences; an epoch is `--batches` batches.
Validation reports MNA (the most probable place is the true place) and OHA (it is the true
place or a graph neighbour) over whole trajectories run frame by frame, every 10 epochs; the
weights that validated best are kept. The validation worlds (default Tr-A world 3) are none of
the ablation's (worlds 0-2 of each split, Test worlds 6 and up).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import dataset  # noqa: E402
import window  # noqa: E402
from model import GRNN, Sizes, map_statistics  # noqa: E402


class Graph:
    """A world's tensors and window selection, built once."""

    def __init__(self, world: dataset.World) -> None:
        self.world = world
        self.nodes = torch.from_numpy(world.view_descriptors)
        edges = dataset.micro_edges(world.view_place, world.view_slot, world.place_edges)
        self.windows = window.Windows(world.view_place, edges, world.place_edges)
        self.adjacent = np.eye(self.windows.places, dtype=bool)
        for p, q in world.place_edges:
            self.adjacent[p, q] = self.adjacent[q, p] = True


def load_worlds(data: Path, patterns: str) -> list[Graph]:
    paths = sorted({p for pattern in patterns.split(",") for p in data.glob(pattern)})
    if not paths:
        raise SystemExit(f"train: no dataset matches {patterns!r} in {data}")
    return [Graph(dataset.load(p)) for p in paths]


@dataclass
class Sequence:
    """Consecutive frames of one trajectory: descriptors, true places, frames to score."""

    frames: NDArray[np.float32]
    places: NDArray[np.int64]
    scored: NDArray[np.bool_]


def sample_sequences(
    graph: Graph, count: int, frames: tuple[int, int], rng: np.random.Generator
) -> list[Sequence]:
    out = []
    for _ in range(count):
        length = int(rng.integers(frames[0], frames[1] + 1))
        candidates = [t for t in graph.world.trajectories if len(t.place) >= length]
        t = candidates[int(rng.integers(len(candidates)))]
        s = int(rng.integers(0, len(t.place) - length + 1))
        scored = t.visible[s : s + length] & (t.place[s : s + length] >= 0)
        out.append(Sequence(t.frames[s : s + length], t.place[s : s + length], scored))
    return out


@dataclass
class Run:
    """A sequence run frame by frame: the summed loss of its scored frames and their count,
    the frames whose most probable place is the true one (or one hop from it), and those whose
    true place was in the window."""

    loss: Tensor
    scored: int = 0
    hits: int = 0
    one_hop: int = 0
    in_window: int = 0


def run_sequence(model: GRNN, graph: Graph, seq: Sequence) -> Run:
    """Runs `seq` from a zero state through the windows; the loss is the negative
    log-likelihood of the true place (its views' posterior summed) where it is in the window."""
    run = Run(torch.zeros(()))
    previous: dict[int, float] | None = None
    before: NDArray[np.int64] | None = None
    state = torch.zeros(1, 0, model.sizes.state)
    for k in range(len(seq.places)):
        similarity = graph.world.view_descriptors @ seq.frames[k]
        stats = map_statistics(torch.from_numpy(similarity)[None])
        w = graph.windows.choose(similarity, previous)
        state = window.carry_state(state, before if before is not None else w.views[:0], w.views)
        frame = torch.from_numpy(seq.frames[k : k + 1])
        logits, state = model(graph.nodes[w.views], w.edges, frame, state, stats)
        previous, before = window.place_posterior(w, logits), w.views
        if not seq.scored[k]:
            continue
        truth = int(seq.places[k])
        best = max(previous, key=lambda p: previous[p])
        run.scored += 1
        run.hits += best == truth
        run.one_hop += bool(graph.adjacent[best, truth])
        if truth in previous:
            run.in_window += 1
            views = torch.log_softmax(logits[0], dim=0)
            mask = torch.from_numpy(w.places == truth)
            run.loss = run.loss - torch.logsumexp(views[mask], dim=0)
    return run


@torch.no_grad()
def evaluate(model: GRNN, graphs: list[Graph]) -> dict[str, float]:
    """MNA, OHA and window recall over every trajectory, run frame by frame from a zero state."""
    model.eval()
    total = Run(torch.zeros(()))
    for g in graphs:
        for t in g.world.trajectories:
            r = run_sequence(model, g, Sequence(t.frames, t.place, t.visible & (t.place >= 0)))
            total.scored += r.scored
            total.hits += r.hits
            total.one_hop += r.one_hop
            total.in_window += r.in_window
    model.train()
    n = max(total.scored, 1)
    return {"mna": total.hits / n, "oha": total.one_hop / n, "window": total.in_window / n}


@dataclass
class Schedule:
    """What one training run does: epochs of `batches` batches of `batch` sequences of
    `frames` frames; Adam at `lr`, times `gamma` every `lr_step` epochs; validation every
    `validate_every` epochs (and after the last), keeping the weights that validated best."""

    epochs: int = 60
    batches: int = 20
    batch: int = 32
    frames: tuple[int, int] = (10, 20)
    lr: float = 1e-4
    weight_decay: float = 1e-3
    lr_step: int = 20
    gamma: float = 0.7
    validate_every: int = 10


def fit(
    model: GRNN,
    train: list[Graph],
    validate: list[Graph],
    schedule: Schedule,
    rng: np.random.Generator,
) -> dict[str, float]:
    """Trains `model` in place; with `validate`, ends on the weights whose validation MNA + OHA
    was highest and returns their scores (else the last weights' training loss)."""
    optimiser = torch.optim.Adam(
        model.parameters(), lr=schedule.lr, weight_decay=schedule.weight_decay
    )
    steps = torch.optim.lr_scheduler.StepLR(
        optimiser, step_size=schedule.lr_step, gamma=schedule.gamma
    )
    started = time.monotonic()
    best: tuple[float, dict[str, Tensor], dict[str, float]] | None = None
    for epoch in range(1, schedule.epochs + 1):
        losses = []
        for _ in range(schedule.batches):
            graph = train[int(rng.integers(len(train)))]
            runs = [
                run_sequence(model, graph, q)
                for q in sample_sequences(graph, schedule.batch, schedule.frames, rng)
            ]
            loss = sum((r.loss for r in runs), torch.zeros(())) / max(
                1, sum(r.in_window for r in runs)
            )
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            losses.append(float(loss))
        steps.step()
        line = f"epoch {epoch}: loss {np.mean(losses):.3f}"
        if validate and (epoch % schedule.validate_every == 0 or epoch == schedule.epochs):
            scores = evaluate(model, validate)
            line += f", validation MNA {scores['mna']:.3f} OHA {scores['oha']:.3f}"
            line += f" (true place in the window: {scores['window']:.3f})"
            if best is None or scores["mna"] + scores["oha"] > best[0]:
                weights = {k: v.clone() for k, v in model.state_dict().items()}
                best = (scores["mna"] + scores["oha"], weights, {**scores, "epoch": epoch})
        print(f"{line} ({time.monotonic() - started:.0f} s)", flush=True)
    if best is None:
        return {"loss": float(np.mean(losses)) if schedule.epochs else float("nan")}
    model.load_state_dict(best[1])
    print(f"train: keeping the weights of epoch {best[2]['epoch']}", flush=True)
    return best[2]


def save(model: GRNN, out: Path) -> None:
    """The checkpoint export.py reads."""
    torch.save({"sizes": asdict(model.sizes), "state_dict": model.state_dict()}, out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--train", default="train-*.npz,tr-t-*.npz")
    parser.add_argument("--validate", default="tr-a-w3-*.npz")
    parser.add_argument("--out", type=Path, required=True)
    defaults = Schedule()
    parser.add_argument("--epochs", type=int, default=defaults.epochs)
    parser.add_argument("--batches", type=int, default=defaults.batches, help="per epoch")
    parser.add_argument("--batch", type=int, default=defaults.batch)
    parser.add_argument("--frames", default="10-20")
    parser.add_argument("--lr", type=float, default=defaults.lr)
    parser.add_argument("--lr-step", type=int, default=defaults.lr_step, help="epochs per x0.7")
    parser.add_argument("--weight-decay", type=float, default=defaults.weight_decay)
    parser.add_argument("--hidden", type=int, default=512)
    parser.add_argument("--neighbour", type=int, default=128)
    parser.add_argument("--state", type=int, default=512)
    parser.add_argument("--no-temporal", action="store_true")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1, help="1 keeps runs reproducible")
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(args.seed)
    lo, _, hi = args.frames.partition("-")
    schedule = Schedule(
        epochs=args.epochs,
        batches=args.batches,
        batch=args.batch,
        frames=(int(lo), int(hi or lo)),
        lr=args.lr,
        weight_decay=args.weight_decay,
        lr_step=args.lr_step,
    )
    train = load_worlds(args.data, args.train)
    validate = load_worlds(args.data, args.validate) if args.validate else []
    model = GRNN(Sizes(args.hidden, args.neighbour, args.state, 0.2, not args.no_temporal))
    fit(model, train, validate, schedule, rng)
    save(model, args.out)
    print(f"train: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
