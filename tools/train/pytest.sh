#!/usr/bin/env bash
# The Python half of the test suite: OHEM, SoftZ, crop rule, export round trip
# (PyTorch vs onnxruntime) and the committed models against their golden vectors.
# Creates tools/train/.venv from requirements.txt on first use (PyTorch from PyPI, ~3 GB).
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "import torch, onnxruntime, onnx, safetensors, tqdm, pytest, tflite, PIL" 2>/dev/null; then
  "$PY" -m venv .venv
  # No download cache: PyPI's torch pulls ~3 GB of CUDA wheels that a cache would keep a
  # second copy of (CI ran out of disk here once). Triton, the GPU kernel compiler (1 GB),
  # is never loaded on the CPU (torch.compile's CPU backend writes C++), so it goes too.
  export PIP_NO_CACHE_DIR=1
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q -r requirements.txt
  .venv/bin/pip uninstall -q -y triton 2>/dev/null || true
fi
exec .venv/bin/python -m pytest -q "$@"
