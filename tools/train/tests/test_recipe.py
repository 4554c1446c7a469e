"""The training recipe end to end on a tiny configuration (issue 34, part 4): the bundle is
made from the release binary (`cargo build --release -p volcap`, which the test command builds
before this suite), stays under 64 MiB, and its run.sh generates the data with two generators,
trains from a start checkpoint (`--init`; the bundled one by default) and leaves a light checkpoint (<= 16 MiB) that `--init`
takes, with the log and budget. Without the binary: a failure under CI, a skip elsewhere."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from volcap_train.nets import make_fourier
from volcap_train.runs import ema_weights, init_weights

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
    # (--sync-parts: the parts' clocks with the device drained at their edges; a no-op here.
    # --geom-weight: the training-only surfaces head goes through the whole recipe too, and
    # stays out of the light checkpoint, which holds the series network only.)
    # --init: a start checkpoint named from the caller's directory (the two-pass network's);
    # --amp bf16: the steps' forward in bfloat16 through the whole recipe; --teacher: distilling
    # the committed fourier-medium beside the truth.
    (tmp_path / "start").mkdir()
    (tmp_path / "start" / "seg2.pt").write_bytes((REPO / "models/checkpoints/shape-fourier-small-seg2.pt").read_bytes())
    missing = subprocess.run([str(bundle / "run.sh"), str(tmp_path / "refused"), "--tiny", "--init", "start/none.pt"], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert missing.returncode == 2 and "--init start/none.pt: no such checkpoint" in missing.stderr, missing.stderr
    subprocess.run([str(bundle / "run.sh"), str(res), "--tiny", "--init", "start/seg2.pt", "--", "--sync-parts", "--geom-weight", "0.1", "--amp", "bf16", "--ema", "0.5", "--teacher", str(REPO / "models/checkpoints/shape-fourier-medium.pt")], check=True, env=env, cwd=tmp_path)
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
    assert budget["args"]["sync_parts"] == "True", budget["args"]
    assert budget["args"]["geom_weight"] == "0.1", budget["args"]
    assert budget["args"]["amp"] == "bf16", budget["args"]
    # --teacher: the committed fourier-medium distilled through the whole recipe.
    assert budget["args"]["teacher"].endswith("shape-fourier-medium.pt") and budget["args"]["teacher_weight"] == "1.0", budget["args"]
    assert budget["args"]["init"] == str(tmp_path / "start" / "seg2.pt"), budget["args"]
    assert not any(n.startswith("geom") for n in w), sorted(w)[:5]
    # --ema: the run keeps the weights' moving average beside them, and the light checkpoint
    # (what ships and what --init resumes) is the average, not the last step's weights.
    assert budget["args"]["ema"] == "0.5", budget["args"]
    run = torch.load(res / "run" / "ckpt.pt", weights_only=False)["modules"]
    avg = ema_weights(run)
    assert avg.keys() == w.keys() and all(torch.equal(w[n], avg[n].float()) for n in w)
    assert any(not torch.equal(run["net"][n].float(), w[n]) for n in w if w[n].is_floating_point())
    assert {"ds-0", "ds-1"} <= {p.name for p in res.iterdir()}
    # The log says where the training's time went (the batches made among the steps).
    log = (res / "recipe.log").read_text()
    assert "time_s" in log and '"steps: batch"' in log, log[-2000:]


def test_a_lean_bundle_in_the_checkout_runs_within_its_time_box(tmp_path):
    """The lent machine's form (make_bundle.sh --lean): only the packed binary and run.sh, in
    the checkout's root, the Python package, segmentation and start checkpoint taken from the
    checkout; --minutes-train stops training at its budget with a checkpoint and says so."""
    if not BINARY.exists():
        if os.environ.get("CI"):
            pytest.fail(f"{BINARY} is missing under CI (cargo build --release -p volcap)")
        pytest.skip(f"{BINARY} not built")
    bundle, res = REPO / f".recipe-test-{os.getpid()}", tmp_path / "result"
    try:
        subprocess.run([str(REPO / "tools/train/recipe/make_bundle.sh"), str(bundle), "--lean"], check=True)
        # The whole wardrobe travels as a pack where the MakeHuman data is here (not in CI).
        wardrobe = (REPO / "../shared/data/makehuman/3dobjs/base.obj").exists()
        expected = ["COMMIT", "run.sh", "volcap.xz"] + (["assets.pack.xz"] if wardrobe else [])
        assert sorted(p.name for p in bundle.iterdir()) == sorted(expected)
        if wardrobe:
            assert (bundle / "assets.pack.xz").stat().st_size < 5 * 2**20
        assert (bundle / "volcap.xz").stat().st_size < 20 * 2**20
        env = {**os.environ, "PYTHON": sys.executable}
        subprocess.run(
            # The surface variant (issue 34 part 3), its halves started from fourier-small's
            # checkpoint as the bundle carries it.
            [str(bundle / "run.sh"), str(res), "--tiny", "--poses", "3", "--hands-every", "2", "--minutes-data", "30", "--minutes-train", "0.0001", "--variant", "fourier-geom", "--", "--geom-weight", "1"],
            check=True, env=env, cwd=tmp_path,
        )
    finally:
        subprocess.run(["rm", "-rf", str(bundle)], check=True)
    budget = json.loads((res / "budget.json").read_text())
    assert budget["steps"] == 1 and "max-minutes" in budget["stopped"], budget
    # Three poses on two generators: a queue of three one-pose jobs, each over every subject
    # (a clock that stops the data early then costs poses, not subjects).
    for j in range(3):
        ds = res / f"ds-{j}"
        split = json.loads((ds / "dataset.json").read_text())["split"]
        assert len(split) == 2 and sorted(split.values()) == ["train", "val"], split
        for sid, part in split.items():
            assert len(list((ds / part / sid).glob("*.safetensors"))) == 2, (j, sid)  # 2 views
        # Dressed from the whole wardrobe where it travelled, else the runtime pack's 3 outfits.
        outfits = json.loads((ds / "dataset.json").read_text())["wardrobe"]["outfits"]
        assert len(outfits) == (9 if wardrobe else 3), outfits
        # --hands-every 2: the second job's hands drawn, the others' at rest.
        hands = json.loads((ds / "dataset.json").read_text())["hands"]
        assert hands == ("varied" if j == 1 else "rest"), (j, hands)
    assert "3 of 3 poses whole" in (res / "recipe.log").read_text()
    light = torch.load(res / "checkpoint.pt", weights_only=False)
    assert light["step"] == 1 and light["variant"] == "fourier-geom"
    make_fourier("fourier-geom").load_state_dict(init_weights(light, res / "checkpoint.pt"))
    # A lean bundle outside the checkout's root is refused by name.
    r = subprocess.run([str(REPO / "tools/train/recipe/make_bundle.sh"), str(tmp_path / "elsewhere"), "--lean"], capture_output=True, text=True)
    assert r.returncode == 2 and "checkout's root" in r.stderr
