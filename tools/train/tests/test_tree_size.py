"""The tracked tree stays small enough to travel: the device tool sends the working tree with
what a call carries, at most 64 MiB together, and the calls this project makes carry the packed
`volcap` (~12 MiB: tools/gpu_bench.sh, tools/train/recipe/make_bundle.sh --lean) and the Vulkan
loader (~1 MiB), the lean recipe also the whole wardrobe as xz (3.4 MiB; 15 MiB with the binary,
so at this limit 63 MiB in all). Reports are kept small by `python -m volcap_train.slim_docs`."""
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
LIMIT_MIB = 48.0


def test_the_tracked_tree_leaves_room_for_what_device_calls_carry():
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    names = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, check=True, capture_output=True).stdout.split(b"\0")
    sizes = Counter()
    for n in filter(None, names):
        p = REPO / n.decode()
        if p.is_file() and not p.is_symlink():
            top = "/".join(p.relative_to(REPO).parts[:2])
            sizes[top] += p.stat().st_size
    total = sum(sizes.values()) / 2**20
    biggest = ", ".join(f"{k} {v / 2**20:.1f}" for k, v in sizes.most_common(6))
    assert total > 1.0, "git ls-files listed almost nothing"
    assert total <= LIMIT_MIB, (
        f"the tracked tree is {total:.1f} MiB, over {LIMIT_MIB} (largest, MiB: {biggest}); "
        "slim the reports (python -m volcap_train.slim_docs DIR [--pack-json]) or drop superseded files"
    )
