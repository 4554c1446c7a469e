"""The run folder and the shared resumable training loop (`train.py`'s subcommands each give
it a step and a validation): seeded, resumable from RUN/ckpt.pt with the same data order, a
progress bar, losses in RUN/log.csv, and the budget (steps, wall time and where it went,
hardware) in RUN/budget.json for the model card. Also `--device`, and the weights of a light
or full checkpoint for `--init`."""

from __future__ import annotations

import csv
import json
import os
import platform
import time
from pathlib import Path

import torch
from tqdm import tqdm


def device(choice: str) -> torch.device:
    """`--device`: `auto` (CUDA when present, else the CPU), `cpu` or `cuda`."""
    if choice == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if choice == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device (torch.cuda.is_available() is false)")
    return torch.device(choice)


def hardware():
    return {"cpu": platform.processor() or platform.machine(), "threads": torch.get_num_threads(), "torch": torch.__version__, "cuda": torch.cuda.is_available()}


def ema_weights(modules) -> dict | None:
    """The weights' moving average of a run trained with `--ema` (torch's AveragedModel state:
    the net's tensors under `module.`, its `n_averaged` dropped), or None without one."""
    ema = modules.get("ema") if isinstance(modules, dict) else None
    if not isinstance(ema, dict):
        return None
    return {n[len("module."):]: v for n, v in ema.items() if n.startswith("module.")}


def make_ema(net, decay: float):
    """`train --ema DECAY`: torch's AveragedModel of `net`, its weights and buffers (BatchNorm's
    running statistics) averaged e <- decay * e + (1 - decay) * w at every update, the first
    update a copy. A decay outside (0, 1) is refused by value."""
    if not 0.0 < decay < 1.0:
        raise SystemExit(f"--ema {decay}: the decay must be in (0, 1), e.g. 0.999")
    from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

    return AveragedModel(net, multi_avg_fn=get_ema_multi_avg_fn(decay), use_buffers=True)


def recompute_bn(net, batches) -> int:
    """The BatchNorm running statistics of `net` recomputed as plain averages over `batches`
    (an iterable of its inputs) in training mode, the weights untouched (torch's `update_bn`):
    an average of weights is not matched by the average of their statistics. Returns how many
    BatchNorm layers there were (0: `update_bn` has nothing to do and runs no batch)."""
    torch.optim.swa_utils.update_bn(batches, net)
    return sum(isinstance(m, torch.nn.modules.batchnorm._BatchNorm) for m in net.modules())


def run_net(modules) -> dict | None:
    """A run's net as it ships: the moving average when the run kept one (`--ema`), the
    trained weights otherwise."""
    if not isinstance(modules, dict):
        return None
    return ema_weights(modules) or modules.get("net")


def init_weights(ckpt, path) -> dict:
    """The net's weights (floating-point ones as f32, integer ones as they are) from a light checkpoint (models/checkpoints/*.pt:
    {"net": ...}) or from a run's full one ({"modules": {"net": ...}, "opt": ...}: the
    optimizer state is dropped; a run with `--ema` gives its moving average, the weights it
    ships); anything else is refused naming the file."""
    weights = None
    if isinstance(ckpt, dict):
        weights = ckpt["net"] if "net" in ckpt else run_net(ckpt.get("modules"))
    if not isinstance(weights, dict):
        raise SystemExit(f"--init {path}: neither a light checkpoint (key `net`) nor a run checkpoint (key `modules.net`)")
    return {n: (v.float() if v.is_floating_point() else v).cpu() for n, v in weights.items()}


class Run:
    def __init__(self, out: Path, args):
        self.out = out
        out.mkdir(parents=True, exist_ok=True)
        self.ckpt = out / "ckpt.pt"
        self.log = out / "log.csv"
        self.args = args
        # --max-minutes: the run's wall-clock budget (resumed runs count their earlier time);
        # `loop` sets t0 and stops at the budget with a checkpoint.
        minutes = getattr(args, "max_minutes", 0) or 0
        self.deadline = minutes * 60.0 if minutes > 0 else None
        self.t0 = time.time()

    def elapsed(self) -> float:
        return time.time() - self.t0

    def progress(self, step: int, steps: int) -> float:
        """How far through its budget the run is, in [0, 1]: the larger of the steps' and, with
        --max-minutes, the clock's share (so a learning-rate schedule anneals by the deadline)."""
        p = step / max(steps, 1)
        if self.deadline:
            p = max(p, self.elapsed() / self.deadline)
        return min(p, 1.0)

    def out_of_time(self) -> bool:
        return self.deadline is not None and self.elapsed() >= self.deadline

    def save(self, state):
        tmp = self.ckpt.with_suffix(".tmp")
        torch.save(state, tmp)
        os.replace(tmp, self.ckpt)  # atomic: a cut-off run never leaves half a checkpoint

    def load(self):
        # On the CPU whatever device wrote it (a GPU run resumed here, or the reverse).
        return torch.load(self.ckpt, weights_only=False, map_location="cpu") if self.ckpt.exists() else None

    def write_log(self, rows, header):
        new = not self.log.exists()
        with open(self.log, "a", newline="") as f:
            w = csv.writer(f)
            if new:
                w.writerow(header)
            w.writerows(rows)

    def finish(self, step, wall, extra):
        b = {"steps": step, "wall_s": round(wall, 1), "hardware": hardware(), "args": {k: str(v) for k, v in vars(self.args).items()}, **extra}
        (self.out / "budget.json").write_text(json.dumps(b, indent=2))
        return b


