#!/usr/bin/env python3
"""Exports torchvision MobileNetV2 (ImageNet weights) to ONNX with multi-level outputs.

The model returns the outputs of `features[i]` for every tap in TAPS, named `f{i}`, for an
input `input` of shape (N, 3, H, W) with dynamic N, H, W: RGB, x/255, normalised with the
ImageNet mean and std (the preprocessing is topoloc's, not part of the graph).

Run with Debian's interpreter, which has the CPU torch (python3-torch, python3-torchvision,
python3-onnx): /usr/bin/python3 scripts/export_mobilenet_onnx.py --weights W.pth --out M.onnx
"""
import argparse
import hashlib

import torch
import torchvision

# Every block boundary worth comparing; topoloc selects its taps by output name.
TAPS = (3, 6, 10, 13, 16, 17, 18)


class MultiLevel(torch.nn.Module):
    def __init__(self, features: torch.nn.Module) -> None:
        super().__init__()
        self.features = features

    def forward(self, x: torch.Tensor):
        outputs = []
        for i, block in enumerate(self.features):
            x = block(x)
            if i in TAPS:
                outputs.append(x)
        return tuple(outputs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--weights", required=True, help="mobilenet_v2-b0353104.pth")
    parser.add_argument("--out", required=True, help="output .onnx path")
    args = parser.parse_args()

    model = torchvision.models.mobilenet_v2()
    state = torch.load(args.weights, map_location="cpu")
    print(model.load_state_dict(state))
    net = MultiLevel(model.features).eval()
    names = [f"f{i}" for i in TAPS]
    dynamic = {"input": {0: "n", 2: "h", 3: "w"}}
    dynamic.update({n: {0: "n", 2: f"h{n}", 3: f"w{n}"} for n in names})
    with torch.no_grad():
        torch.onnx.export(
            net,
            torch.zeros(1, 3, 240, 320),
            args.out,
            input_names=["input"],
            output_names=names,
            dynamic_axes=dynamic,
            opset_version=13,
        )
    digest = hashlib.sha256(open(args.out, "rb").read()).hexdigest()
    print(f"wrote {args.out} (sha256 {digest})")


if __name__ == "__main__":
    main()
