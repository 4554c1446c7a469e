#!/usr/bin/env bash
# The Python half of the test suite: OHEM, SoftZ, crop rule, export round trip
# (PyTorch vs onnxruntime) and the committed models against their golden vectors.
# Creates tools/train/.venv from requirements.txt on first use (PyTorch from PyPI, ~3 GB).
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c "import torch, onnxruntime, onnx, safetensors, tqdm, pytest, tflite, PIL" 2>/dev/null; then
  "$PY" -m venv .venv
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q -r requirements.txt
fi
exec .venv/bin/python -m pytest -q "$@"
