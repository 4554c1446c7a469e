"""Convert a TFLite image model (float, fp16 weights behind DEQUANTIZE) to ONNX, NHWC -> NCHW.

Written for MediaPipe's selfie segmentation (`mediapipe` 0.10.21 wheel), whose graph uses
CONV_2D, DEPTHWISE_CONV_2D, HARD_SWISH, RELU, LOGISTIC, ADD, MUL, AVERAGE_POOL_2D / MEAN,
RESIZE_BILINEAR and MediaPipe's custom `Convolution2DTransposeBias`; any other operator is
refused by name. The public converters (tflite2onnx 0.4.1) stop at HARD_SWISH and the custom
transpose convolution, hence this small one: every activation tensor is kept in NCHW, weights
are permuted once, and SAME padding becomes explicit pads (TFLite puts the odd pixel after).

The ONNX model takes `image` [1, 3, H, W] RGB in [0, 1] and returns the model's outputs in
NCHW. `tflite` (the flatbuffer schema package, Apache-2.0) reads the file.
"""

from __future__ import annotations

import struct

import numpy as np
import onnx

from .onnx_rewrite import resize_to_shifts
from onnx import TensorProto, helper, numpy_helper

try:
    import tflite
except ImportError as e:  # pragma: no cover - reported to the user
    raise SystemExit("the TFLite converter needs the `tflite` package: pip install tflite==2.18.0") from e

_OPNAMES = {v: k for k, v in tflite.BuiltinOperator.__dict__.items() if not k.startswith("_")}
_DTYPES = {tflite.TensorType.FLOAT32: np.float32, tflite.TensorType.FLOAT16: np.float16, tflite.TensorType.INT32: np.int32}


class Unsupported(ValueError):
    pass


def _fused(act: int, name: str, nodes: list, out: str) -> str:
    """Append the fused activation of a TFLite op; returns the tensor name to use."""
    if act == tflite.ActivationFunctionType.NONE:
        return out
    if act == tflite.ActivationFunctionType.RELU:
        nodes.append(helper.make_node("Relu", [name], [out]))
        return out
    raise Unsupported(f"fused activation {act}")


