"""Exports a GRNN checkpoint of train.py to the ONNX file topoloc's estimator runs.

    /usr/bin/python3 python/train/export.py grnn.pt grnn.onnx [--f16]

The contract the Rust estimator checks (names, element types, ranks; N, M, B dynamic):
- inputs: `nodes` float32 (N, D), the unit-norm descriptors of the window's views
  (window.py); `edges` int64 (2, M), the micro edges between them (dataset.micro_edges);
  `frame` float32 (B, D), the frames' unit-norm descriptors; `state` float32 (B, N, S), zeros
  at a sequence's start; `stats` float32 (B, 3), the max, mean and standard deviation of the
  frame's cosine over the whole map's views;
- outputs: `logits` float32 (B, N) (a softmax over the nodes gives the view posterior);
  `new_state` float32 (B, N, S);
- metadata: `topoloc.model` = "grnn", `topoloc.state` = S, `topoloc.temporal` = 0 or 1,
  `topoloc.features` = "cosine,cosine-max,zscore", `topoloc.max_nodes` = the most nodes one
  step accepts (`--max-nodes`, default 2048: a window of 40 places of 50 views; the estimator
  refuses maps whose largest window is bigger, since the step's cost and its (N, N)
  adjacency grow with its square).
With --f16 the weights are stored as float16 and cast to float32 inside the graph (inputs and
outputs stay float32).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from model import GRNN, Sizes, map_statistics  # noqa: E402

INPUTS = ["nodes", "edges", "frame", "state", "stats"]
OUTPUTS = ["logits", "new_state"]
OPSET = 16  # ScatterElements with reduction=add


def load_checkpoint(path: Path) -> GRNN:
    checkpoint = torch.load(path, map_location="cpu")
    model = GRNN(Sizes(**checkpoint["sizes"]))
    model.load_state_dict(checkpoint["state_dict"])
    return model.eval()


def register_scatter_add() -> None:
    """Exports `scatter_add` as ScatterElements with reduction "add". torch 1.13's own symbolic
    refuses an index whose static shape it cannot prove equal to the source's (ours is an
    `expand` of the edge targets, equal at run time)."""
    from torch.onnx import symbolic_helper

    @symbolic_helper.parse_args("v", "i", "v", "v")
    def scatter_add(g, data, dim, index, src):  # torch calls it with graph values
        return g.op("ScatterElements", data, index, src, axis_i=dim, reduction_s="add")

    torch.onnx.register_custom_op_symbolic("aten::scatter_add", scatter_add, OPSET)


def restore_state_input(proto, width: int) -> None:
    """torch's exporter drops an input the graph never reads: a network trained without the
    temporal module (`train.py --no-temporal`) ignores `state`. The contract has the same inputs
    for every model, so the input is put back in its place, unread."""
    import onnx

    inputs = list(proto.graph.input)
    if "state" in [i.name for i in inputs]:
        return
    shape = ["b", "n", width]
    inputs.insert(
        INPUTS.index("state"),
        onnx.helper.make_tensor_value_info("state", onnx.TensorProto.FLOAT, shape),
    )
    del proto.graph.input[:]
    proto.graph.input.extend(inputs)


def export(model: GRNN, out: Path, f16: bool, max_nodes: int = 2048) -> None:
    import onnx  # Debian's python3-onnx

    register_scatter_add()

    n, dim, state = 6, 8, model.sizes.state
    nodes = torch.nn.functional.normalize(torch.randn(n, dim), dim=1)
    edges = torch.tensor([[0, 1, 2, 3, 4, 5], [1, 0, 3, 2, 5, 4]], dtype=torch.int64)
    frame = torch.nn.functional.normalize(torch.randn(1, dim), dim=1)
    zeros = torch.zeros(1, n, state)
    stats = map_statistics(frame @ nodes.T)
    dynamic = {
        "nodes": {0: "n", 1: "d"},
        "edges": {1: "m"},
        "frame": {0: "b", 1: "d"},
        "state": {0: "b", 1: "n"},
        "stats": {0: "b"},
        "logits": {0: "b", 1: "n"},
        "new_state": {0: "b", 1: "n"},
    }
    torch.onnx.export(
        model,
        (nodes, edges, frame, zeros, stats),
        str(out),
        input_names=INPUTS,
        output_names=OUTPUTS,
        dynamic_axes=dynamic,
        opset_version=OPSET,
    )
    proto = onnx.load(str(out))
    restore_state_input(proto, state)
    if f16:
        from onnx import numpy_helper

        for init in list(proto.graph.initializer):
            array = numpy_helper.to_array(init)
            if array.dtype.name != "float32":
                continue
            half = numpy_helper.from_array(array.astype("float16"), init.name + "_f16")
            proto.graph.initializer.remove(init)
            proto.graph.initializer.append(half)
            cast = onnx.helper.make_node(
                "Cast", [half.name], [init.name], to=onnx.TensorProto.FLOAT
            )
            proto.graph.node.insert(0, cast)
    meta = {
        "topoloc.model": "grnn",
        "topoloc.state": str(state),
        "topoloc.temporal": str(int(model.sizes.temporal)),
        "topoloc.features": "cosine,cosine-max,zscore",
        "topoloc.max_nodes": str(max_nodes),
    }
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(proto)
    onnx.save(proto, str(out))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--f16", action="store_true", help="float16 weights")
    parser.add_argument("--max-nodes", type=int, default=2048, help="most nodes per step")
    args = parser.parse_args()
    export(load_checkpoint(args.checkpoint), args.out, args.f16, args.max_nodes)
    print(f"export: {args.out} ({args.out.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
