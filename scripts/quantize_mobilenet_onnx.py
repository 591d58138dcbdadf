#!/usr/bin/env python3
"""Quantizes the MobileNetV2 multi-level export to int8 with ONNX Runtime's static quantization.

QDQ format, weights int8 per output channel, activations uint8 (u8s8: the form ONNX Runtime's
CPU kernels run fastest, with AVX2, AVX-512 VNNI or ARM dot products alike); the graph's inputs
and outputs stay float, named as in the f32 model, so the same code runs either file.

Three choices keep the f32 network's features (chosen on held-out crops of the same photographs,
sharp and blurred to Nordland's 64x32, by the cosine of each tap's pooled 4x4 vector to the f32
network's; BENCHMARKS.md, "int8 MobileNetV2"):
- the stem (the first convolution, on the normalised image) stays f32: quantizing the image and
  the stem's 3-channel weights cost most of the agreement (cosines 0.80-0.90 -> 0.95-0.98);
- the depthwise 3x3 convolutions stay f32 (a few percent of the network's operations; their
  per-channel weight ranges after batch-norm folding are the known weak spot of MobileNetV2
  post-training quantization), the 1x1 convolutions, which hold most of the time, run int8;
- activation ranges are the 99.99th percentile of the calibration values, not their extremes,
  so a few outliers do not coarsen every other value's steps.

Activation ranges are calibrated on photographs that ship inside a pinned wheel
(scikit-image 0.22.0's bundled data: street, rocket, motorcycles, faces, textures), cut into
fixed-seed crops at the network input size, in colour and in grey (KITTI-like cameras), under
brightness from night-dark to bright. Everything is seeded, so one input gives one file.

Run in a virtual environment with onnxruntime, onnx, numpy and pillow (scripts/setup-models.sh
makes one with pinned versions):
  python quantize_mobilenet_onnx.py --model M.onnx --photos-wheel SKIMAGE.whl --out M-int8.onnx
"""

import argparse
import io
import os
import tempfile
import zipfile

import numpy as np
import onnx
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process
from PIL import Image

# Natural photographs among the wheel's data files (not the synthetic charts).
PHOTOS = (
    "astronaut.png",
    "brick.png",
    "camera.png",
    "chelsea.png",
    "coffee.png",
    "coins.png",
    "grass.png",
    "gravel.png",
    "motorcycle_left.png",
    "motorcycle_right.png",
    "page.png",
    "rocket.jpg",
)
# topoloc's preprocessing of the ONNX backend (src/describe/onnx.rs): RGB / 255, ImageNet.
MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)
CALIBRATION_PERCENTILE = 99.99
INPUT_SIZE = (320, 240)  # width, height: the backend's default input
CROPS_PER_PHOTO = 6
# Brightness as a gain on linear-ish pixel values: night-dark, dim, as taken, bright.
GAINS = (0.12, 0.35, 1.0, 1.4)
SEED = 20261207


def calibration_inputs(wheel: str) -> list[np.ndarray]:
    """Fixed-seed crops of the wheel's photographs, as the backend's input tensors."""
    rng = np.random.default_rng(SEED)
    inputs = []
    with zipfile.ZipFile(wheel) as z:
        for name in PHOTOS:
            photo = Image.open(io.BytesIO(z.read(f"skimage/data/{name}"))).convert("RGB")
            w, h = photo.size
            for k in range(CROPS_PER_PHOTO):
                # A crop of 50-100% of the shorter side at the input's aspect, anywhere.
                scale = rng.uniform(0.5, 1.0)
                ch = int(min(h, w * INPUT_SIZE[1] / INPUT_SIZE[0]) * scale)
                cw = int(ch * INPUT_SIZE[0] / INPUT_SIZE[1])
                x0 = int(rng.integers(0, w - cw + 1))
                y0 = int(rng.integers(0, h - ch + 1))
                crop = photo.crop((x0, y0, x0 + cw, y0 + ch)).resize(INPUT_SIZE, Image.BILINEAR)
                if k % 2 == 1:  # grey cameras give equal channels
                    crop = crop.convert("L").convert("RGB")
                gain = GAINS[(k + PHOTOS.index(name)) % len(GAINS)]
                pixels = np.clip(np.asarray(crop, dtype=np.float32) * gain, 0, 255).round()
                x = (pixels / 255.0 - MEAN) / STD
                inputs.append(np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32))
    return inputs


def groups(node) -> int:
    """A convolution's `group` attribute (1 when absent): > 1 for depthwise convolutions."""
    return next((a.i for a in node.attribute if a.name == "group"), 1)


class Reader(CalibrationDataReader):
    def __init__(self, inputs: list[np.ndarray]) -> None:
        self.items = iter([{"input": x} for x in inputs])

    def get_next(self):
        return next(self.items, None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--model", required=True, help="the f32 mobilenetv2-mlf.onnx")
    parser.add_argument("--photos-wheel", required=True, help="scikit_image-0.22.0 wheel")
    parser.add_argument("--out", required=True, help="output .onnx path")
    args = parser.parse_args()
    inputs = calibration_inputs(args.photos_wheel)
    with tempfile.TemporaryDirectory() as tmp:
        prepared = os.path.join(tmp, "prepared.onnx")
        # Symbolic shape inference cannot follow the export's dynamic sizes; ONNX's is enough.
        quant_pre_process(args.model, prepared, skip_symbolic_shape=True)
        graph = onnx.load(prepared).graph
        stem = [n.name for n in graph.node if n.op_type == "Conv" and "input" in n.input]
        if len(stem) != 1:
            raise SystemExit(f"expected one convolution on 'input', found {stem}")
        depthwise = [n.name for n in graph.node if n.op_type == "Conv" and groups(n) > 1]
        quantize_static(
            prepared,
            args.out,
            Reader(inputs),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            calibrate_method=CalibrationMethod.Percentile,
            extra_options={"CalibPercentile": CALIBRATION_PERCENTILE},
            nodes_to_exclude=stem + depthwise,
        )
    print(
        f"quantized {args.model} -> {args.out} on {len(inputs)} calibration crops "
        f"(f32: the stem and {len(depthwise)} depthwise convolutions)"
    )


if __name__ == "__main__":
    main()