def _same_pads(in_hw, k_hw, stride_hw, dil_hw=(1, 1)):
    pads_b, pads_e = [], []
    for i, k, s, d in zip(in_hw, k_hw, stride_hw, dil_hw):
        ek = (k - 1) * d + 1
        out = -(-i // s)
        total = max((out - 1) * s + ek - i, 0)
        pads_b.append(total // 2)
        pads_e.append(total - total // 2)
    return pads_b + pads_e


def convert(path: str, *, producer: str = "volcap tflite_onnx") -> onnx.ModelProto:
    buf = open(path, "rb").read()
    model = tflite.Model.GetRootAsModel(buf, 0)
    if model.SubgraphsLength() != 1:
        raise Unsupported(f"{path}: {model.SubgraphsLength()} subgraphs (expected 1)")
    g = model.Subgraphs(0)

    def tensor(i):
        return g.Tensors(i)

    def shape(i):
        return [int(x) for x in tensor(i).ShapeAsNumpy()]

    def data(i):
        t = tensor(i)
        b = model.Buffers(t.Buffer())
        if b is None or b.DataLength() == 0:
            return None
        return np.frombuffer(b.DataAsNumpy().tobytes(), dtype=_DTYPES[t.Type()]).reshape(shape(i))

    consts: dict[int, np.ndarray] = {}
    for i in range(g.TensorsLength()):
        d = data(i)
        if d is not None:
            consts[i] = d.astype(np.float32) if d.dtype == np.float16 else d
    name = {i: f"t{i}" for i in range(g.TensorsLength())}
    nodes, inits = [], []

    def init(arr: np.ndarray, nm: str) -> str:
        inits.append(numpy_helper.from_array(np.ascontiguousarray(arr), nm))
        return nm

    def operand(i: int) -> str:
        """An elementwise operand: activations are NCHW already; a constant NHWC tensor is
        permuted (4-D) or kept (channel vectors broadcast the same way once reshaped)."""
        if i in consts:
            c = consts[i]
            if c.ndim == 4:
                c = c.transpose(0, 3, 1, 2)
            elif c.ndim == 1 and c.size > 1:
                c = c.reshape(1, -1, 1, 1)
            return init(c.astype(np.float32), f"k{i}")
        return name[i]

    for n in range(g.OperatorsLength()):
        op = g.Operators(n)
        oc = model.OperatorCodes(op.OpcodeIndex())
        code = max(oc.BuiltinCode(), oc.DeprecatedBuiltinCode())
        kind = _OPNAMES.get(code, str(code))
        ins = [int(x) for x in op.InputsAsNumpy()]
        outs = [int(x) for x in op.OutputsAsNumpy()]
        o = name[outs[0]]
        if kind == "DEQUANTIZE":
            src = ins[0]
            if src not in consts:
                raise Unsupported(f"op {n}: DEQUANTIZE of a non-constant tensor")
            consts[outs[0]] = consts[src].astype(np.float32)
            continue
        if kind in ("CONV_2D", "DEPTHWISE_CONV_2D"):
            opts_t = tflite.Conv2DOptions if kind == "CONV_2D" else tflite.DepthwiseConv2DOptions
            opts = opts_t()
            tab = op.BuiltinOptions()
            opts.Init(tab.Bytes, tab.Pos)
            w = consts[ins[1]]
            in_shape = shape(ins[0])  # NHWC
            if kind == "CONV_2D":
                wt = w.transpose(0, 3, 1, 2)  # OHWI -> OIHW
                group = 1
            else:
                wt = w.transpose(3, 0, 1, 2)  # 1HW(C*m) -> (C*m)1HW
                group = in_shape[3]
            kh, kw = w.shape[1], w.shape[2]
            stride = (opts.StrideH(), opts.StrideW())
            dil = (opts.DilationHFactor(), opts.DilationWFactor())
            pads = _same_pads(in_shape[1:3], (kh, kw), stride, dil) if opts.Padding() == tflite.Padding.SAME else [0, 0, 0, 0]
            cin = [name[ins[0]], init(wt, f"w{n}")]
            if len(ins) > 2 and ins[2] >= 0:
                cin.append(init(consts[ins[2]].astype(np.float32), f"b{n}"))
            pre = o if opts.FusedActivationFunction() == tflite.ActivationFunctionType.NONE else f"{o}_pre"
            nodes.append(helper.make_node("Conv", cin, [pre], kernel_shape=[kh, kw], strides=list(stride), dilations=list(dil), pads=pads, group=group))
            _fused(opts.FusedActivationFunction(), pre, nodes, o)
        elif kind in ("ADD", "MUL"):
            opts_t = tflite.AddOptions if kind == "ADD" else tflite.MulOptions
            opts = opts_t()
            tab = op.BuiltinOptions()
            act = tflite.ActivationFunctionType.NONE
            if tab is not None:
                opts.Init(tab.Bytes, tab.Pos)
                act = opts.FusedActivationFunction()
            pre = o if act == tflite.ActivationFunctionType.NONE else f"{o}_pre"
            nodes.append(helper.make_node("Add" if kind == "ADD" else "Mul", [operand(ins[0]), operand(ins[1])], [pre]))
            _fused(act, pre, nodes, o)
        elif kind == "HARD_SWISH":
            nodes.append(helper.make_node("HardSwish", [name[ins[0]]], [o]))
        elif kind == "RELU":
            nodes.append(helper.make_node("Relu", [name[ins[0]]], [o]))
        elif kind == "LOGISTIC":
            nodes.append(helper.make_node("Sigmoid", [name[ins[0]]], [o]))
        elif kind == "AVERAGE_POOL_2D":
            opts = tflite.Pool2DOptions()
            tab = op.BuiltinOptions()
            opts.Init(tab.Bytes, tab.Pos)
            in_shape = shape(ins[0])
            k = (opts.FilterHeight(), opts.FilterWidth())
            stride = (opts.StrideH(), opts.StrideW())
            if opts.Padding() == tflite.Padding.SAME and any(_same_pads(in_shape[1:3], k, stride)):
                raise Unsupported(f"op {n}: padded AVERAGE_POOL_2D")
            pre = o if opts.FusedActivationFunction() == tflite.ActivationFunctionType.NONE else f"{o}_pre"
            nodes.append(helper.make_node("AveragePool", [name[ins[0]]], [pre], kernel_shape=list(k), strides=list(stride)))
            _fused(opts.FusedActivationFunction(), pre, nodes, o)
        elif kind == "MEAN":
            axes = consts[ins[1]].reshape(-1).tolist()
            if sorted(int(a) for a in axes) != [1, 2]:
                raise Unsupported(f"op {n}: MEAN over axes {axes} (only spatial means)")
            nodes.append(helper.make_node("GlobalAveragePool", [name[ins[0]]], [o]))
        elif kind == "RESIZE_BILINEAR":
            opts = tflite.ResizeBilinearOptions()
            tab = op.BuiltinOptions()
            opts.Init(tab.Bytes, tab.Pos)
            size = consts[ins[1]].reshape(-1).astype(np.int64)
            cin = shape(outs[0])[3]
            mode = "align_corners" if opts.AlignCorners() else ("half_pixel" if opts.HalfPixelCenters() else "asymmetric")
            sizes = init(np.array([1, cin, int(size[0]), int(size[1])], np.int64), f"s{n}")
            nodes.append(helper.make_node("Resize", [name[ins[0]], "", "", sizes], [o], mode="linear", coordinate_transformation_mode=mode))
        elif kind == "CUSTOM" and oc.CustomCode() == b"Convolution2DTransposeBias":
            # MediaPipe's custom options: TfLiteTransposeConvParams {padding, stride_w, stride_h} (3 x int32).
            raw = op.CustomOptionsAsNumpy().tobytes()
            padding, stride_w, stride_h = struct.unpack("<3i", raw[:12])
            w = consts[ins[1]]  # [O, H, W, I]
            wt = w.transpose(3, 0, 1, 2)  # -> [I, O, H, W]
            kh, kw = w.shape[1], w.shape[2]
            in_hw = shape(ins[0])[1:3]
            out_hw = shape(outs[0])[1:3]
            if padding == tflite.Padding.SAME:
                total = [(i - 1) * s + k - oo for i, s, k, oo in zip(in_hw, (stride_h, stride_w), (kh, kw), out_hw)]
                pads = [t // 2 for t in total] + [t - t // 2 for t in total]
            else:
                pads = [0, 0, 0, 0]
            cin = [name[ins[0]], init(wt, f"w{n}"), init(consts[ins[2]].astype(np.float32), f"b{n}")]
            nodes.append(helper.make_node("ConvTranspose", cin, [o], kernel_shape=[kh, kw], strides=[stride_h, stride_w], pads=pads))
        else:
            raise Unsupported(f"op {n}: unsupported TFLite operator {kind}")

    gin = [int(x) for x in g.InputsAsNumpy()]
    gout = [int(x) for x in g.OutputsAsNumpy()]
    if len(gin) != 1:
        raise Unsupported(f"{path}: {len(gin)} inputs (expected 1 image)")
    ishape = shape(gin[0])
    nodes.insert(0, helper.make_node("Identity", ["image"], [name[gin[0]]]))
    outputs = []
    for j, t in enumerate(gout):
        s = shape(t)
        oname = "mask" if j == 0 else f"out{j}"
        nodes.append(helper.make_node("Identity", [name[t]], [oname]))
        outputs.append(helper.make_tensor_value_info(oname, TensorProto.FLOAT, [s[0], s[3], s[1], s[2]]))
    graph = helper.make_graph(nodes, "tflite", [helper.make_tensor_value_info("image", TensorProto.FLOAT, [ishape[0], ishape[3], ishape[1], ishape[2]])], outputs, inits)
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name=producer)
    m.ir_version = 8
    onnx.checker.check_model(m)
    # RESIZE_BILINEAR x2 as shifted sums: the same function, faster in tract (onnx_rewrite.py).
    m, _ = resize_to_shifts(m)
    return m
