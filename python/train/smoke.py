"""The GRNN's whole path, small enough for CI: train -> export -> load -> localize.

    TOPOLOC_LIBRARY=target/release/libtopoloc.so /usr/bin/python3 python/train/smoke.py

On generated chain worlds (random unit view descriptors, 4 views per place; query frames are a
view plus noise, walking along the chain), it:
1. trains a tiny GRNN twice from the same seed and checks the weights are identical;
2. exports it to ONNX twice and checks the files are byte-identical;
3. loads it in the library (the topoloc package, through the C ABI) and localizes a walk, and
   checks that every frame's place posterior is PyTorch's own on the same windows (the library
   chooses the window, builds the micro graph and the features in Rust: this is where the two
   could drift apart), and that the trained model finds most places;
4. checks the typed errors: a file that is not ONNX, a model whose input names break the
   contract, a map larger than the model's `topoloc.max_nodes`, a map without edges, a missing
   model file.
Exits non-zero, naming the failed check, when any fails. Needs Debian's python3-torch and
python3-onnx (python/train/setup.sh).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import dataset  # noqa: E402  (imports the topoloc package of this checkout)
import export  # noqa: E402
import window  # noqa: E402
from model import GRNN, Sizes, map_statistics  # noqa: E402

import train  # noqa: E402

topoloc = dataset.topoloc
DIM = 32
VIEWS = 4
NOISE = 1.6


def unit(x: np.ndarray) -> np.ndarray:
    return (x / np.linalg.norm(x, axis=-1, keepdims=True)).astype(np.float32)


def chain_world(seed: int, places: int = 40, walks: int = 2) -> dataset.World:
    """A chain of `places` places; each walk goes along it, two or three frames per place."""
    rng = np.random.default_rng(seed)
    views = unit(rng.standard_normal((places * VIEWS, DIM)))
    view_place = np.repeat(np.arange(places), VIEWS).astype(np.int64)
    view_slot = np.tile(np.arange(VIEWS), places).astype(np.int64)
    edges = np.stack([np.arange(places - 1), np.arange(1, places)], axis=1).astype(np.int64)
    trajectories = []
    for _ in range(walks):
        place = np.repeat(np.arange(places), rng.integers(2, 4, places)).astype(np.int64)
        view = place * VIEWS + rng.integers(0, VIEWS, len(place))
        noise = unit(rng.standard_normal((len(place), DIM)))
        frames = unit(views[view] + NOISE * noise)
        visible = np.ones(len(place), dtype=bool)
        trajectories.append(dataset.Trajectory(frames, view, place, visible))
    return dataset.World(views, view_place, view_slot, edges, trajectories)


def library_map(world: dataset.World, with_edges: bool = True) -> topoloc.Map:
    with topoloc.MapBuilder("smoke", "chain", DIM) as b:
        for p in range(int(world.view_place.max()) + 1):
            b.add_place()
            for v in np.flatnonzero(world.view_place == p):
                b.add_view(p, world.view_descriptors[v])
        if with_edges:
            for p, q in world.place_edges:
                b.add_edge(int(p), int(q), 1.0)
        return b.build()


def trained(seed: int) -> GRNN:
    torch.manual_seed(seed)
    torch.set_num_threads(1)
    model = GRNN(Sizes(hidden=16, neighbour=8, state=16))
    graphs = [train.Graph(chain_world(s)) for s in (1, 2)]
    schedule = train.Schedule(epochs=12, batches=4, batch=8, frames=(8, 16), lr=1e-2)
    train.fit(model, graphs, [], schedule, np.random.default_rng(seed))
    return model.eval()


@torch.no_grad()
def pytorch_posteriors(model: GRNN, world: dataset.World, frames: np.ndarray) -> list[dict]:
    """Each frame's place posterior, computed as train.run_sequence does."""
    graph = train.Graph(world)
    previous, before = None, None
    state = torch.zeros(1, 0, model.sizes.state)
    out = []
    for frame in frames:
        similarity = world.view_descriptors @ frame
        stats = map_statistics(torch.from_numpy(similarity)[None])
        w = graph.windows.choose(similarity, previous)
        state = window.carry_state(state, before if before is not None else w.views[:0], w.views)
        logits, state = model(
            graph.nodes[w.views], w.edges, torch.from_numpy(frame[None]), state, stats
        )
        previous, before = window.place_posterior(w, logits), w.views
        out.append(previous)
    return out


