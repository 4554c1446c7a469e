"""Fine-tune the segmentation network (MediaPipe's, `mediapipe_seg`) on the simulator's renders.

    python -m volcap_train.mediapipe_seg --out M        # M/seg.onnx: MediaPipe's own weights
    python -m volcap_train.seg_tune --seg M/seg.onnx --data DS16W --more-data DSF67 ... --out RUN [--steps 1500] [--mix 0.3] [--install ../../models]
    python -m volcap_train.seg_tune --seg MEDIAPIPE.onnx --mix-from RUN/tuned.onnx --mix 0.3 --out DIR [--install ../../models]   # no training

MediaPipe's segmenter was trained on real selfie imagery; on the simulator's full-body renders its
masks cut the feet and cover the gaps between legs (docs/eval/hands.md section 43), which costs the
shape network's P2S (`volcap eval --gt-mask`). This runs the ONNX graph itself in PyTorch
(`OnnxNet`: its few operators, the convolution weights as parameters, everything else as
constants), trains the weights on the train splits' images and true masks (half as rendered, half
composited over the trainer's procedural backgrounds with photometric and sensor effects; random
scale and shift as the engine's second, cropped pass sees the person), with an L2 pull towards the
original weights (`--anchor-weight`: what the real-photo training taught is kept where the renders
do not ask otherwise), and writes the same graph with the new weights (RUN/tuned.onnx) and with the
original's weights moved only a share `--mix` of the way to them (RUN/seg.onnx; weight-space
interpolation, WiSE-FT, Wortsman et al., CVPR 2022: most of the renders' gain, none of the
real photos' loss, docs/eval/hands.md section 43): one ONNX file of the same
contract (`image` [1, 3, 256, 256] RGB in [0, 1] -> `mask` person probability) that tract, ONNX
Runtime and the GPU backend run unchanged. Judge the result with `seg_compare` (real photos and
held-out renders) and `volcap eval --models-dir` (the shape's figures through the engine).
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np
import onnx
import torch
import torch.nn.functional as F
from onnx import helper, numpy_helper
from safetensors import safe_open
from tqdm import tqdm

TRAINABLE_OPS = ("Conv", "ConvTranspose")


class Unsupported(ValueError):
    pass


def _attrs(node) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


class OnnxNet(torch.nn.Module):
    """An ONNX graph of the segmenter's operators run by PyTorch, batched along dimension 0 (the
    graph's Reshape shapes fix a batch of 1: their first entry is taken as the batch). The
    weights and biases of Conv / ConvTranspose nodes are parameters; every other initializer is a
    constant. An operator outside the set is refused naming it and its node."""

    OPS = ("Identity", "Conv", "ConvTranspose", "Mul", "Add", "Relu", "Sigmoid", "HardSwish", "AveragePool", "Slice", "Concat", "Unsqueeze", "Reshape")

    def __init__(self, model: onnx.ModelProto):
        super().__init__()
        self.model = model
        g = model.graph
        for n in g.node:
            if n.op_type not in self.OPS:
                raise Unsupported(f"node {n.name or n.output[0]}: operator {n.op_type} is not supported by OnnxNet")
        inits = {i.name: numpy_helper.to_array(i) for i in g.initializer}
        train = {name for n in g.node if n.op_type in TRAINABLE_OPS for name in n.input[1:] if name in inits}
        self.names = sorted(train)  # parameter i <-> initializer self.names[i]
        self.params = torch.nn.ParameterList([torch.nn.Parameter(torch.from_numpy(inits[k].astype(np.float32).copy())) for k in self.names])
        self.consts = {k: torch.from_numpy(np.array(v)) for k, v in inits.items() if k not in train}
        self.nodes = [(n.op_type, list(n.input), list(n.output), _attrs(n), n.name or n.output[0]) for n in g.node]
        self.input = g.input[0].name
        self.output = g.output[0].name
        # The logits: the input of the Sigmoid that feeds the output (through Identity nodes).
        producer = {o: (op, ins) for op, ins, outs, _, _ in self.nodes for o in outs}
        name = self.output
        while producer.get(name, ("", []))[0] == "Identity":
            name = producer[name][1][0]
        if producer.get(name, ("", []))[0] != "Sigmoid":
            raise Unsupported(f"output {self.output}: not produced by a Sigmoid (no logits to train on)")
        self.logits_name = producer[name][1][0]

    def forward(self, x: torch.Tensor, logits: bool = False) -> torch.Tensor:
        env = dict(self.consts)
        env.update(zip(self.names, self.params))
        env[self.input] = x
        for op, ins, outs, at, name in self.nodes:
            a = [env[i] if i else None for i in ins]
            env[outs[0]] = self._run(op, a, at, name, x.shape[0])
            if logits and outs[0] == self.logits_name:
                return env[outs[0]]
        return env[self.output]

    @staticmethod
    def _run(op, a, at, name, batch):
        if op == "Identity":
            return a[0]
        if op in ("Conv", "ConvTranspose"):
            pads = at.get("pads", [0, 0, 0, 0])
            strides = tuple(at.get("strides", [1, 1]))
            dil = tuple(at.get("dilations", [1, 1]))
            x = a[0]
            if op == "ConvTranspose":
                if any(pads) or dil != (1, 1) or at.get("group", 1) != 1:
                    raise Unsupported(f"node {name}: ConvTranspose with pads, dilations or groups")
                return F.conv_transpose2d(x, a[1], a[2] if len(a) > 2 else None, stride=strides)
            t, l, b, r = pads
            if (t, l) == (b, r):
                return F.conv2d(x, a[1], a[2] if len(a) > 2 else None, strides, (t, l), dil, at.get("group", 1))
            return F.conv2d(F.pad(x, (l, r, t, b)), a[1], a[2] if len(a) > 2 else None, strides, 0, dil, at.get("group", 1))
        if op == "Mul":
            return a[0] * a[1]
        if op == "Add":
            return a[0] + a[1]
        if op == "Relu":
            return F.relu(a[0])
        if op == "Sigmoid":
            return torch.sigmoid(a[0])
        if op == "HardSwish":
            return F.hardswish(a[0])
        if op == "AveragePool":
            if any(at.get("pads", [0])) or at.get("ceil_mode", 0):
                raise Unsupported(f"node {name}: AveragePool with pads or ceil_mode")
            return F.avg_pool2d(a[0], tuple(at["kernel_shape"]), tuple(at.get("strides", at["kernel_shape"])))
        if op == "Slice":
            x = a[0]
            starts, ends = a[1].tolist(), a[2].tolist()
            axes = a[3].tolist() if len(a) > 3 and a[3] is not None else list(range(len(starts)))
            steps = a[4].tolist() if len(a) > 4 and a[4] is not None else [1] * len(starts)
            idx = [slice(None)] * x.dim()
            for s, e, ax, st in zip(starts, ends, axes, steps):
                if st != 1:
                    raise Unsupported(f"node {name}: Slice with step {st}")
                idx[ax] = slice(s, min(e, x.shape[ax]))
            return x[tuple(idx)]
        if op == "Concat":
            return torch.cat(a, dim=at["axis"])
        if op == "Unsqueeze":
            x = a[0]
            for ax in sorted(a[1].tolist()):
                x = x.unsqueeze(ax)
            return x
        if op == "Reshape":
            shape = a[1].tolist()
            if shape and shape[0] == 1:
                shape[0] = batch
            return a[0].reshape(shape)
        raise Unsupported(f"node {name}: operator {op}")

    def to_onnx(self, note: str = "") -> onnx.ModelProto:
        """The same graph with this module's parameters as its initializers (f32)."""
        m = copy.deepcopy(self.model)
        new = {k: p.detach().cpu().numpy().astype(np.float32) for k, p in zip(self.names, self.params)}
        for i, init in enumerate(m.graph.initializer):
            if init.name in new:
                m.graph.initializer[i].CopyFrom(numpy_helper.from_array(new[init.name], init.name))
        return with_note(m, note)


