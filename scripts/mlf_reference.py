#!/usr/bin/env python3
"""Reference multi-level features (MLF) of torchvision MobileNetV2, computed with PyTorch only.

This is the independent side of tests/onnx_parity.rs: it uses neither ONNX Runtime nor the
exported .onnx file nor any topoloc code. It builds torchvision's mobilenet_v2, loads the ImageNet
.pth weights, runs `features` block by block (the same block boundaries that
scripts/export_mobilenet_onnx.py exports as outputs `f{block}`), and for each tap in order:
`adaptive_avg_pool2d` to the grid, flatten channel-major, L2-normalise the level; the levels are
concatenated and printed to stdout as a JSON list of floats.

Preprocessing, in float32: RGB, x/255, then (x - mean) / std with the ImageNet mean and std.
No resizing is done here: give an image already at the network input size (320x240 for topoloc's
default). Resizing is OpenCV's job on the Rust side and is covered by other tests.

Run with Debian's interpreter (python3-torch, python3-torchvision):
  /usr/bin/python3 scripts/mlf_reference.py --weights mobilenet_v2-b0353104.pth \
      --image pattern.rgb --width 320 --height 240 --taps f6,f13,f17,f18 --grid 4 4
--image is raw packed RGB8 (width*height*3 bytes, rows top to bottom); a path ending in .png is
decoded (to RGB) with Pillow instead, and must then have the given width and height.
"""
import argparse
import json
import sys

import numpy as np
import torch
import torchvision

MEAN = (0.485, 0.456, 0.406)
STD = (0.229, 0.224, 0.225)


def parse_tap(name: str) -> int:
    if not name.startswith("f") or not name[1:].isdigit():
        raise SystemExit(f"tap '{name}' is not of the form f<block>")
    return int(name[1:])


def load_rgb(path: str, width: int, height: int) -> np.ndarray:
    if path.lower().endswith(".png"):
        from PIL import Image

        pixels = np.asarray(Image.open(path).convert("RGB"), dtype=np.uint8)
        if pixels.shape != (height, width, 3):
            raise SystemExit(f"{path} is {pixels.shape[1]}x{pixels.shape[0]}, not {width}x{height}")
        return pixels
    data = np.fromfile(path, dtype=np.uint8)
    if data.size != width * height * 3:
        raise SystemExit(f"{path} has {data.size} bytes, expected {width}x{height}x3")
    return data.reshape(height, width, 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--weights", required=True, help="mobilenet_v2-b0353104.pth")
    parser.add_argument("--image", required=True, help="raw RGB8 bytes (or a .png)")
    parser.add_argument("--width", type=int, required=True)
    parser.add_argument("--height", type=int, required=True)
    parser.add_argument("--taps", default="f6,f13,f17,f18", help="comma-separated f<block> names")
    parser.add_argument("--grid", type=int, nargs=2, default=(4, 4), metavar=("ROWS", "COLS"))
    args = parser.parse_args()

    taps = [parse_tap(t) for t in args.taps.split(",") if t]
    if not taps:
        raise SystemExit("no taps")
    rows, cols = args.grid

    torch.set_grad_enabled(False)
    model = torchvision.models.mobilenet_v2()
    model.load_state_dict(torch.load(args.weights, map_location="cpu"))
    features = model.features.eval()
    if max(taps) >= len(features):
        raise SystemExit(f"features has only {len(features)} blocks")

    pixels = load_rgb(args.image, args.width, args.height)
    x = torch.from_numpy(pixels.copy()).permute(2, 0, 1).unsqueeze(0).to(torch.float32) / 255.0
    mean = torch.tensor(MEAN, dtype=torch.float32).view(1, 3, 1, 1)
    std = torch.tensor(STD, dtype=torch.float32).view(1, 3, 1, 1)
    x = (x - mean) / std

    maps = {}
    for i, block in enumerate(features):
        x = block(x)
        if i in taps:
            maps[i] = x
        if i >= max(taps):
            break

    out = []
    for tap in taps:
        pooled = torch.nn.functional.adaptive_avg_pool2d(maps[tap], (rows, cols))
        level = pooled[0].reshape(-1).to(torch.float64)  # channel-major: c, row, col
        norm = torch.linalg.norm(level)
        if norm > 0:
            level = level / norm
        out.extend(level.tolist())
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