def library_against_pytorch(model: GRNN, path: Path, world: dataset.World) -> tuple[float, int]:
    """Localizes the world's first walk through the C ABI with the exported `path`: the largest
    difference of a candidate's probability from PyTorch's, and the frames on the true place."""
    frames, truth = world.trajectories[0].frames, world.trajectories[0].place
    expected = pytorch_posteriors(model, world, frames)
    worst, hits = 0.0, 0
    with library_map(world) as m, topoloc.Localizer(
        m, mode="grnn", grnn_model_path=path, top_k=5, off_map_probability=0.0
    ) as loc:
        for i, frame in enumerate(frames):
            r = loc.process(frame, timestamp=0.1 * i)
            for c in r.candidates:
                worst = max(worst, abs(c.probability - expected[i].get(c.place, 0.0)))
            hits += r.place == truth[i]
    return worst, hits


def check(condition: bool, what: str) -> None:
    if not condition:
        raise SystemExit(f"smoke: FAILED: {what}")
    print(f"smoke: ok: {what}")


def expect_error(error: type, text: str, make) -> None:
    try:
        make()
    except error as e:
        check(text in str(e), f"{error.__name__} names {text!r} ({e})")
        return
    raise SystemExit(f"smoke: FAILED: expected {error.__name__} ({text!r})")


def main() -> int:
    model = trained(seed=3)
    again = trained(seed=3)
    same = all(
        torch.equal(a, b) for a, b in zip(model.state_dict().values(), again.state_dict().values())
    )
    check(same, "training twice from one seed gives identical weights")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        onnx_path, copy = folder / "grnn.onnx", folder / "copy.onnx"
        export.export(model, onnx_path, f16=False)
        export.export(again, copy, f16=False)
        check(onnx_path.read_bytes() == copy.read_bytes(), "exporting twice gives identical files")

        world = chain_world(seed=11, walks=1)
        frames = world.trajectories[0].frames
        truth = world.trajectories[0].place
        worst, hits = library_against_pytorch(model, onnx_path, world)
        check(
            worst < 2e-3, f"the library's posterior is PyTorch's (largest difference {worst:.2e})"
        )
        torch.manual_seed(5)
        stateless = GRNN(Sizes(hidden=16, neighbour=8, state=16, temporal=False)).eval()
        stateless_path = folder / "stateless.onnx"
        export.export(stateless, stateless_path, f16=False)
        worst_stateless, _ = library_against_pytorch(stateless, stateless_path, world)
        check(
            worst_stateless < 2e-3,
            "a network without the temporal module keeps the contract's inputs and runs in the "
            f"library as in PyTorch (largest difference {worst_stateless:.2e})",
        )
        single = np.mean(
            [
                world.view_place[np.argmax(world.view_descriptors @ f)] == t
                for f, t in zip(frames, truth)
            ]
        )
        accuracy = hits / len(frames)
        check(
            accuracy > single + 0.1,
            f"the trained GRNN ({accuracy:.2f}) beats single frames ({single:.2f}) on a noisy walk",
        )

        garbage = folder / "garbage.onnx"
        garbage.write_bytes(b"\x08\x07 this is not a protobuf model")
        with library_map(world) as m:
            expect_error(
                topoloc.ModelError,
                "not a loadable ONNX model",
                lambda: topoloc.Localizer(m, mode="grnn", grnn_model_path=garbage),
            )
            import onnx

            proto = onnx.load(str(onnx_path))
            proto.graph.input[0].name = "views"
            for node in proto.graph.node:
                node.input[:] = ["views" if n == "nodes" else n for n in node.input]
            renamed = folder / "renamed.onnx"
            onnx.save(proto, str(renamed))
            expect_error(
                topoloc.ModelError,
                "inputs are",
                lambda: topoloc.Localizer(m, mode="grnn", grnn_model_path=renamed),
            )
            small = folder / "small.onnx"
            export.export(model, small, f16=True, max_nodes=10)
            expect_error(
                topoloc.InvalidOptionError,
                "accepts at most 10",
                lambda: topoloc.Localizer(m, mode="grnn", grnn_model_path=small),
            )
            expect_error(
                topoloc.BackendUnavailableError,
                str(folder / "missing.onnx"),
                lambda: topoloc.Localizer(m, mode="grnn", grnn_model_path=folder / "missing.onnx"),
            )
        with library_map(world, with_edges=False) as bare:
            expect_error(
                topoloc.InvalidOptionError,
                "no graph",
                lambda: topoloc.Localizer(bare, mode="grnn", grnn_model_path=onnx_path),
            )
    print("smoke: train -> export -> load -> localize passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
