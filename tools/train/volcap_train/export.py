"""Export trained runs to ONNX (f32 and int8 QDQ), golden vectors and model cards.

`python -m volcap_train.export --data DIR --runs RUNS --out models/`

Files per shape variant V: `shape-V.encoder.onnx` (image [1,4,256,256] -> features
[1,F,64,64]), `shape-V.mlp.onnx` (feat [N,F], z [N,Z] -> occ [N,1] in [0,1]); the engine
samples the features and encodes z (SoftZ or scalar) itself. Colour: `color.encoder.onnx`,
`color.mlp.onnx` (feat [N,Fc], rgb [N,3], z [N,1] -> rgb [N,3]). Segmentation: `seg.onnx`
(image [1,3,256,256] RGB in [0,1] -> mask [1,1,256,256] in [0,1]). `*.int8.onnx`: QDQ
int8 (Conv/MatMul/Gemm quantized; no QLinearAdd, which tract lacks). Metadata keys
`volcap.*` describe the contract; the engine checks them and the shapes at load.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import onnx
import torch
import torch.nn as nn
from safetensors.numpy import save_file

from . import crop as C
from .data import Split
from .nets import SOFTZ_BINS, ColorEncoder, ColorMlp, SegNet, SHAPE_VARIANTS, encode_z, encoder_input, make_shape, sample_features

OPSET = 17
SAMPLE_RULE = "bilinear align_corners=1 padding=border"


class Sig(nn.Module):
    def __init__(self, m):
        super().__init__()
        self.m = m

    def forward(self, *a):
        return torch.sigmoid(self.m(*a))


def count_macs(module: nn.Module, *inputs) -> int:
    """Multiply-accumulates of Conv2d and Linear layers for one forward pass."""
    total = [0]

    def hook(m, i, o):
        if isinstance(m, nn.Conv2d):
            total[0] += o.numel() * (m.in_channels // m.groups) * m.kernel_size[0] * m.kernel_size[1]
        elif isinstance(m, nn.Linear):
            total[0] += o.numel() // o.shape[-1] * m.in_features * m.out_features

    hs = [m.register_forward_hook(hook) for m in module.modules() if isinstance(m, (nn.Conv2d, nn.Linear))]
    with torch.no_grad():
        module(*inputs)
    for h in hs:
        h.remove()
    return total[0]


def params(m: nn.Module) -> int:
    return sum(p.numel() for p in m.parameters())


def export(module, inputs, names_in, names_out, path: Path, meta: dict, dynamic_batch: bool):
    module.eval()
    dyn = {n: {0: "n"} for n in names_in + names_out} if dynamic_batch else None
    torch.onnx.export(module, inputs, str(path), input_names=names_in, output_names=names_out, opset_version=OPSET, dynamic_axes=dyn, dynamo=False)
    m = onnx.load(str(path))
    for k, v in meta.items():
        p = m.metadata_props.add()
        p.key, p.value = f"volcap.{k}", str(v)
    onnx.checker.check_model(m)
    onnx.save(m, str(path))


def quantize(src: Path, dst: Path, feeds: list[dict]):
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.it = iter(feeds)

        def get_next(self):
            return next(self.it, None)

    quantize_static(str(src), str(dst), Reader(), quant_format=QuantFormat.QDQ, op_types_to_quantize=["Conv", "MatMul", "Gemm"], per_channel=False, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8)
    m = onnx.load(str(dst))
    src_meta = {p.key: p.value for p in onnx.load(str(src)).metadata_props}
    del m.metadata_props[:]
    for k, v in {**src_meta, "volcap.precision": "int8"}.items():
        p = m.metadata_props.add()
        p.key, p.value = k, v
    onnx.save(m, str(dst))


def load_modules(run: Path, names):
    st = torch.load(run / "ckpt.pt", weights_only=False)
    return st, [st["modules"][n] for n in names]


def golden_sample(feat, n, gen):
    c, h, w = feat.shape
    iy = torch.randint(0, h, (n,), generator=gen)
    ix = torch.randint(0, w, (n,), generator=gen)
    return iy, ix, feat[:, iy, ix].T.contiguous()


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.export")
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--runs", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=None, help="run names to export (default: all present)")
    args = ap.parse_args(argv)
    out = args.out
    (out / "golden").mkdir(parents=True, exist_ok=True)
    va = Split(args.data, "val")
    gi = 0
    rgb = va.rgb01(gi)
    mask = va.mask01(gi)
    crop = C.crop_params(mask[0])
    x = encoder_input(C.apply_crop(rgb, crop)[None], C.apply_crop(mask, crop)[None])
    pts = C.to_crop(va.points[gi][::31][:256], crop)
    calib = []
    for i in range(0, len(va), max(1, len(va) // 16)):
        m = va.mask01(i)
        p = C.crop_params(m[0])
        if p is not None:
            calib.append(encoder_input(C.apply_crop(va.rgb01(i), p)[None], C.apply_crop(m, p)[None]))
    gen = torch.Generator().manual_seed(7)
    common = {
        "image_u8": va.image[gi].permute(1, 2, 0).contiguous().numpy(),
        "mask_u8": va.mask[gi][0].numpy(),
        "crop": np.array(crop, dtype=np.float32),
        "points": pts.numpy().astype(np.float32),
    }
    cards = {}
    runs = sorted(p.parent for p in args.runs.glob("*/ckpt.pt"))
    for run in runs:
        name = run.name
        if args.only and name not in args.only:
            continue
        budget = json.loads((run / "budget.json").read_text()) if (run / "budget.json").exists() else {}
        if name == "seg":
            st, (sd,) = load_modules(run, ["seg"])
            net = SegNet(int(budget.get("args", {}).get("width", 12)))
            net.load_state_dict(sd)
            net.eval()
            inp = rgb[None]
            path = out / "seg.onnx"
            meta = {"kind": "seg", "input_size": 256, "precision": "f32", "run": name}
            export(Sig(net), (inp,), ["image"], ["mask"], path, meta, False)
            quantize(path, out / "seg.int8.onnx", [{"image": va.rgb01(i)[None].numpy()} for i in range(0, len(va), max(1, len(va) // 16))])
            with torch.no_grad():
                prob = torch.sigmoid(net(inp))[0, 0]
            iy, ix, vals = golden_sample(prob[None], 512, gen)
            save_file({**common, "iy": iy.int().numpy(), "ix": ix.int().numpy(), "mask_prob": vals[:, 0].numpy()}, str(out / "golden" / "seg.safetensors"))
            macs = count_macs(net, inp)
            cards["seg"] = {"files": ["seg.onnx", "seg.int8.onnx"], "params": params(net), "gmacs_frame": macs / 1e9, "budget": budget}
            continue
        if name == "color":
            st, (se, sm) = load_modules(run, ["enc", "mlp"])
            enc, mlp = ColorEncoder(), ColorMlp()
            enc.load_state_dict(se)
            mlp.load_state_dict(sm)
            enc.eval(), mlp.eval()
            fc = enc.net[-1].out_channels
            meta = {"kind": "color-encoder", "input_size": 256, "feature_channels": fc, "feature_size": 64, "sample": SAMPLE_RULE, "precision": "f32", "run": name}
            export(enc, (x,), ["image"], ["features"], out / "color.encoder.onnx", meta, False)
            n = 64
            fb, rb, zb = torch.randn(n, fc), torch.rand(n, 3), torch.rand(n, 1) * 2 - 1
            meta = {"kind": "color-mlp", "feature_channels": fc, "precision": "f32", "run": name}
            export(mlp, (fb, rb, zb), ["feat", "rgb", "z"], ["rgb_out"], out / "color.mlp.onnx", meta, True)
            with torch.no_grad():
                feat = enc(x)
                f = sample_features(feat, pts[None, :, :2])[0]
                prgb = sample_features(x[:, :3] * 0.5 + 0.5, pts[None, :, :2])[0]
                col = mlp(f, prgb, pts[:, 2:3])
            iy, ix, fv = golden_sample(feat[0], 256, gen)
            save_file({**common, "iy": iy.int().numpy(), "ix": ix.int().numpy(), "features": fv.numpy(), "rgb_out": col.numpy()}, str(out / "golden" / "color.safetensors"))
            cards["color"] = {"files": ["color.encoder.onnx", "color.mlp.onnx"], "params": params(enc) + params(mlp), "gmacs_frame": count_macs(enc, x) / 1e9, "macs_point": count_macs(mlp, fb[:1], rb[:1], zb[:1]), "budget": budget}
            continue
        variant = budget.get("args", {}).get("variant", "compact")
        if variant not in SHAPE_VARIANTS:
            continue
        st, (se, sm) = load_modules(run, ["enc", "mlp"])
        enc, mlp, zenc = make_shape(variant)
        enc.load_state_dict(se)
        mlp.load_state_dict(sm)
        enc.eval(), mlp.eval()
        f_ch = SHAPE_VARIANTS[variant][1]
        zdim = SOFTZ_BINS if zenc == "softz" else 1
        base = f"shape-{name}"
        emeta = {"kind": "shape-encoder", "variant": variant, "input_size": 256, "feature_channels": f_ch, "feature_size": 64, "sample": SAMPLE_RULE, "crop_fill": C.FILL, "precision": "f32", "run": name}
        export(enc, (x,), ["image"], ["features"], out / f"{base}.encoder.onnx", emeta, False)
        n = 64
        fb, zb = torch.randn(n, f_ch), encode_z(torch.rand(n) * 2 - 1, zenc)
        mmeta = {"kind": "shape-mlp", "variant": variant, "feature_channels": f_ch, "z_encoding": zenc, "z_dim": zdim, "precision": "f32", "run": name}
        export(Sig(mlp), (fb, zb), ["feat", "z"], ["occ"], out / f"{base}.mlp.onnx", mmeta, True)
        files = [f"{base}.encoder.onnx", f"{base}.mlp.onnx"]
        with torch.no_grad():
            feat = enc(x)
            f = sample_features(feat, pts[None, :, :2])[0]
            occ = torch.sigmoid(mlp(f, encode_z(pts[:, 2], zenc)))[:, 0]
        iy, ix, fv = golden_sample(feat[0], 256, gen)
        save_file({**common, "iy": iy.int().numpy(), "ix": ix.int().numpy(), "features": fv.numpy(), "occ": occ.numpy()}, str(out / "golden" / f"{base}.safetensors"))
        if name in ("compact", "large"):
            quantize(out / f"{base}.encoder.onnx", out / f"{base}.encoder.int8.onnx", [{"image": c.numpy()} for c in calib])
            with torch.no_grad():
                mf = []
                for c in calib[:8]:
                    fe = enc(c)
                    fs = sample_features(fe, pts[None, :, :2])[0]
                    mf.append({"feat": fs.numpy(), "z": encode_z(pts[:, 2], zenc).numpy()})
            quantize(out / f"{base}.mlp.onnx", out / f"{base}.mlp.int8.onnx", mf)
            files += [f"{base}.encoder.int8.onnx", f"{base}.mlp.int8.onnx"]
        cards[base] = {"files": files, "variant": variant, "params": params(enc) + params(mlp), "gmacs_frame": count_macs(enc, x) / 1e9, "macs_point": count_macs(mlp, fb[:2], zb[:2]) // 2, "budget": budget}
    index = out / "models.json"
    old = json.loads(index.read_text()) if index.exists() else {}
    old.update(cards)
    index.write_text(json.dumps(old, indent=2, sort_keys=True))
    for name, c in cards.items():
        write_card(out, name, c, args.data)
    print(json.dumps({k: v["files"] for k, v in cards.items()}, indent=1))


def write_card(out: Path, name: str, c: dict, data: Path):
    b = c.get("budget", {})
    a = b.get("args", {})
    lines = [
        f"# Model card: {name}",
        "",
        f"Files: {', '.join('`' + f + '`' for f in c['files'])}. Trained and exported by `tools/train/train_all.sh`",
        "(`python -m volcap_train.train` then `python -m volcap_train.export`); the ONNX files are the one source of truth",
        "for the weights; golden input/output vectors from PyTorch are in `golden/` and checked against the engine by `cargo test`.",
        "",
        "| | |",
        "|---|---|",
        f"| task | {a.get('task', name)} |",
        f"| variant | {c.get('variant', '-')} |",
        f"| parameters | {c['params']:,} |",
        f"| GMACs per frame (encoder) | {c['gmacs_frame']:.3f} |",
        f"| MACs per point (MLP) | {c.get('macs_point', '-')} |",
        f"| OHEM | {a.get('ohem', '-')} |",
        f"| steps x batch x points | {b.get('steps', '?')} x {a.get('batch', '?')} x {a.get('points', '-')} |",
        f"| wall time | {b.get('wall_s', '?')} s |",
        f"| hardware | {json.dumps(b.get('hardware', {}))} |",
        f"| seed | {a.get('seed', '?')} |",
        f"| validation (held-out subjects) | {json.dumps(b.get('val', {}))} |",
        "",
        "**Data.** Rendered by `volcap sim dataset` from the CC0 MakeHuman assets (synthetic people, procedural poses,",
        "studio lighting; segmentation composited over procedural backgrounds with photometric extremes). Validation",
        "subjects are held out by identity. Not trained on real photographs: expect a domain gap on real cameras.",
        "",
        "**Contract.** Input NDC convention and feature sampling: `volcap.sample` metadata",
        f"(`{SAMPLE_RULE}`), person crop rule `tools/train/volcap_train/crop.py` = `service/engine/src/model/preprocess.rs`.",
        "Accuracy of the full pipeline (Chamfer, P2S, IoU, mask IoU, time per stage): `docs/eval/`.",
        "",
    ]
    (out / f"{name}.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
