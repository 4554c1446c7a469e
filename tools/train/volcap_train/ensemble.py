"""An ensemble of Fourier nets as one ONNX file: the mean of their coefficient maps. The series
is linear in its coefficients, so this is the mean of the nets' occupancy fields, at N times
one net's encoder cost (a candidate for boards whose encoder runs on a GPU).

  python -m volcap_train.ensemble OUT.onnx RUN_OR_CKPT RUN_OR_CKPT... --variant fourier-small --like models/shape-NAME.fourier.onnx

The file takes the metadata of `--like` (the model it stands in for: its surface level, depth
frame, segmentation passes), its `volcap.run` naming the ensemble. Measured in
docs/eval/hands.md section 25 (five runs of one start: the hands lost further, not kept)."""
from __future__ import annotations

import argparse
from pathlib import Path

import onnx
import torch
from torch import nn

from .export import export
from .point_iou import load


class Ensemble(nn.Module):
    """The mean of `nets`' outputs for one input."""

    def __init__(self, nets):
        super().__init__()
        self.nets = nn.ModuleList(nets)

    def forward(self, x):
        return sum(n(x) for n in self.nets) / len(self.nets)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.ensemble")
    ap.add_argument("out", type=Path)
    ap.add_argument("inputs", type=Path, nargs="+")
    ap.add_argument("--variant", required=True, help="the runs' --variant")
    ap.add_argument("--like", type=Path, required=True, help="the exported model whose metadata the ensemble takes")
    a = ap.parse_args(argv)
    if len(a.inputs) < 2:
        raise SystemExit("ensemble: needs at least two inputs")
    if not a.like.exists():
        raise SystemExit(f"--like {a.like}: no such file")
    nets = [load(p, a.variant) for p in a.inputs]
    meta = {p.key.removeprefix("volcap."): p.value for p in onnx.load(str(a.like)).metadata_props}
    size = int(meta.get("input_size", 256))
    meta["run"] = f"ensemble of {len(nets)}: " + ", ".join(str(p) for p in a.inputs)
    export(Ensemble(nets), (torch.rand(1, 4, size, size),), ["image"], ["coeff"], a.out, meta, False)
    print(f"{a.out}: the mean of {len(nets)} {a.variant} nets")


if __name__ == "__main__":
    main()
