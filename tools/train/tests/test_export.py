"""Export round trip: PyTorch vs onnxruntime on the same inputs (fresh seeded nets), and the
committed ONNX files vs their committed PyTorch golden vectors (the engine's tests check the
same golden vectors through tract)."""

import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from volcap_train import crop as C
from volcap_train.export import INT8_MAX_DRIFT, Sig, export
from volcap_train.golden import golden_path, load_golden
from volcap_train.nets import SegNet, encode_z, make_shape, sample_features

MODELS = Path(__file__).resolve().parents[3] / "models"


def run(path, feeds):
    s = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return s.run(None, feeds)[0]


@pytest.mark.parametrize("variant", ["compact", "compact-plain-z"])
def test_shape_round_trip(tmp_path, variant):
    torch.manual_seed(0)
    enc, mlp, zenc = make_shape(variant)
    # Non-trivial batch-norm statistics.
    enc.train(), mlp.train()
    with torch.no_grad():
        for _ in range(3):
            f = enc(torch.randn(2, 4, 256, 256))
            mlp(sample_features(f, torch.rand(2, 64, 2) * 2 - 1).reshape(128, -1), encode_z(torch.rand(128) * 2 - 1, zenc))
    enc.eval(), mlp.eval()
    x = torch.randn(1, 4, 256, 256)
    export(enc, (x,), ["image"], ["features"], tmp_path / "e.onnx", {"kind": "shape-encoder"}, False)
    fb = torch.randn(37, f.shape[1])
    zb = encode_z(torch.rand(37) * 2 - 1, zenc)
    export(Sig(mlp), (fb, zb), ["feat", "z"], ["occ"], tmp_path / "m.onnx", {"kind": "shape-mlp"}, True)
    with torch.no_grad():
        fe = enc(x).numpy()
        oc = torch.sigmoid(mlp(fb, zb)).numpy()
    np.testing.assert_allclose(run(tmp_path / "e.onnx", {"image": x.numpy()}), fe, rtol=1e-4, atol=1e-4)
    # A different batch size than the one exported with: the batch axis is dynamic.
    np.testing.assert_allclose(run(tmp_path / "m.onnx", {"feat": fb.numpy(), "z": zb.numpy()}), oc, rtol=1e-5, atol=1e-5)


def fresh_fourier(seed, shift, draw):
    """A seeded small FourierNet with non-trivial batch-norm statistics (three training-mode
    batches drawn by `draw`), in eval mode."""
    from volcap_train.nets import FourierNet

    torch.manual_seed(seed)
    net = FourierNet(k=7, c=6, shift=shift)
    net.train()
    with torch.no_grad():
        for _ in range(3):
            net(draw(2, 4, 256, 256))
    return net.eval()


@pytest.mark.parametrize("shift", [False, True])
def test_fourier_round_trip(tmp_path, shift):
    net = fresh_fourier(2, shift, torch.randn)
    x = torch.randn(1, 4, 256, 256)
    export(net, (x,), ["image"], ["coeff"], tmp_path / "f.onnx", {"kind": "shape-fourier"}, False)
    with torch.no_grad():
        ref = net(x).numpy()
    out = run(tmp_path / "f.onnx", {"image": x.numpy()})
    assert out.shape == (1, 15, 128, 128)
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-4)


def test_seg_round_trip(tmp_path):
    torch.manual_seed(1)
    net = SegNet().eval()
    x = torch.rand(1, 3, 256, 256)
    export(Sig(net), (x,), ["image"], ["mask"], tmp_path / "s.onnx", {"kind": "seg"}, False)
    with torch.no_grad():
        ref = torch.sigmoid(net(x)).numpy()
    np.testing.assert_allclose(run(tmp_path / "s.onnx", {"image": x.numpy()}), ref, rtol=1e-4, atol=1e-5)


def test_grid_sample_convention_is_pixel_centres():
    # align_corners=True: NDC -1 / +1 hit the first / last pixel centres exactly.
    f = torch.arange(12.0).reshape(1, 1, 3, 4)
    xy = torch.tensor([[[-1.0, -1.0], [1.0, 1.0], [-1.0 + 2.0 / 3.0, 0.0], [5.0, 5.0]]])
    v = sample_features(f, xy)[0, :, 0]
    assert v.tolist() == [0.0, 11.0, 5.0, 11.0]


