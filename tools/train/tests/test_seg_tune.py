"""seg_tune: the segmenter's ONNX graph run by PyTorch (OnnxNet) reads what ONNX Runtime reads,
its trained weights go back into the same graph, an operator it does not know is refused by name,
and a few steps on a toy set lower the loss and keep the output finite."""
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from onnx import TensorProto, helper, numpy_helper
from safetensors.numpy import save_file

from volcap_train import seg_tune
from volcap_train.seg_tune import OnnxNet, Unsupported, iou

SEG = Path(__file__).resolve().parents[3] / "models" / "seg.onnx"


def ort_run(model: onnx.ModelProto, x: np.ndarray) -> np.ndarray:
    s = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    return np.concatenate([s.run(None, {"image": x[i : i + 1]})[0] for i in range(len(x))])


def test_the_committed_segmenter_reads_as_in_onnx_runtime_batched_and_at_the_extremes():
    model = onnx.load(str(SEG))
    net = OnnxNet(model)
    g = torch.Generator().manual_seed(3)
    x = torch.cat([torch.rand(2, 3, 256, 256, generator=g), torch.zeros(1, 3, 256, 256), torch.ones(1, 3, 256, 256)])
    with torch.no_grad():
        y = net(x).numpy()
        z = net(x, logits=True)
    ref = ort_run(model, x.numpy())
    assert y.shape == ref.shape == (4, 1, 256, 256)
    assert np.abs(y - ref).max() < 1e-5
    # The logits are what the output's Sigmoid reads.
    assert torch.allclose(torch.sigmoid(z), torch.from_numpy(y), atol=1e-6)
    assert np.isfinite(y).all()
    # Every weight of a convolution is a parameter; the constants are the rest.
    n_conv = sum(1 for n in model.graph.node if n.op_type in ("Conv", "ConvTranspose"))
    assert len(net.params) >= n_conv


def test_trained_weights_are_written_into_the_same_graph():
    model = onnx.load(str(SEG))
    net = OnnxNet(model)
    with torch.no_grad():
        for p in net.params:
            p.mul_(1.05)
    out = net.to_onnx("test")
    assert [n.op_type for n in out.graph.node] == [n.op_type for n in model.graph.node]
    x = torch.rand(1, 3, 256, 256, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        mine = net(x).numpy()
    theirs = ort_run(out, x.numpy())
    before = ort_run(model, x.numpy())
    # (weights scaled by 1.05 at every layer make a sharper network: PyTorch's and ONNX Runtime's
    # summation orders differ by up to ~3e-5 here)
    assert np.abs(mine - theirs).max() < 2e-4
    assert np.abs(theirs - before).max() > 1e-2  # the new weights, not the old ones


def test_an_operator_outside_the_set_is_refused_naming_it_and_its_node():
    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 4, 4])
    y = helper.make_tensor_value_info("mask", TensorProto.FLOAT, [1, 3, 4, 4])
    graph = helper.make_graph([helper.make_node("Tanh", ["image"], ["mask"], name="squash")], "g", [x], [y])
    with pytest.raises(Unsupported, match="squash.*Tanh"):
        OnnxNet(helper.make_model(graph))
    # An output that is not a Sigmoid's has no logits to train on.
    graph = helper.make_graph([helper.make_node("Relu", ["image"], ["mask"], name="r")], "g", [x], [y])
    with pytest.raises(Unsupported, match="Sigmoid"):
        OnnxNet(helper.make_model(graph))


def toy_graph() -> onnx.ModelProto:
    """image -> Conv 3x3 (3 -> 1) -> Sigmoid -> mask: a segmenter small enough to train in a test."""
    w = numpy_helper.from_array(np.zeros((1, 3, 3, 3), np.float32), "w")
    b = numpy_helper.from_array(np.zeros(1, np.float32), "b")
    nodes = [
        helper.make_node("Conv", ["image", "w", "b"], ["z"], pads=[1, 1, 1, 1], kernel_shape=[3, 3]),
        helper.make_node("Sigmoid", ["z"], ["p"]),
        helper.make_node("Identity", ["p"], ["mask"]),
    ]
    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 256, 256])
    y = helper.make_tensor_value_info("mask", TensorProto.FLOAT, [1, 1, 256, 256])
    return helper.make_model(helper.make_graph(nodes, "toy", [x], [y], [w, b]), opset_imports=[helper.make_opsetid("", 17)])


