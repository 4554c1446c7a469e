"""judge.sh: a run through the engine against the default. Its errors before any work (the
whole path, export and six evaluations, is minutes of engine time: run by hand, figures in
docs/eval/hands.md section 24)."""
import os
import subprocess
from pathlib import Path

JUDGE = Path(__file__).resolve().parents[1] / "judge.sh"


def run(args, env=None):
    e = dict(os.environ)
    e.pop("DATA", None)
    e.update(env or {})
    return subprocess.run(["bash", str(JUDGE), *args], capture_output=True, text=True, env=e)


def test_without_arguments_it_prints_its_use():
    r = run([])
    assert r.returncode == 2
    assert "tools/train/judge.sh RUN OUT" in r.stdout and "BASE_DIR" in r.stdout
    assert "EVAL_ARGS" in r.stdout and "JOBS" in r.stdout


def test_a_missing_dataset_and_a_folder_that_is_not_a_run_are_named(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    r = run([str(run_dir), str(tmp_path / "out")])
    assert r.returncode != 0 and "DATA" in r.stderr
    r = run([str(run_dir), str(tmp_path / "out")], {"DATA": str(tmp_path)})
    assert r.returncode == 2
    assert f"{run_dir}/ckpt.pt is missing" in r.stderr
    (run_dir / "ckpt.pt").write_bytes(b"")
    r = run([str(run_dir), str(tmp_path / "out")], {"DATA": str(tmp_path)})
    assert r.returncode == 2 and "budget.json is missing" in r.stderr