def test_crop_rule_round_trip():
    m = torch.zeros(256, 256)
    m[40:200, 100:140] = 1
    p = C.crop_params(m)
    s, tx, ty = p
    assert s == pytest.approx((2 * 159 / 255) / 2 / C.FILL)
    pts = torch.rand(10, 3) * 2 - 1
    back = C.to_crop(pts, p)
    assert torch.allclose(back[:, 0] * s + tx, pts[:, 0], atol=1e-6)
    assert C.crop_params(torch.zeros(8, 8)) is None


def committed():
    idx = MODELS / "models.json"
    if not idx.exists():
        return []
    return [k for k in json.loads(idx.read_text()) if k.startswith("shape-")]


@pytest.mark.parametrize("name", committed())
def test_committed_models_match_their_golden_vectors(name):
    g = load_golden(golden_path(MODELS / "golden", name))
    img = torch.from_numpy(g["image_u8"]).permute(2, 0, 1).float() / 255
    mask = torch.from_numpy(g["mask_u8"]).float()[None] / 255
    crop = tuple(float(v) for v in g["crop"])
    assert crop == pytest.approx(C.crop_params(mask[0]), abs=1e-6)
    from volcap_train.nets import encoder_input

    x = encoder_input(C.apply_crop(img, crop)[None], C.apply_crop(mask, crop)[None])
    fourier = MODELS / f"{name}.fourier.onnx"
    if fourier.exists():
        from volcap_train import fourier as FO

        coeff = run(fourier, {"image": x.numpy()})
        np.testing.assert_allclose(coeff[0][:, g["iy"], g["ix"]].T, g["features"], rtol=1e-3, atol=1e-3)
        pts = torch.from_numpy(g["points"])
        c = sample_features(torch.from_numpy(coeff), pts[None, :, :2])[0]
        k = (coeff.shape[1] - 1) // 2
        # The surface level the engine reads as 0.5 (`volcap.iso_level`, absent: 0.5).
        meta = {p.key: p.value for p in onnx.load(str(fourier), load_external_data=False).metadata_props}
        iso = float(meta.get("volcap.iso_level", "0.5"))
        occ = (FO.decode(c, pts[:, 2] * FO.ZETA_SCALE, k) + (0.5 - iso)).clamp(0, 1).numpy()
        np.testing.assert_allclose(occ, g["occ"], rtol=1e-3, atol=1e-3)
        return
    feat = run(MODELS / f"{name}.encoder.onnx", {"image": x.numpy()})
    np.testing.assert_allclose(feat[0][:, g["iy"], g["ix"]].T, g["features"], rtol=1e-3, atol=1e-3)
    pts = torch.from_numpy(g["points"])
    f = sample_features(torch.from_numpy(feat), pts[None, :, :2])[0].numpy()
    s = ort.InferenceSession(str(MODELS / f"{name}.mlp.onnx"), providers=["CPUExecutionProvider"])
    zdim = s.get_inputs()[1].shape[1]
    z = encode_z(pts[:, 2], "softz" if zdim == 64 else "scalar").numpy()
    occ = s.run(None, {"feat": f, "z": z})[0][:, 0]
    np.testing.assert_allclose(occ, g["occ"], rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("name", sorted(p.name.split(".")[0] for p in MODELS.glob("shape-fourier*.fourier.int8.onnx")))
def test_committed_fourier_int8_stays_near_its_f32(name):
    """The int8 export of every committed Fourier model reads nearly the occupancy of its f32
    one along the golden input's query points (a crop of a held-out image, as the engine makes
    it). Calibrating the activation ranges on a few held-out images had fourier-small's int8
    0.052 off on average here (0.06 of point IoU lost on held-out subjects); ranges from the
    training images the run saw give 0.011 (export.fourier_calib)."""
    from volcap_train import fourier as FO
    from volcap_train.nets import encoder_input

    g = load_golden(golden_path(MODELS / "golden", name))
    img = torch.from_numpy(g["image_u8"]).permute(2, 0, 1).float() / 255
    mask = torch.from_numpy(g["mask_u8"]).float()[None] / 255
    crop = tuple(float(v) for v in g["crop"])
    x = encoder_input(C.apply_crop(img, crop)[None], C.apply_crop(mask, crop)[None]).numpy()
    pts = torch.from_numpy(g["points"])
    k = (run(MODELS / f"{name}.fourier.onnx", {"image": x}).shape[1] - 1) // 2

    def occ(path):
        coeff = torch.from_numpy(run(path, {"image": x}))
        return FO.decode(sample_features(coeff, pts[None, :, :2])[0], pts[:, 2] * FO.ZETA_SCALE, k)

    f32, int8 = occ(MODELS / f"{name}.fourier.onnx"), occ(MODELS / f"{name}.fourier.int8.onnx")
    assert torch.isfinite(int8).all()
    assert (int8 - f32).abs().mean().item() < INT8_MAX_DRIFT


def fresh_fourier_onnx(path):
    """fresh_fourier(3, ...) exported as f32 ONNX to `path`; returns its trace input."""
    net = fresh_fourier(3, False, torch.rand)
    x = torch.rand(1, 4, 256, 256)
    export(net, (x,), ["image"], ["coeff"], path, {"kind": "shape-fourier"}, False)
    return x


def test_both_int8_schemes_run_and_fine_quantizes_weights_per_channel(tmp_path):
    """export.quantize: the default scheme has one scale per weight tensor; `fine=True` one per
    output channel (the export keeps whichever reads the occupancy closer to f32). Both files
    run and stay near their f32 on a fresh net."""
    from volcap_train.export import quantize

    x = fresh_fourier_onnx(tmp_path / "f.onnx")
    feeds = [{"image": torch.rand(1, 4, 256, 256).numpy()} for _ in range(4)] + [{"image": x.numpy()}]
    ref = run(tmp_path / "f.onnx", {"image": x.numpy()})
    for fine in (False, True):
        q = tmp_path / f"q{fine}.onnx"
        quantize(tmp_path / "f.onnx", q, feeds, fine=fine)
        m = onnx.load(str(q))
        assert {p.key: p.value for p in m.metadata_props}["volcap.precision"] == "int8"
        inits = {i.name: i for i in m.graph.initializer}
        weight_scales = [inits[n.input[1]] for n in m.graph.node if n.op_type == "DequantizeLinear" and n.input[0] in inits and inits[n.input[0]].data_type == onnx.TensorProto.INT8]
        assert weight_scales, "no quantized weights"
        sizes = {int(np.prod(s.dims)) if len(s.dims) else 1 for s in weight_scales}
        assert (max(sizes) > 1) == fine, sizes
        out = run(q, {"image": x.numpy()})
        assert np.isfinite(out).all()
        assert np.abs(out - ref).mean() < 0.1 * np.abs(ref).mean() + 1e-3


def test_fine_int8_percentile_sets_the_activation_ranges(tmp_path):
    """export.quantize(fine=True, percentile=p): activation ranges come from the p-th percentile,
    so a lower percentile clips more and gives no larger activation scale on any tensor and a
    smaller one on some; the export's candidates (FOURIER_INT8_SCHEMES) are distinct schemes."""
    from volcap_train.export import FOURIER_INT8_SCHEMES, quantize

    fresh_fourier_onnx(tmp_path / "f.onnx")
    feeds = [{"image": torch.rand(1, 4, 256, 256).numpy()} for _ in range(4)]

    def act_scales(pct):
        q = tmp_path / f"q{pct}.onnx"
        quantize(tmp_path / "f.onnx", q, feeds, fine=True, percentile=pct)
        m = onnx.load(str(q))
        inits = {i.name: onnx.numpy_helper.to_array(i) for i in m.graph.initializer}
        # Activations: QuantizeLinear nodes fed by a tensor that is not an initializer.
        return {n.input[0]: float(inits[n.input[1]]) for n in m.graph.node if n.op_type == "QuantizeLinear" and n.input[0] not in inits}

    lo, hi = act_scales(99.0), act_scales(99.99999)
    assert lo.keys() == hi.keys() and lo
    assert all(lo[t] <= hi[t] * (1 + 1e-6) for t in lo)
    assert any(lo[t] < 0.9 * hi[t] for t in lo)
    names = [s[0] for s in FOURIER_INT8_SCHEMES]
    assert len(set(names)) == len(names)
    assert len({(f, p, k) for _, f, p, k in FOURIER_INT8_SCHEMES}) == len(FOURIER_INT8_SCHEMES)


def test_int8_keeps_the_named_convolutions_in_f32(tmp_path):
    """quantize(keep_f32=KEEP_F32): the Fourier net's first two convolutions (named as every
    Fourier export names them) read float32 weights and inputs, every other convolution int8
    ones; the file runs near its f32; a name the graph lacks is refused, named."""
    from volcap_train.export import KEEP_F32, quantize

    x = fresh_fourier_onnx(tmp_path / "f.onnx")
    feeds = [{"image": torch.rand(1, 4, 256, 256).numpy()} for _ in range(4)] + [{"image": x.numpy()}]
    q = tmp_path / "q.onnx"
    quantize(tmp_path / "f.onnx", q, feeds, fine=True, keep_f32=KEEP_F32)
    m = onnx.load(str(q))
    made_by = {o: n for n in m.graph.node for o in n.output}
    inits = {i.name for i in m.graph.initializer}

    def dequantized(t):
        return t in made_by and made_by[t].op_type == "DequantizeLinear"

    convs = {n.name: n for n in m.graph.node if n.op_type == "Conv"}
    assert set(KEEP_F32) <= convs.keys(), sorted(convs)
    for name, n in convs.items():
        kept = name in KEEP_F32
        assert dequantized(n.input[1]) != kept, name
        assert (n.input[1] in inits) == kept, name
        assert dequantized(n.input[0]) != kept, name
    ref = run(tmp_path / "f.onnx", {"image": x.numpy()})
    out = run(q, {"image": x.numpy()})
    assert np.isfinite(out).all()
    assert np.abs(out - ref).mean() < 0.1 * np.abs(ref).mean() + 1e-3
    with pytest.raises(ValueError, match="/e9/nowhere/Conv"):
        quantize(tmp_path / "f.onnx", tmp_path / "bad.onnx", feeds, keep_f32=("/e9/nowhere/Conv",))


def test_export_reads_a_light_checkpoint_as_a_run_s(tmp_path):
    # What the training recipe brings back from a lent machine is a light checkpoint
    # ({"net": weights}); placed as RUN/ckpt.pt it exports like a run's full one.
    from volcap_train.export import load_modules
    from volcap_train.nets import FourierNet

    net = FourierNet(3, 4, False)
    run = tmp_path / "fourier-small"
    run.mkdir()
    torch.save({"net": net.state_dict(), "step": 7, "variant": "fourier-small"}, run / "ckpt.pt")
    st, (sd,) = load_modules(run, ["net"])
    assert st["step"] == 7
    assert sd.keys() == net.state_dict().keys()
    full = tmp_path / "full"
    full.mkdir()
    torch.save({"modules": {"net": net.state_dict()}, "step": 9}, full / "ckpt.pt")
    assert load_modules(full, ["net"])[1][0].keys() == sd.keys()
    # A run trained with --ema exports its moving average, not its last weights.
    avg = {k: v + 1 if v.is_floating_point() else v for k, v in net.state_dict().items()}
    ema = tmp_path / "ema"
    ema.mkdir()
    torch.save({"modules": {"net": net.state_dict(), "ema": {"n_averaged": torch.tensor(3), **{f"module.{k}": v for k, v in avg.items()}}}, "step": 9}, ema / "ckpt.pt")
    got = load_modules(ema, ["net"])[1][0]
    assert got.keys() == sd.keys() and all(torch.equal(got[k], avg[k]) for k in avg)
    # A module the checkpoint lacks is refused naming the file and the module.
    with pytest.raises(SystemExit, match=r"ckpt\.pt: no module enc"):
        load_modules(run, ["enc", "net"])


@pytest.mark.parametrize("name", sorted(p.name.split(".")[0] for p in MODELS.glob("shape-fourier*.fourier*.onnx")))
def test_committed_fourier_files_say_the_segmentation_passes_they_were_trained_on(name):
    # The engine feeds a model masks made as its training masks were (`volcap.segment_passes`,
    # absent: 1; `[model] segment_passes` unset): the file must say what its run used.
    card = json.loads((MODELS / "models.json").read_text())[name]
    trained = int(card.get("budget", {}).get("args", {}).get("segment_passes", 1) or 1)
    for f in MODELS.glob(f"{name}.fourier*.onnx"):
        meta = {p.key: p.value for p in onnx.load(str(f), load_external_data=False).metadata_props}
        assert int(meta.get("volcap.segment_passes", "1")) == trained, f.name


def test_fourier_export_writes_the_segmentation_passes_of_a_two_pass_run():
    from volcap_train.export import fourier_meta

    one = fourier_meta("fourier-small", 15, "body", 0.55, "x", passes=1)
    two = fourier_meta("fourier-small", 15, "body", 0.55, "x", passes=2)
    assert "segment_passes" not in one and two["segment_passes"] == "2"
    assert {k: v for k, v in two.items() if k != "segment_passes"} == one


def test_the_card_names_the_calibration_count_and_a_bad_count_is_refused(tmp_path):
    from volcap_train.export import INT8_CALIB_IMAGES, calib_row, main

    assert f"from {INT8_CALIB_IMAGES} training images" in calib_row(None, 0)
    row = calib_row(Path("seg.onnx"), 0, True, 99.9999, 320)
    assert "from 320 training images, the product's masks" in row and "99.9999" in row
    for bad in ["0", "256,0", "256,x", "", "192,192"]:
        with pytest.raises(SystemExit):
            main(["--data", str(tmp_path), "--runs", str(tmp_path), "--out", str(tmp_path), "--int8-calib-images", bad])


def test_calibration_counts_parse_in_order_and_name_the_bad_value():
    import argparse

    from volcap_train.export import calib_counts

    assert calib_counts("256") == [256]
    assert calib_counts("256,192,160") == [256, 192, 160]
    for bad, says in [("0", "at least 1"), ("256,-3", "-3 images"), ("2x6", "'2x6'"), ("192,192", "named twice")]:
        with pytest.raises(argparse.ArgumentTypeError, match=says):
            calib_counts(bad)


def test_the_sides_count_the_cells_a_series_moves_across_the_level():
    """export.sides_of: a ray inside on [-0.3, 0.1] against the same ray grown to 0.2 (K = 15,
    read at the engine's 129 depths, 1/64 apart): the grown one holds about 0.5 / 0.4 of the
    cells inside, and the cells changing side are the ones it gained; a map against itself
    changes none."""
    from volcap_train import fourier as FO
    from volcap_train.export import sides_of

    k = 15
    ray = lambda hi: FO.interval_coeffs(torch.tensor(-0.3, dtype=torch.float64), torch.tensor(hi, dtype=torch.float64), k)
    a, b = ray(0.1)[:, None, None], ray(0.2)[:, None, None]
    na, nb, nc = sides_of(a, b, k, 0.55)
    assert 22 <= na <= 26 and 29 <= nb <= 33, (na, nb)
    assert 1.15 < nb / na < 1.35
    assert nb - na <= nc <= nb - na + 2, (na, nb, nc)
    assert sides_of(a, a, k, 0.55) == (na, na, 0)


def test_int8_sides_read_a_file_against_its_f32_over_whole_volumes(tmp_path):
    """export.int8_sides: a file against itself moves no cell and keeps the volume; its int8
    file moves some and keeps about the volume; a level no cell reaches is an error naming
    the f32 file."""
    from volcap_train import fourier as FO
    from volcap_train.export import int8_sides, quantize

    x = fresh_fourier_onnx(tmp_path / "f.onnx")
    feeds = [{"image": torch.rand(1, 4, 256, 256).numpy()} for _ in range(3)] + [{"image": x.numpy()}]
    quantize(tmp_path / "f.onnx", tmp_path / "q.onnx", feeds)
    coeff = torch.from_numpy(run(tmp_path / "f.onnx", {"image": x.numpy()})[0])
    k = (coeff.shape[0] - 1) // 2
    zs = FO.basis(torch.linspace(-1.0, 1.0, 129), k)
    level = (zs @ coeff.reshape(coeff.shape[0], -1)).median().item()
    assert int8_sides(tmp_path / "f.onnx", tmp_path / "f.onnx", feeds, k, level) == (0.0, 1.0)
    changed, volume = int8_sides(tmp_path / "f.onnx", tmp_path / "q.onnx", feeds, k, level)
    assert 0.0 < changed < 0.5 and 0.7 < volume < 1.3, (changed, volume)
    with pytest.raises(ValueError, match="f.onnx: no cell inside"):
        int8_sides(tmp_path / "f.onnx", tmp_path / "q.onnx", feeds, k, 1e9)
