#!/usr/bin/env bash
# The Python half of the test suite: OHEM, SoftZ, crop rule, export round trip
# (PyTorch vs onnxruntime) and the committed models against their golden vectors.
# Creates tools/train/.venv from requirements.txt on first use (PyTorch from PyPI with its
# CUDA wheels: about 4.5 GB installed).
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
IMPORTS="import torch, onnxruntime, onnx, safetensors, tqdm, pytest, tflite, PIL"
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "$IMPORTS" 2>/dev/null; then
  "$PY" -m venv .venv
  # CI ran out of disk here twice. What the install holds at its peak, kept small:
  # - no download cache (it kept a second copy of every wheel);
  # - one package at a time: pip keeps every wheel of one `pip install` until its end (3 GB
  #   of CUDA wheels beside what they unpack to); resolved once (`--dry-run --report`, from
  #   PyPI's metadata files, no wheel downloaded), then each package installed alone, without
  #   its dependencies (the resolution already named them);
  # - Triton, the GPU kernel compiler (1 GB), is left out: never loaded on the CPU
  #   (torch.compile's CPU backend writes C++; tests/test_amp.py compiles without it);
  # - pip's temporary files on this disk, beside the venv, not in a /tmp that may be small.
  export PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
  export TMPDIR="$PWD/.venv/pip-tmp"
  mkdir -p "$TMPDIR"
  fail() {
    # The tail of a CI log is what gets read: say what failed and how full the disks were.
    echo "pytest.sh: $1; free disk:" >&2
    df -h . /tmp "$HOME" >&2 || true
    du -sh .venv 2>/dev/null >&2 || true
    exit 1
  }
  .venv/bin/pip install -q --upgrade pip || fail "pip's own upgrade failed"
  .venv/bin/pip install -q --dry-run --ignore-installed --report "$TMPDIR/plan.json" -r requirements.txt \
    || fail "resolving requirements.txt failed"
  PLAN=$(.venv/bin/python - "$TMPDIR/plan.json" <<'PYEOF'
import json, sys
skip = {"triton"}
for item in json.load(open(sys.argv[1]))["install"]:
    meta = item["metadata"]
    if meta["name"].lower() not in skip:
        print(f'{meta["name"]}=={meta["version"]}')
PYEOF
  ) || fail "reading pip's plan failed"
  for spec in $PLAN; do
    .venv/bin/pip install -q --no-deps "$spec" || fail "installing $spec failed"
  done
  rm -rf "$TMPDIR"
  unset TMPDIR
  .venv/bin/python -c "$IMPORTS" || fail "the venv cannot import what the tests need"
fi
exec .venv/bin/python -m pytest -q "$@"
