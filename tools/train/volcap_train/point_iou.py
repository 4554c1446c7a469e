"""Point IoU of Fourier checkpoints on held-out whole bodies and on their upper-body crops
(train.fourier_upper_cached: the person cut by the frame's lower edge), at surface levels.

  python -m volcap_train.point_iou --data /work/data/ds2 --ckpt RUN [RUN ...] [--levels 0.5,0.55] [--seg ../../models/seg.onnx]

RUN is a run folder (its ckpt.pt) or a light checkpoint (models/checkpoints/*.pt). Depth in the
body frame (fourier.centre_depth), as the committed models are trained."""
from __future__ import annotations

import argparse
from pathlib import Path

import torch
from . import fourier as FO
from .nets import FourierNet, fourier_variant
from .train import fourier_cached, fourier_upper_cached, init_weights, predict_points


def load(path: Path, variant: str) -> FourierNet:
    k, width, shift = fourier_variant(variant)
    net = FourierNet(k, width, shift)
    ck = path / "ckpt.pt" if path.is_dir() else path
    net.load_state_dict(init_weights(torch.load(ck, weights_only=False), ck))
    return net.eval()


def point_iou(net: FourierNet, d: dict, levels) -> dict:
    """level -> (mean, mean of the 10 worst) per-image point IoU over the items of `d`."""
    occ, lab = predict_points(net, d["rgb"], d["mask"], d["points"], 16), d["occ"] > 0.5
    out = {}
    for level in levels:
        iou = FO.level_iou(occ, lab, level)
        out[level] = (iou.mean().item(), iou.sort().values[:10].mean().item())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.point_iou")
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--ckpt", type=Path, nargs="+", required=True)
    ap.add_argument("--variant", default="fourier-small")
    ap.add_argument("--split", default="val")
    ap.add_argument("--levels", default="0.5,0.55")
    ap.add_argument("--seg", type=Path, default=None, help="also score the whole bodies with this ONNX segmentation model's masks and crops (the engine's input; seg_masks)")
    args = ap.parse_args(argv)
    levels = [float(v) for v in args.levels.split(",")]
    k = fourier_variant(args.variant)[0]
    sets = {"whole": fourier_cached(args.data, args.split, k), "upper": fourier_upper_cached(args.data, args.split, k, 1)}
    if args.seg is not None:
        sets[f"whole, {args.seg.stem} masks"] = fourier_cached(args.data, args.split, k, args.seg)
    for d in sets.values():
        FO.centre_depth(d["coeff"], d["points"], k)
    for ck in args.ckpt:
        net = load(ck, args.variant)
        for name, d in sets.items():
            r = point_iou(net, d, levels)
            print(f"{ck} {name} ({len(d['rgb'])} images): " + ", ".join(f"level {lv}: {m:.3f} (worst-10 {w:.3f})" for lv, (m, w) in r.items()), flush=True)


if __name__ == "__main__":
    main()
