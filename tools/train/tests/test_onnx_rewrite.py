"""The Resize rewrite keeps the function: a model with bilinear x2 upsamplings (PyTorch's
align_corners=False, ONNX half-pixel) gives the same outputs without any Resize node."""

import io

import numpy as np
import onnx
import onnxruntime as ort
import torch
import torch.nn as nn
import torch.nn.functional as F

from volcap_train.onnx_rewrite import resize_to_shifts


class Up(nn.Module):
    def __init__(self):
        super().__init__()
        self.c = nn.Conv2d(3, 5, 3, padding=1)

    def forward(self, x):
        y = F.interpolate(self.c(x), scale_factor=2.0, mode="bilinear", align_corners=False)
        # A non-square map, then an upsampling of another kind that must stay a Resize.
        y = F.interpolate(y, scale_factor=2.0, mode="bilinear", align_corners=False)
        return y, F.interpolate(x, scale_factor=2.0, mode="nearest")


def run(m: onnx.ModelProto, x: np.ndarray):
    return ort.InferenceSession(m.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"x": x})


def test_bilinear_x2_becomes_shifts_with_the_same_outputs():
    torch.manual_seed(0)
    buf = io.BytesIO()
    x = torch.randn(1, 3, 7, 5)
    torch.onnx.export(Up().eval(), (x,), buf, input_names=["x"], opset_version=17, dynamo=False)
    m = onnx.load_from_string(buf.getvalue())
    assert sum(n.op_type == "Resize" for n in m.graph.node) == 3
    want = run(m, x.numpy())
    m2, n = resize_to_shifts(onnx.load_from_string(buf.getvalue()))
    assert n == 2
    ops = [nd.op_type for nd in m2.graph.node]
    assert ops.count("Resize") == 1  # the nearest one is left alone
    got = run(m2, x.numpy())
    for a, b in zip(want, got):
        assert a.shape == b.shape
        assert np.abs(a - b).max() < 1e-5
    # Edges: a constant image stays constant, a ramp keeps its ends (clamped, not extrapolated).
    ramp = np.broadcast_to(np.linspace(-1, 1, 5, dtype=np.float32), (1, 3, 7, 5)).copy()
    for a, b in zip(run(m, ramp), run(m2, ramp)):
        assert np.abs(a - b).max() < 1e-5
    # Nothing to rewrite: the model comes back unchanged.
    m3, n3 = resize_to_shifts(m2)
    assert n3 == 0 and len(m3.graph.node) == len(m2.graph.node)