def toy_set(root: Path, n: int, seed: int):
    """Shards whose person is a red rectangle on a dark grey background."""
    rng = np.random.default_rng(seed)
    for split, count in (("train", n), ("val", max(2, n // 4))):
        for i in range(count):
            img = np.full((256, 256, 3), 40, np.uint8)
            mask = np.zeros((256, 256), np.uint8)
            y0, x0 = rng.integers(20, 120, 2)
            h, w = rng.integers(60, 120, 2)
            img[y0 : y0 + h, x0 : x0 + w] = (220, 30, 30)
            mask[y0 : y0 + h, x0 : x0 + w] = 255
            d = root / split / f"s{i:03d}"
            d.mkdir(parents=True, exist_ok=True)
            save_file({"image": img, "mask": mask}, str(d / "000_00.safetensors"))


def test_a_few_steps_on_a_toy_set_learn_the_mask_and_write_a_graph_onnx_runtime_reads(tmp_path):
    toy_set(tmp_path / "ds", 8, seed=5)
    seg = tmp_path / "toy.onnx"
    onnx.save(toy_graph(), str(seg))
    out = tmp_path / "run"
    seg_tune.main(["--data", str(tmp_path / "ds"), "--seg", str(seg), "--out", str(out), "--steps", "60", "--batch", "4",
                   "--lr", "0.05", "--anchor-weight", "0", "--composite", "0", "--affine", "0", "--crop", "0", "--eval-every", "30", "--threads", "1"])
    import json

    budget = json.loads((out / "budget.json").read_text())
    assert budget["val_mask_iou_start"] < 0.5  # a zero conv reads 0.5 everywhere: no pixel above it
    assert budget["log"][-1]["val_mask_iou"] > 0.9
    img, mask = seg_tune.load_images([tmp_path / "ds"], "val")
    p = ort_run(onnx.load(str(out / "seg.onnx")), img.float().numpy() / 255.0)
    assert np.isfinite(p).all()
    assert float(iou(torch.from_numpy(p) > 0.5, mask > 0).mean()) > 0.9
    # Both files say they were tuned (the toy graph has no `volcap.run`: the doc string).
    for name in ("tuned.onnx", "seg.onnx"):
        assert "seg_tune: 60 steps on the renders" in onnx.load(str(out / name)).doc_string
    # --mix 1 (the default): the shipped file is the tuned one.
    assert np.array_equal(p, ort_run(onnx.load(str(out / "tuned.onnx")), img.float().numpy() / 255.0))


def test_the_anchor_holds_the_weights_near_the_original(tmp_path):
    toy_set(tmp_path / "ds", 8, seed=6)
    model = toy_graph()
    model.graph.initializer[0].CopyFrom(numpy_helper.from_array(np.full((1, 3, 3, 3), 0.01, np.float32), "w"))
    seg = tmp_path / "toy.onnx"
    onnx.save(model, str(seg))
    moved = {}
    for weight in (0.0, 100.0):
        out = tmp_path / f"run{weight}"
        seg_tune.main(["--data", str(tmp_path / "ds"), "--seg", str(seg), "--out", str(out), "--steps", "20", "--batch", "4",
                       "--lr", "0.01", "--anchor-weight", str(weight), "--composite", "0", "--affine", "0", "--crop", "0", "--eval-every", "20", "--threads", "1"])
        w = numpy_helper.to_array(next(i for i in onnx.load(str(out / "seg.onnx")).graph.initializer if i.name == "w"))
        moved[weight] = float(np.abs(w - 0.01).mean())
    assert moved[100.0] < 0.5 * moved[0.0]


@pytest.mark.parametrize(
    "flag,value,message",
    [("--steps", "0", "--steps must be positive"), ("--lr", "nan", "--lr must be a positive number"),
     ("--composite", "1.5", "--composite: 1.5 is out of range"), ("--anchor-weight", "-1", "--anchor-weight: -1.0 is out of range"),
     ("--mix", "2", "--mix: 2.0 is out of range"), ("--mix-from", "/nonexistent.onnx", "--mix-from /nonexistent.onnx: no such file")],
)
def test_bad_options_are_refused_by_name(tmp_path, capsys, flag, value, message):
    with pytest.raises(SystemExit):
        seg_tune.main(["--data", str(tmp_path), "--seg", str(SEG), "--out", str(tmp_path / "o"), flag, value])
    assert message in capsys.readouterr().err


def test_the_mix_moves_each_weight_its_share_of_the_way_and_refuses_another_graph(tmp_path):
    base = toy_graph()
    tuned = toy_graph()
    w1 = np.random.default_rng(2).normal(size=(1, 3, 3, 3)).astype(np.float32)
    tuned.graph.initializer[0].CopyFrom(numpy_helper.from_array(w1, "w"))
    for share in (0.0, 0.3, 1.0):
        out = seg_tune.mix_models(base, tuned, share)
        w = numpy_helper.to_array(out.graph.initializer[0])
        assert np.allclose(w, share * w1, atol=1e-7)  # the base's weights are zero
    # The CLI's mix-only mode writes the same, and the run's name says it was mixed.
    onnx.save(base, str(tmp_path / "base.onnx"))
    onnx.save(tuned, str(tmp_path / "tuned.onnx"))
    seg_tune.main(["--seg", str(tmp_path / "base.onnx"), "--mix-from", str(tmp_path / "tuned.onnx"), "--mix", "0.3", "--out", str(tmp_path / "o")])
    w = numpy_helper.to_array(onnx.load(str(tmp_path / "o" / "seg.onnx")).graph.initializer[0])
    assert np.allclose(w, 0.3 * w1, atol=1e-7)
    other = toy_graph()
    other.graph.node[1].op_type = "Relu"
    with pytest.raises(SystemExit, match="operators differ"):
        seg_tune.mix_models(base, other, 0.5)
    with pytest.raises(SystemExit, match="initializer w: missing or of another shape"):
        wrong = toy_graph()
        wrong.graph.initializer[0].CopyFrom(numpy_helper.from_array(np.zeros((1, 3, 1, 1), np.float32), "w"))
        seg_tune.mix_models(base, wrong, 0.5)


def test_install_copies_the_file_and_names_its_tuning_in_the_index(tmp_path):
    import json

    base, tuned = toy_graph(), toy_graph()
    base.metadata_props.add(key="volcap.run", value="original")
    tuned.graph.initializer[0].CopyFrom(numpy_helper.from_array(np.ones((1, 3, 3, 3), np.float32), "w"))
    onnx.save(base, str(tmp_path / "base.onnx"))
    onnx.save(tuned, str(tmp_path / "tuned.onnx"))
    models = tmp_path / "models"
    models.mkdir()
    (models / "models.json").write_text(json.dumps({"seg": {"files": ["seg.onnx"], "license": "Apache-2.0", "params": 1, "source": "original"}}))
    seg_tune.main(["--seg", str(tmp_path / "base.onnx"), "--mix-from", str(tmp_path / "tuned.onnx"), "--mix", "0.3", "--out", str(tmp_path / "o"), "--install", str(models)])
    assert (models / "seg.onnx").read_bytes() == (tmp_path / "o" / "seg.onnx").read_bytes()
    entry = json.loads((models / "models.json").read_text())["seg"]
    assert entry["source"].startswith("original, seg_tune: mixed 0.3 with tuned weights sha256:")
    assert entry["params"] == 1 and entry["license"] == "Apache-2.0"
