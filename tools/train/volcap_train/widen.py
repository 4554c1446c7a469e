"""Widen a trained Fourier head without changing what it computes (Net2Net-style), so that a
wider encoder, or a series of more terms, starts from the narrow one's training instead of
from scratch:

  python -m volcap_train.widen --init ../../models/checkpoints/shape-fourier-small.pt --from fourier-small --to fourier-medium --out RUNS/widened.pt
  python -m volcap_train.widen --init ../../models/checkpoints/shape-fourier-small-seg2.pt --from fourier-small --to fourier-small-k31 --out RUNS/k31.pt

More terms (K0 -> K1 >= K0): the series' channels are c0, a1, b1, ..., so the narrow head's
2 K0 + 1 outputs are the first ones of the wide head's and the harmonics K0 + 1 .. K1 start at
zero (weights and bias of the last 1x1 convolution): the same occupancy along every ray.

Every conv keeps its old output channels' weights on its old input channels; its weights from
the new input channels are zero (so the old channels compute exactly what they did), and the
new output channels start from the wider net's fresh initialization. Batch norm keeps the old
channels' statistics and affine terms. The output is a light checkpoint for `train fourier
--init`. Concatenated skips are mapped segment by segment (the decoder reads
[upsampled, skip])."""
from __future__ import annotations

import argparse
from pathlib import Path

import torch
from torch import nn

from .nets import GEOM_VARIANTS, HR_VARIANTS, FourierNet, fourier_variant
from .runs import init_weights


def segments(name: str, c: int) -> list[int] | None:
    """Input-channel layout of a conv in units of c: the decoder's concatenations."""
    return {"d3.0": [8, 8], "d2.0": [8, 4], "d1.0": [4, 2], "d0.0": [2, 1]}.get(name)


def channel_map(old_len: int, new_len: int, seg: list[int] | None, c_old: int, c_new: int) -> torch.Tensor:
    """Index in the wide tensor of every old channel (old_len of them)."""
    if seg is None:
        return torch.arange(old_len)
    out, o, n = [], 0, 0
    for m in seg:
        out.append(torch.arange(m * c_old) + n)
        o += m * c_old
        n += m * c_new
    idx = torch.cat(out)
    assert len(idx) == old_len and n == new_len, (old_len, new_len, seg)
    return idx


def widen(narrow: FourierNet, wide: FourierNet, c_old: int, c_new: int) -> FourierNet:
    """Copy `narrow` into `wide` (same depth layout, c and K not smaller) preserving its
    function: the new harmonics' outputs (the head's last convolution past 2 K0 + 1) are zero."""
    old_mods = dict(narrow.named_modules())
    last = wide.out[-1]
    with torch.no_grad():
        for name, m in wide.named_modules():
            o = old_mods.get(name)
            if isinstance(m, nn.Conv2d):
                in_idx = channel_map(o.in_channels, m.in_channels, segments(name, c_old), c_old, c_new)
                n = o.out_channels
                m.weight[:n] = 0.0  # the old outputs read nothing from the new inputs ...
                m.weight[:n, in_idx] = o.weight  # ... and what they read before from the old
                if m.bias is not None:
                    m.bias[:n] = o.bias
                if m is last:
                    m.weight[n:] = 0.0
                    m.bias[n:] = 0.0
            elif isinstance(m, nn.BatchNorm2d):
                n = o.num_features
                m.weight[:n], m.bias[:n] = o.weight, o.bias
                m.running_mean[:n], m.running_var[:n] = o.running_mean, o.running_var
                m.num_batches_tracked.copy_(o.num_batches_tracked)
    return wide


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.widen")
    ap.add_argument("--init", type=Path, required=True, help="the narrow net: a light checkpoint or a run's ckpt.pt")
    ap.add_argument("--from", dest="src", default="fourier-small")
    ap.add_argument("--to", dest="dst", default="fourier-medium")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    (k0, c0, s0), (k1, c1, s1) = fourier_variant(args.src), fourier_variant(args.dst)
    if s0 != s1 or c1 < c0 or k1 < k0 or (c1, k1) == (c0, k0) or args.dst in GEOM_VARIANTS or args.src in GEOM_VARIANTS or args.dst in HR_VARIANTS:
        raise SystemExit(f"--from {args.src} (K {k0}, c {c0}) cannot be widened into --to {args.dst} (K {k1}, c {c1}): the same depth layout, c and K not smaller, one of them larger")
    narrow = FourierNet(k0, c0, s0)
    light = torch.load(args.init, weights_only=False)
    narrow.load_state_dict(init_weights(light, args.init))
    torch.manual_seed(args.seed)
    wide = widen(narrow, FourierNet(k1, c1, s1), c0, c1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"net": wide.state_dict(), "step": light.get("step", 0) if isinstance(light, dict) else 0, "widened_from": str(args.init)}, args.out)
    print(f"{args.src} (K {k0}, c {c0}) -> {args.dst} (K {k1}, c {c1}): {sum(p.numel() for p in wide.parameters())} parameters, written to {args.out}")


if __name__ == "__main__":
    main()
