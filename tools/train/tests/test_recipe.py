"""The training recipe end to end on a tiny configuration (issue 34, part 4): the bundle is
made from the release binary (`cargo build --release -p volcap`, which the test command builds
before this suite), stays under 64 MiB, and its run.sh generates the data with two generators,
trains from the bundled checkpoint and leaves a light checkpoint (<= 16 MiB) that `--init`
takes, with the log and budget. Without the binary: a failure under CI, a skip elsewhere."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from volcap_train.train import init_weights

REPO = Path(__file__).resolve().parents[3]
BINARY = REPO / "target" / "release" / "volcap"


def test_the_bundle_runs_the_recipe_end_to_end(tmp_path):
    if not BINARY.exists():
        if os.environ.get("CI"):
            pytest.fail(f"{BINARY} is missing under CI (cargo build --release -p volcap)")
        pytest.skip(f"{BINARY} not built")
    bundle, res = tmp_path / "bundle", tmp_path / "result"
    # The embedded runtime pack: CI has no ../shared (a real bundle packs the full folder).
    subprocess.run([str(REPO / "tools/train/recipe/make_bundle.sh"), str(bundle), "--assets", "embedded"], check=True)
    size = sum(p.stat().st_size for p in bundle.rglob("*") if p.is_file())
    assert size < 64 * 2**20, f"bundle {size} bytes"
    assert (bundle / "volcap.gz").exists() and not (bundle / "volcap").exists()
    env = {**os.environ, "PYTHON": sys.executable}
    # Run from elsewhere: the bundle must not need the checkout.
    subprocess.run([str(bundle / "run.sh"), str(res), "--tiny"], check=True, env=env, cwd=tmp_path)
    ck = res / "checkpoint.pt"
    assert 0 < ck.stat().st_size <= 16 * 2**20
    light = torch.load(ck, weights_only=False)
    assert light["step"] == 3 and light["variant"] == "fourier-small"
    w = init_weights(light, ck)
    assert all(torch.isfinite(v).all() for v in w.values())
    rows = (res / "log.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 3, rows
    budget = json.loads((res / "budget.json").read_text())
    assert budget["steps"] == 3 and "cuda" in budget["hardware"]
    assert {"ds-0", "ds-1"} <= {p.name for p in res.iterdir()}
