"""Light checkpoints: a net's weights, its step and variant, without the optimizer or OHEM
state (a few MB, committed under models/checkpoints/), for `train --init` in a later session.

  python -m volcap_train.light RUN_DIR OUT.pt --variant fourier-small

writes the light checkpoint of a run folder's latest `ckpt.pt` (a run still going included:
the trainer replaces ckpt.pt atomically)."""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from .runs import init_weights


def save(path: Path, weights: dict, step: int, variant: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"net": weights, "step": step, "variant": variant}, path)


def from_run(run: Path, out: Path, variant: str) -> int:
    """The light checkpoint of `run`'s ckpt.pt written to `out`; returns its step."""
    ck = run / "ckpt.pt"
    if not ck.exists():
        raise SystemExit(f"{run}: no ckpt.pt (not a run folder, or no checkpoint written yet)")
    st = torch.load(ck, weights_only=False, map_location="cpu")
    step = int(st["step"]) if isinstance(st, dict) and "step" in st else -1
    save(out, init_weights(st, ck), step, variant)
    return step


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.light")
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--variant", required=True, help="the run's --variant (recorded in the light checkpoint)")
    a = ap.parse_args(argv)
    step = from_run(a.run, a.out, a.variant)
    print(f"{a.out}: {a.variant} at step {step}")


if __name__ == "__main__":
    main()