def loop(run: Run, modules, opt, steps, step_fn, eval_fn, extra_state=None, ckpt_every=100, header=("step", "loss")):
    """The shared resumable loop. step_fn(step) -> loss (float); eval_fn() -> dict.
    budget.json records where the wall time went (`time_s`: the steps, and the parts of them
    that step_fn measures in extra_state["parts"], the checkpoints, the validation; this
    invocation's, where `wall_s` counts a resumed run's earlier time too): a GPU run that is
    slower than its GPU says there which part holds it."""
    gen = extra_state["gen"]
    # A second generator on the training device (the augmentations' on a GPU), when there is one.
    agen = extra_state.get("agen")
    st = run.load()
    step, wall = 0, 0.0
    if st is not None:
        for name, m in modules.items():
            m.load_state_dict(st["modules"][name])
        opt.load_state_dict(st["opt"])
        gen.set_state(st["gen"])
        if agen is not None and "agen" in st:
            agen.set_state(st["agen"])
        torch.set_rng_state(st["torch_rng"])
        if "ohem" in st and extra_state.get("ohem") is not None:
            extra_state["ohem"].load_state_dict(st["ohem"])
        step, wall = st["step"], st["wall"]
        print(f"resuming {run.out} at step {step}/{steps}")
    rows = []
    bar = tqdm(total=steps, initial=step, desc=run.out.name, unit="step")
    t0 = time.time() - wall
    run.t0 = t0
    stopped = None
    spent = {"steps": 0.0, "checkpoints": 0.0, "validation": 0.0}
    while step < steps:
        for m in modules.values():
            m.train()
        ts = time.time()
        loss = step_fn(step)
        spent["steps"] += time.time() - ts
        step += 1
        rows.append((step, f"{loss:.6f}"))
        bar.update(1)
        bar.set_postfix(loss=f"{loss:.4f}")
        if run.out_of_time():
            stopped = f"--max-minutes {run.deadline / 60:g} reached at step {step}"
        if step % ckpt_every == 0 or step == steps or stopped:
            if (step == steps or stopped) and extra_state.get("before_last_checkpoint") is not None:
                # What the run finishes with before its last checkpoint (--ema: the average's
                # BatchNorm statistics recomputed), so that the checkpoint holds it.
                ts = time.time()
                extra_state["before_last_checkpoint"]()
                spent["finishing"] = time.time() - ts
            ts = time.time()
            state = {"modules": {n: m.state_dict() for n, m in modules.items()}, "opt": opt.state_dict(), "gen": gen.get_state(), "torch_rng": torch.get_rng_state(), "step": step, "wall": time.time() - t0}
            if agen is not None:
                state["agen"] = agen.get_state()
            if extra_state.get("ohem") is not None:
                state["ohem"] = extra_state["ohem"].state_dict()
            run.save(state)
            run.write_log(rows, header)
            rows = []
            spent["checkpoints"] += time.time() - ts
        if stopped:
            print(stopped)
            break
    bar.close()
    wall = time.time() - t0
    if st is not None and st["step"] >= steps:
        wall = st["wall"]
    for m in modules.values():
        m.eval()
    ts = time.time()
    with torch.no_grad():
        metrics = eval_fn()
    spent["validation"] = time.time() - ts
    # Parts of the steps' time that step_fn measured (extra_state "parts"), as "steps: PART".
    spent.update({f"steps: {k}": v for k, v in (extra_state.get("parts") or {}).items()})
    time_s = {k: round(v, 1) for k, v in spent.items()}
    b = run.finish(step, wall, {"val": metrics, "time_s": time_s, **({"stopped": stopped} if stopped else {})})
    print(json.dumps(b["val"]))
    return b
