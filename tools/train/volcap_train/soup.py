"""Weight averaging ("model soup", Wortsman et al. 2022): the element-wise mean of the weights
of runs fine-tuned from one starting point, written as a light checkpoint. It costs nothing at
run time (one network, same MACs); whether it helps is measured like any run (point_iou, eval).

  python -m volcap_train.soup OUT.pt RUN_OR_CKPT RUN_OR_CKPT... --variant fourier-small [--weights 2,1,1]

Each input is a run folder (its ckpt.pt) or a checkpoint file, full or light. Inputs whose
weights differ in names or shapes are refused, naming the input and the tensor. BatchNorm
running statistics are averaged like the weights (exact for the mean, an approximation for the
variance, as in the paper's uniform soups), or, with `--bn-data DS`, recomputed for the soup's
own weights on `--bn-images` seeded training images of a dataset (its cached items, as the
trainer reads them: `--seg` and `--segment-passes` name the cache), as the trainer does for its
moving average (`--ema-bn-images`): runs from other training seeds lie further apart than an
average's steps, and the mean of their statistics need not be their mean's.

  python -m volcap_train.soup OUT.pt RUN... --variant fourier-small --bn-data DS16 --seg ../../models/seg.onnx --segment-passes 2"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from . import light
from .runs import init_weights, recompute_bn


def load_weights(path: Path) -> dict:
    ck = path / "ckpt.pt" if path.is_dir() else path
    if not ck.exists():
        raise SystemExit(f"{path}: no checkpoint (a run folder with ckpt.pt, or a .pt file)")
    return init_weights(torch.load(ck, weights_only=False, map_location="cpu"), ck)


def average(sets: list[dict], weights: list[float], names: list[str]) -> dict:
    """The weighted mean of state dicts `sets` (weights normalised to sum 1); `names` name the
    inputs in errors."""
    if len(sets) < 2:
        raise SystemExit("soup: needs at least two inputs")
    if len(weights) != len(sets):
        raise SystemExit(f"soup: --weights has {len(weights)} values for {len(sets)} inputs")
    if any(not (w >= 0) for w in weights) or sum(weights) <= 0:
        raise SystemExit(f"soup: --weights must be >= 0 with a positive sum, got {weights}")
    base = sets[0]
    for s, n in zip(sets[1:], names[1:]):
        if s.keys() != base.keys():
            diff = sorted(set(s) ^ set(base))
            raise SystemExit(f"soup: {n} has other tensors than {names[0]}: {diff[:5]}")
        for t, v in s.items():
            if v.shape != base[t].shape:
                raise SystemExit(f"soup: {n}: tensor {t} has shape {tuple(v.shape)}, {names[0]} has {tuple(base[t].shape)}")
    total = float(sum(weights))
    out = {}
    for t in base:
        acc = torch.zeros_like(base[t], dtype=torch.float64)
        for s, w in zip(sets, weights):
            acc += s[t].double() * (w / total)
        out[t] = acc.float()
    return out


def bn_batches(data: Path, variant: str, seg: Path | None, passes: int, images: int, seed: int, batch: int = 8):
    """The encoder inputs of `images` training images of dataset `data` drawn by `seed`, in
    batches, read from its cached items (memory-mapped: only the drawn images are paged in)
    as the trainer gives them to the net without augmentation."""
    from .items import fourier_cache_path
    from .nets import encoder_input, fourier_variant

    k = fourier_variant(variant)[0]
    cache = fourier_cache_path(data, "train", k, seg, passes)
    if not cache.exists():
        raise SystemExit(f"--bn-data {data}: no cached training items {cache.name} (k {k}, seg {seg}, passes {passes}); a training run on it builds them")
    d = torch.load(cache, mmap=True, weights_only=False)
    n = min(images, len(d["rgb"]))
    if n < 1:
        raise SystemExit(f"--bn-images {images}: needs at least one image")
    idx = torch.randperm(len(d["rgb"]), generator=torch.Generator().manual_seed(seed))[:n].sort().values
    for s in range(0, n, batch):
        i = idx[s : s + batch]
        yield encoder_input(d["rgb"][i].float() / 255.0, d["mask"][i].float() / 255.0)


def with_bn_recomputed(weights: dict, variant: str, batches) -> tuple[dict, int, int]:
    """`weights` with the BatchNorm running statistics recomputed for them over `batches`
    (recompute_bn); returns them, how many BatchNorm layers there were and how many images
    the statistics saw."""
    from .nets import make_fourier

    net = make_fourier(variant)
    net.load_state_dict(weights)
    seen = [0]

    def counted():
        for b in batches:
            seen[0] += len(b)
            yield b

    with torch.no_grad():
        layers = recompute_bn(net, counted())
    return {n: v.detach().float().clone() for n, v in net.state_dict().items()}, layers, seen[0]


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.soup")
    ap.add_argument("out", type=Path)
    ap.add_argument("inputs", type=Path, nargs="+")
    ap.add_argument("--variant", required=True, help="the runs' --variant (recorded in the light checkpoint)")
    ap.add_argument("--weights", default=None, help="comma-separated weight per input (default: uniform)")
    ap.add_argument("--bn-data", type=Path, default=None, help="a dataset folder: recompute the soup's BatchNorm statistics on its training items instead of averaging them")
    ap.add_argument("--bn-images", type=int, default=800, help="with --bn-data: how many training images")
    ap.add_argument("--bn-seed", type=int, default=0, help="with --bn-data: the draw of the images")
    ap.add_argument("--seg", type=Path, default=None, help="with --bn-data: the segmentation model the items' masks came from (as the runs' --seg)")
    ap.add_argument("--segment-passes", type=int, default=1, help="with --bn-data: as the runs' --segment-passes")
    a = ap.parse_args(argv)
    try:
        weights = [float(w) for w in a.weights.split(",")] if a.weights else [1.0] * len(a.inputs)
    except ValueError:
        raise SystemExit(f"soup: --weights {a.weights!r}: not comma-separated numbers")
    names = [str(p) for p in a.inputs]
    soup = average([load_weights(p) for p in a.inputs], weights, names)
    bn = "BatchNorm statistics averaged"
    if a.bn_data is not None:
        soup, layers, seen = with_bn_recomputed(soup, a.variant, bn_batches(a.bn_data, a.variant, a.seg, a.segment_passes, a.bn_images, a.bn_seed))
        bn = f"BatchNorm statistics of {layers} layers recomputed on {seen} images of {a.bn_data}"
    light.save(a.out, soup, -1, a.variant)
    print(f"{a.out}: {a.variant}, mean of {len(a.inputs)} inputs, weights {weights}; {bn}")


if __name__ == "__main__":
    main()
