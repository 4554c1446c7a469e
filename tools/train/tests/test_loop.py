"""The shared training loop: a checkpoint every --ckpt-every steps and at the end, every
step logged, and budget.json saying where the wall time went (steps, checkpoints,
validation: what a GPU run that is slower than its GPU reads first)."""
import argparse
import json

import torch

from volcap_train.runs import Run, loop


def sgd_step(net, opt) -> float:
    """One step of fitting net(1, 1) to 1: the loops' step_fn."""
    loss = (net(torch.ones(1, 2)) - 1.0).pow(2).sum()
    opt.zero_grad()
    loss.backward()
    opt.step()
    return float(loss)


def test_checkpoints_log_and_the_budgets_time_split(tmp_path, monkeypatch):
    saved = []
    save = Run.save

    def counting(self, state):
        saved.append(state["step"])
        save(self, state)

    monkeypatch.setattr(Run, "save", counting)
    torch.manual_seed(0)
    net = torch.nn.Linear(2, 1)
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    run = Run(tmp_path / "run", argparse.Namespace(max_minutes=0))

    parts = {"batch": 0.0}

    def step_fn(step):
        parts["batch"] += 0.1
        return sgd_step(net, opt)

    b = loop(run, {"net": net}, opt, 12, step_fn, lambda: {"ok": 1.0}, {"gen": torch.Generator().manual_seed(0), "parts": parts}, ckpt_every=5)
    assert saved == [5, 10, 12]
    rows = (run.out / "log.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 12
    budget = json.loads((run.out / "budget.json").read_text())
    assert budget == json.loads(json.dumps(b))
    t = budget["time_s"]
    assert set(t) == {"steps", "checkpoints", "validation", "steps: batch"}
    assert all(v >= 0.0 for v in t.values())
    assert t["steps"] + t["checkpoints"] + t["validation"] <= budget["wall_s"] + 1.0
    # What step_fn measured of its own time comes through as a part of the steps.
    assert t["steps: batch"] == round(12 * 0.1, 1)
    assert torch.load(run.out / "ckpt.pt", weights_only=False)["step"] == 12


def test_the_hook_before_the_last_checkpoint_runs_once_and_the_checkpoint_holds_it(tmp_path):
    # `train --ema`: the average's BatchNorm statistics are recomputed at the run's end, before
    # its last checkpoint (what export and --init read), and nowhere else.
    net = torch.nn.Linear(2, 1)
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    run = Run(tmp_path / "run", argparse.Namespace(max_minutes=0))
    calls = []

    def finish():
        calls.append(1)
        with torch.no_grad():
            net.bias.fill_(42.0)

    b = loop(run, {"net": net}, opt, 7, lambda step: sgd_step(net, opt), lambda: {"ok": 1.0}, {"gen": torch.Generator().manual_seed(0), "before_last_checkpoint": finish}, ckpt_every=3)
    assert calls == [1]
    assert torch.load(run.out / "ckpt.pt", weights_only=False)["modules"]["net"]["bias"].item() == 42.0
    assert "finishing" in b["time_s"]
