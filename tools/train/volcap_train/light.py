"""Light checkpoints: a net's weights, its step and variant, without the optimizer or OHEM
state (a few MB, committed under models/checkpoints/), for `train --init` in a later session.

  python -m volcap_train.light RUN_DIR OUT.pt --variant fourier-small [--half]

writes the light checkpoint of a run folder's latest `ckpt.pt` (a run still going included:
the trainer replaces ckpt.pt atomically). `--half` (export's `--light-half`) keeps the
floating-point tensors as float16, half the bytes (a medium net's 3.8 MB -> 1.9 MB, so it fits
the tree's budget): weights rounded by 2^-11 of their value (2^-25 below 2^-14) that `--init`
only starts from (`runs.init_weights` reads them back as f32; fourier-medium's run (36): its
coefficient maps move by 0.3 % of their RMS). A tensor float16 cannot hold (beyond its range,
or a nonzero value it would flush to zero) stays f32."""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from .runs import init_weights


def half_or_f32(t: torch.Tensor) -> torch.Tensor:
    """`t` as float16 where that keeps every value finite and every nonzero value nonzero
    (else as it is); integer tensors (BatchNorm's step count) as they are."""
    if not t.is_floating_point():
        return t
    h = t.detach().to(torch.float16)
    if not torch.isfinite(h).all() or bool(((h == 0) & (t != 0)).any()):
        return t
    return h


def save(path: Path, weights: dict, step: int, variant: str, half: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if half:
        weights = {n: half_or_f32(v) for n, v in weights.items()}
    torch.save({"net": weights, "step": step, "variant": variant, "dtype": "float16" if half else "float32"}, path)


def from_run(run: Path, out: Path, variant: str, half: bool = False) -> int:
    """The light checkpoint of `run`'s ckpt.pt written to `out`; returns its step."""
    ck = run / "ckpt.pt"
    if not ck.exists():
        raise SystemExit(f"{run}: no ckpt.pt (not a run folder, or no checkpoint written yet)")
    st = torch.load(ck, weights_only=False, map_location="cpu")
    step = int(st["step"]) if isinstance(st, dict) and "step" in st else -1
    save(out, init_weights(st, ck), step, variant, half)
    return step


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.light")
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--variant", required=True, help="the run's --variant (recorded in the light checkpoint)")
    ap.add_argument("--half", action="store_true", help="float16 weights: half the bytes (see the module's text)")
    a = ap.parse_args(argv)
    step = from_run(a.run, a.out, a.variant, a.half)
    print(f"{a.out}: {a.variant} at step {step}")


if __name__ == "__main__":
    main()
