"""Graph rewrites that keep a model's function and make it faster in tract (the engine's
runtime), applied by `export.export`, by `tflite_onnx.convert` and, for committed files, by

    python -m volcap_train.onnx_rewrite MODEL.onnx [...]

(which checks the result against the original in onnxruntime before overwriting).

`resize_to_shifts`: every bilinear x2 upsampling (ONNX `Resize`, mode linear, half-pixel
centres, NCHW with H and W doubled) becomes, per axis, two one-sample shifts with the edge
repeated, two weighted sums and an interleave:

    even[p] = 3/4 x[p] + 1/4 x[max(p - 1, 0)],   odd[p] = 3/4 x[p] + 1/4 x[min(p + 1, n - 1)]

which is what `Resize` computes (equal to within float rounding). tract runs `Resize` through a
generic per-axis resampler; the shifted sums are plain element-wise kernels (the Fourier head's
field stage 51-53 -> 47-51 ms on this machine, `volcap bench pipeline`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import onnx
from onnx import helper, numpy_helper, shape_inference


def _shape(m: onnx.ModelProto, name: str):
    for vi in list(m.graph.value_info) + list(m.graph.input) + list(m.graph.output):
        if vi.name == name:
            dims = vi.type.tensor_type.shape.dim
            if all(d.HasField("dim_value") for d in dims):
                return [d.dim_value for d in dims]
    return None


def resize_to_shifts(model: onnx.ModelProto) -> tuple[onnx.ModelProto, int]:
    """The model with every bilinear x2 `Resize` replaced (see the module text); returns it
    and the number of nodes replaced. Resize nodes of any other kind are left as they are."""
    inferred = shape_inference.infer_shapes(model)
    g = model.graph
    new_nodes, inits, count = [], [], 0

    def const(name, arr):
        inits.append(numpy_helper.from_array(np.asarray(arr), name))
        return name

    for node in g.node:
        if node.op_type != "Resize":
            new_nodes.append(node)
            continue
        attrs = {a.name: helper.get_attribute_value(a) for a in node.attribute}
        mode = attrs.get("mode", b"nearest")
        ctm = attrs.get("coordinate_transformation_mode", b"half_pixel")
        src = _shape(inferred, node.input[0])
        dst = _shape(inferred, node.output[0])
        ok = (
            node.op_type == "Resize"
            and mode == b"linear"
            and ctm in (b"half_pixel", b"pytorch_half_pixel")
            and src is not None
            and dst is not None
            and len(src) == 4
            and dst[:2] == src[:2]
            and dst[2] == 2 * src[2]
            and dst[3] == 2 * src[3]
            and min(src[2], src[3]) >= 2
        )
        if not ok:
            new_nodes.append(node)
            continue
        count += 1
        p = f"rs{count}_"
        x = node.input[0]
        shape = list(src)
        for axis in (2, 3):
            n = shape[axis]
            t = f"{p}a{axis}_"

            def sl(name, start, end):
                new_nodes.append(helper.make_node("Slice", [x, const(f"{name}_s", [start]), const(f"{name}_e", [end]), const(f"{name}_a", [axis])], [name]))
                return name

            first, head = sl(t + "first", 0, 1), sl(t + "head", 0, n - 1)
            tail, last = sl(t + "tail", 1, n), sl(t + "last", n - 1, n)
            new_nodes.append(helper.make_node("Concat", [first, head], [t + "prev"], axis=axis))
            new_nodes.append(helper.make_node("Concat", [tail, last], [t + "next"], axis=axis))
            q3, q1 = const(t + "q3", np.float32(0.75)), const(t + "q1", np.float32(0.25))
            new_nodes.append(helper.make_node("Mul", [x, q3], [t + "x3"]))
            for side in ("prev", "next"):
                new_nodes.append(helper.make_node("Mul", [t + side, q1], [t + side + "1"]))
                new_nodes.append(helper.make_node("Add", [t + "x3", t + side + "1"], [t + side + "w"]))
                new_nodes.append(helper.make_node("Unsqueeze", [t + side + "w", const(t + side + "ax", [axis + 1])], [t + side + "u"]))
            new_nodes.append(helper.make_node("Concat", [t + "prevu", t + "nextu"], [t + "pair"], axis=axis + 1))
            shape[axis] = 2 * n
            out = node.output[0] if axis == 3 else t + "out"
            new_nodes.append(helper.make_node("Reshape", [t + "pair", const(t + "shape", np.array(shape, dtype=np.int64))], [out]))
            x = out
    if count:
        # The replaced nodes' scales/sizes (initializers or Constant nodes) are no longer used.
        used = {i for n in new_nodes for i in n.input} | {o.name for o in g.output}
        new_nodes = [n for n in new_nodes if n.op_type != "Constant" or any(o in used for o in n.output)]
        kept = [t for t in g.initializer if t.name in used]
        del g.node[:]
        g.node.extend(new_nodes)
        del g.initializer[:]
        g.initializer.extend(kept + inits)
        onnx.checker.check_model(model)
    return model, count


def _check_same(a: Path, b: onnx.ModelProto, tol: float = 1e-4) -> float:
    import onnxruntime as ort

    ref = ort.InferenceSession(str(a), providers=["CPUExecutionProvider"])
    new = ort.InferenceSession(b.SerializeToString(), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(0)
    feeds = {}
    for i in ref.get_inputs():
        shape = [d if isinstance(d, int) else 1 for d in i.shape]
        feeds[i.name] = rng.random(shape, dtype=np.float32)
    worst = 0.0
    for x, y in zip(ref.run(None, feeds), new.run(None, feeds)):
        worst = max(worst, float(np.abs(x - y).max()))
    if worst > tol:
        raise SystemExit(f"{a}: rewritten model differs by {worst} (> {tol}); not written")
    return worst


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.onnx_rewrite", description=__doc__.split("\n\n")[0])
    ap.add_argument("models", nargs="+", type=Path)
    a = ap.parse_args(argv)
    for path in a.models:
        m, n = resize_to_shifts(onnx.load(str(path)))
        if n == 0:
            print(f"{path}: no bilinear x2 Resize, unchanged")
            continue
        worst = _check_same(path, m)
        onnx.save(m, str(path))
        print(f"{path}: {n} Resize replaced, max |difference| {worst:.2e} (onnxruntime, random input)")


if __name__ == "__main__":
    main()