def with_note(m: onnx.ModelProto, note: str) -> onnx.ModelProto:
    """`note` appended to the model's doc string and to its `volcap.run` metadata (which
    `mediapipe_seg --golden-only` and models.json read: a tuned file never passes for the
    original)."""
    if note:
        m.doc_string = (m.doc_string + "\n" if m.doc_string else "") + note
        props = {p.key: p for p in m.metadata_props}
        if "volcap.run" in props:
            props["volcap.run"].value = f"{props['volcap.run'].value}, {note}"
    return m


def mix_models(base: onnx.ModelProto, tuned: onnx.ModelProto, share: float, note: str = "") -> onnx.ModelProto:
    """`base` with each floating-point initializer moved `share` of the way to `tuned`'s (0: the
    base, 1: the tuned model). The two must be one graph: the same operators in the same order
    and the same initializers with the same shapes, else the first difference is named."""
    if [n.op_type for n in base.graph.node] != [n.op_type for n in tuned.graph.node]:
        raise SystemExit("--mix-from: the tuned model's operators differ from --seg's (not one graph)")
    t = {i.name: numpy_helper.to_array(i) for i in tuned.graph.initializer}
    out = copy.deepcopy(base)
    for i, init in enumerate(out.graph.initializer):
        w0 = numpy_helper.to_array(init)
        if init.name not in t or t[init.name].shape != w0.shape:
            raise SystemExit(f"--mix-from: initializer {init.name}: missing or of another shape in the tuned model")
        if w0.dtype == np.float32 and not np.array_equal(t[init.name], w0):
            w = (w0.astype(np.float64) + share * (t[init.name].astype(np.float64) - w0)).astype(np.float32)
            out.graph.initializer[i].CopyFrom(numpy_helper.from_array(w, init.name))
    return with_note(out, note)


