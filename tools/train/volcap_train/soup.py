"""Weight averaging ("model soup", Wortsman et al. 2022): the element-wise mean of the weights
of runs fine-tuned from one starting point, written as a light checkpoint. It costs nothing at
run time (one network, same MACs); whether it helps is measured like any run (point_iou, eval).

  python -m volcap_train.soup OUT.pt RUN_OR_CKPT RUN_OR_CKPT... --variant fourier-small [--weights 2,1,1]

Each input is a run folder (its ckpt.pt) or a checkpoint file, full or light. Inputs whose
weights differ in names or shapes are refused, naming the input and the tensor. BatchNorm
running statistics are averaged like the weights (exact for the mean, an approximation for the
variance, as in the paper's uniform soups)."""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from . import light
from .runs import init_weights


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


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.soup")
    ap.add_argument("out", type=Path)
    ap.add_argument("inputs", type=Path, nargs="+")
    ap.add_argument("--variant", required=True, help="the runs' --variant (recorded in the light checkpoint)")
    ap.add_argument("--weights", default=None, help="comma-separated weight per input (default: uniform)")
    a = ap.parse_args(argv)
    try:
        weights = [float(w) for w in a.weights.split(",")] if a.weights else [1.0] * len(a.inputs)
    except ValueError:
        raise SystemExit(f"soup: --weights {a.weights!r}: not comma-separated numbers")
    names = [str(p) for p in a.inputs]
    soup = average([load_weights(p) for p in a.inputs], weights, names)
    light.save(a.out, soup, -1, a.variant)
    print(f"{a.out}: {a.variant}, mean of {len(a.inputs)} inputs, weights {weights}")


if __name__ == "__main__":
    main()