def install(seg: Path, models: Path) -> None:
    """Copy a tuned segmenter to MODELS/seg.onnx and name it in MODELS/models.json's `seg` entry
    (its `source`: the file's `volcap.run`, which says how it was tuned and mixed)."""
    import shutil

    shutil.copyfile(seg, models / "seg.onnx")
    run = {p.key: p.value for p in onnx.load(str(seg)).metadata_props}.get("volcap.run", "")
    index = models / "models.json"
    idx = json.loads(index.read_text()) if index.exists() else {}
    idx.setdefault("seg", {"files": ["seg.onnx"], "license": "Apache-2.0"})["source"] = run
    index.write_text(json.dumps(idx, indent=2, sort_keys=True))


def load_images(roots: list[Path], split: str = "train", limit: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """The images (u8 [N, 3, 256, 256]) and true masks (u8 [N, 1, 256, 256]) of the shards of
    each `volcap sim dataset` folder's split, read without their point samples."""
    files = [f for r in roots for f in sorted((r / split).glob("*/*.safetensors"))]
    if limit:
        files = files[:: max(1, len(files) // limit)][:limit]
    if not files:
        raise SystemExit(f"{', '.join(map(str, roots))}: no {split}/*/*.safetensors shards")
    imgs, masks = [], []
    for f in tqdm(files, desc=f"reading {split}", unit="image", leave=False):
        with safe_open(str(f), framework="np") as t:
            img, m = t.get_tensor("image"), t.get_tensor("mask")
        if img.shape != (256, 256, 3) or m.shape != (256, 256):
            raise SystemExit(f"{f}: image {img.shape} / mask {m.shape}, expected (256, 256, 3) / (256, 256)")
        imgs.append(img)
        masks.append(m)
    img = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2).contiguous()
    mask = torch.from_numpy(np.stack(masks)).unsqueeze(1).contiguous()
    if int(mask.max()) > 1:
        mask = (mask > 127).to(torch.uint8)
    return img, mask


def batch(img, mask, idx, gen, composite: float, affine: float, crop: float = 0.0):
    """One augmented batch: RGB [B, 3, 256, 256] in [0, 1] and the true mask in {0, 1}. A share
    `crop` of the images is the engine's second-pass view: the person's crop (crop.py's rule on
    the true mask) resampled to the frame's size."""
    from . import crop as C
    from .data import backgrounds, photometric, random_affine, sensor

    rgb = img[idx].float() / 255.0
    m = mask[idx].float()
    for i in torch.nonzero(torch.rand(len(idx), generator=gen) < crop).flatten().tolist():
        p = C.crop_params(m[i, 0])
        if p is not None:
            rgb[i], m[i] = C.apply_crop(rgb[i], p), C.apply_crop(m[i], p)
    comp = torch.rand(len(idx), generator=gen) < composite
    if bool(comp.any()):
        k = int(comp.sum())
        bg = backgrounds(k, rgb.shape[-1], gen)
        rgb[comp] = sensor(photometric(rgb[comp] * m[comp] + bg * (1 - m[comp]), gen), gen)
    flip = torch.rand(len(idx), generator=gen) < 0.5
    rgb[flip] = rgb[flip].flip(-1)
    m[flip] = m[flip].flip(-1)
    rgb, m, _ = random_affine(rgb, m, gen, p=affine)
    return rgb.clamp(0, 1), (m > 0.5).float()


def iou(pred: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """Per-image IoU of bool masks [B, ...]; an image where both are empty counts 1."""
    p, r = pred.flatten(1), ref.flatten(1)
    inter = (p & r).sum(1).float()
    union = (p | r).sum(1).float()
    return torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union))


@torch.no_grad()
def evaluate(net: OnnxNet, img, mask, chunk: int = 16) -> float:
    out = []
    for s in range(0, len(img), chunk):
        p = net(img[s : s + chunk].float() / 255.0) > 0.5
        out.append(iou(p, mask[s : s + chunk] > 0))
    return float(torch.cat(out).mean())


def anchor_loss(net: OnnxNet, start: list[tuple[torch.Tensor, torch.Tensor]]) -> torch.Tensor:
    """Mean over the parameters of their squared distance to the original weights, each relative
    to the original's mean square: 1.0 means a tensor moved as far as it is large. `start`:
    `anchor_start(net)`, each original tensor with its mean square (fixed for the run)."""
    terms = [((p - p0) ** 2).mean() / scale for p, (p0, scale) in zip(net.params, start)]
    return torch.stack(terms).mean()


def anchor_start(net: OnnxNet) -> list[tuple[torch.Tensor, torch.Tensor]]:
    return [(p.detach().clone(), p.detach().pow(2).mean() + 1e-8) for p in net.params]


def train(args) -> dict:
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    gen = torch.Generator().manual_seed(args.seed)
    net = OnnxNet(onnx.load(str(args.seg)))
    start = anchor_start(net)
    img, mask = load_images([args.data, *args.more_data], "train", args.limit)
    vimg, vmask = load_images([args.data], "val", args.val_images)
    base = evaluate(net, vimg, vmask)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, args.steps)
    args.out.mkdir(parents=True, exist_ok=True)
    log = []
    t0 = time.time()
    bar = tqdm(range(args.steps), desc="seg_tune", unit="step")
    for step in bar:
        idx = torch.randint(0, len(img), (args.batch,), generator=gen)
        x, y = batch(img, mask, idx, gen, args.composite, args.affine, args.crop)
        z = net(x, logits=True)
        bce = F.binary_cross_entropy_with_logits(z, y)
        anchor = anchor_loss(net, start)
        loss = bce + args.anchor_weight * anchor
        if not torch.isfinite(loss):
            raise SystemExit(f"seg_tune: step {step}: non-finite loss (bce {float(bce)}, anchor {float(anchor)})")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        bar.set_postfix(bce=f"{bce.item():.4f}", anchor=f"{anchor.item():.2e}")
        if (step + 1) % args.eval_every == 0 or step + 1 == args.steps:
            v = evaluate(net, vimg, vmask)
            log.append({"step": step + 1, "bce": bce.item(), "anchor": anchor.item(), "val_mask_iou": v, "seconds": time.time() - t0})
            tqdm.write(f"step {step + 1}: held-out mask IoU {v:.4f} (start {base:.4f})")
    done = f"seg_tune: {args.steps} steps on the renders (seed {args.seed})"
    tuned = net.to_onnx(done)
    onnx.save(tuned, str(args.out / "tuned.onnx"))
    onnx.save(mix_models(net.model, tuned, args.mix, f"{done}, mixed {args.mix:g}"), str(args.out / "seg.onnx"))
    budget = {
        "steps": args.steps, "batch": args.batch, "lr": args.lr, "anchor_weight": args.anchor_weight, "composite": args.composite,
        "affine": args.affine, "crop": args.crop, "mix": args.mix, "seed": args.seed, "threads": args.threads, "train_images": len(img), "seconds": time.time() - t0,
        "val_mask_iou_start": base, "log": log,
    }
    (args.out / "budget.json").write_text(json.dumps(budget, indent=1))
    return budget


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.seg_tune", description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="a `volcap sim dataset` folder (train split; its val split is the held-out check)")
    ap.add_argument("--more-data", type=Path, nargs="*", default=[], help="more folders whose train splits join the data")
    ap.add_argument("--seg", type=Path, required=True, help="the segmenter to start from: MediaPipe's (`mediapipe_seg --out M`: M/seg.onnx; the committed models/seg.onnx is already tuned)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=1e-4)
    ap.add_argument("--anchor-weight", type=float, default=1.0, help="the pull towards the original weights")
    ap.add_argument("--composite", type=float, default=0.5, help="share of images composited over procedural backgrounds")
    ap.add_argument("--affine", type=float, default=0.5, help="share of images scaled and shifted")
    ap.add_argument("--crop", type=float, default=0.3, help="share of images cropped to the person as the engine's second pass sees them")
    ap.add_argument("--mix", type=float, default=1.0, help="the share of the way from the original weights to the tuned ones in OUT/seg.onnx")
    ap.add_argument("--mix-from", type=Path, default=None, help="no training: OUT/seg.onnx = --seg moved --mix of the way to this tuned model")
    ap.add_argument("--install", type=Path, default=None, help="a models folder: copy OUT/seg.onnx there as seg.onnx and name it in its models.json")
    ap.add_argument("--limit", type=int, default=0, help="at most this many training images (spread over the sets; 0: all)")
    ap.add_argument("--val-images", type=int, default=192)
    ap.add_argument("--eval-every", type=int, default=250)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    for name in ("steps", "batch", "eval_every", "threads", "val_images"):
        if getattr(args, name) <= 0:
            ap.error(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}")
    if not (args.lr > 0 and np.isfinite(args.lr)):
        ap.error(f"--lr must be a positive number, got {args.lr}")
    for name in ("anchor_weight", "composite", "affine", "crop", "mix"):
        v = getattr(args, name)
        if not (np.isfinite(v) and v >= 0) or (name != "anchor_weight" and v > 1):
            ap.error(f"--{name.replace('_', '-')}: {v} is out of range")
    if not args.seg.exists():
        ap.error(f"--seg {args.seg}: no such file")
    if args.install is not None and not args.install.is_dir():
        ap.error(f"--install {args.install}: not a folder")
    if args.mix_from is not None:
        if not args.mix_from.exists():
            ap.error(f"--mix-from {args.mix_from}: no such file")
        args.out.mkdir(parents=True, exist_ok=True)
        import hashlib

        tag = hashlib.sha256(args.mix_from.read_bytes()).hexdigest()[:8]
        note = f"seg_tune: mixed {args.mix:g} with tuned weights sha256:{tag}"
        onnx.save(mix_models(onnx.load(str(args.seg)), onnx.load(str(args.mix_from)), args.mix, note), str(args.out / "seg.onnx"))
        print(f"seg_tune: {args.out / 'seg.onnx'}: {args.seg} moved {args.mix:g} of the way to {args.mix_from}")
        if args.install:
            install(args.out / "seg.onnx", args.install)
        return
    if args.data is None:
        ap.error("--data is required to train (or --mix-from to only mix)")
    b = train(args)
    if args.install:
        install(args.out / "seg.onnx", args.install)
    print(f"seg_tune: {args.out / 'seg.onnx'}: held-out mask IoU {b['val_mask_iou_start']:.4f} -> {b['log'][-1]['val_mask_iou']:.4f} in {b['seconds']:.0f} s")


if __name__ == "__main__":
    main()
