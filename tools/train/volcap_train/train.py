"""Training: `python -m volcap_train.train {seg,shape,color} --data DIR --out RUN [...]`.

Every run is seeded, resumable (a checkpoint every --ckpt-every steps and at the end; a run
that is cut off continues from its last checkpoint with the same data order), shows a
progress bar, logs losses to RUN/log.csv and records its budget (steps, wall time and where
it went, hardware) in RUN/budget.json for the model card: the run folder and the loop are
`runs.py`; the Fourier head's training items (targets, caches, several datasets joined, the
upper-body variant) are `items.py`; this module holds each network's step.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from . import crop as C
from .data import Split, backgrounds, photometric, random_affine, sensor
from . import fourier as FO
from .nets import FOURIER_VARIANTS, ColorEncoder, FourierGeomNet, make_fourier, fourier_variant, ColorMlp, FourierNet, SegNet, encode_z, encoder_input, make_shape, sample_features
from .ohem import OhemState
from .ray_losses import centre_aligned, check_hinge_options, ray_hinges, ray_level_bce, thin_mask
from .runs import Run, device, init_weights, loop, make_ema, recompute_bn
from .surfaces import GeomHead, geometry_loss, surface_depths
from .items import fourier_cached, fourier_union, fourier_upper_cached


def cropped(split: Split):
    """Crop every image around its (ground-truth) person mask with the engine's rule and
    move its points into crop NDC. Returns encoder inputs [B,4,256,256] and the moved tensors."""
    xs, pts, surf, keep = [], [], [], []
    for i in range(len(split)):
        m = split.mask01(i)
        p = C.crop_params(m[0])
        if p is None:
            continue
        rgb = C.apply_crop(split.rgb01(i), p)
        mm = C.apply_crop(m, p)
        xs.append(encoder_input(rgb[None], mm[None])[0])
        pts.append(C.to_crop(split.points[i], p))
        surf.append(C.to_crop(split.surface[i], p))
        keep.append(i)
    keep = torch.tensor(keep)
    return torch.stack(xs), torch.stack(pts), split.occ[keep], torch.stack(surf), split.surface_rgb[keep], keep


def cropped_cached(root: Path, split: str):
    """`cropped` of a split, cached beside the shards (it is deterministic)."""
    cache = root / f"cropped-{split}.pt"
    if cache.exists():
        return torch.load(cache)
    out = cropped(Split(root, split))
    torch.save(out, cache)
    return out


def perturb_mask(m: torch.Tensor, gen: torch.Generator, p: float = 0.5) -> torch.Tensor:
    """Segmentation-like mask errors for a fraction p of the images: the mask dilated or
    eroded by 1-3 pixels (the encoder sees predicted masks at run time). On `gen`'s device;
    the draws are read back once for the batch (one wait on a GPU, not three per image)."""
    out = m.clone()
    draws = torch.rand((m.shape[0], 3), generator=gen, device=gen.device).tolist()
    for i, (apply, radius, grow) in enumerate(draws):
        if apply >= p:
            continue
        r = 1 + min(int(radius * 3), 2)
        k = 2 * r + 1
        if grow < 0.5:
            out[i] = F.max_pool2d(m[i : i + 1], k, 1, r)[0]
        else:
            out[i] = -F.max_pool2d(-m[i : i + 1], k, 1, r)[0]
    return out


def predict_points(net: FourierNet, rgb: torch.Tensor, mask: torch.Tensor, points: torch.Tensor, batch: int = 8) -> torch.Tensor:
    """A Fourier net's occupancy [B, N] at crop-NDC points [B, N, 3] of crops given as u8
    RGB [B, 3, S, S] and masks [B, 1, S, S], in batches, without gradients."""
    out = []
    with torch.no_grad():
        for s in range(0, len(rgb), batch):
            x = encoder_input(rgb[s : s + batch].float() / 255, mask[s : s + batch].float() / 255)
            out.append(fourier_query(net(x), points[s : s + batch], net.k))
    return torch.cat(out)


def fourier_query(coeff: torch.Tensor, pts: torch.Tensor, k: int) -> torch.Tensor:
    """The whole point query of the Fourier head: coefficient maps [B, 2K+1, H, W], crop-NDC
    points [B, N, 3] -> occupancy [B, N] (grid_sample rule of the engine, zeta from crop z)."""
    c = sample_features(coeff, pts[..., :2])  # [B, N, 2K+1]
    return FO.decode(c, pts[..., 2] * FO.ZETA_SCALE, k)


def train_seg(args):
    torch.manual_seed(args.seed)
    gen = torch.Generator().manual_seed(args.seed)
    tr, va = Split(args.data, "train"), Split(args.data, "val")
    net = SegNet(args.width)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    run = Run(args.out, args)

    def batch(split, idx, g):
        rgb, m = split.rgb01(idx), split.mask01(idx)
        rgb, m, _ = random_affine(rgb, m, g)
        bg = backgrounds(len(idx), rgb.shape[-1], g)
        x = rgb * m + bg * (1 - m)
        return photometric(x, g), m

    def step_fn(step):
        idx = torch.randint(0, len(tr), (args.batch,), generator=gen)
        x, m = batch(tr, idx, gen)
        loss = F.binary_cross_entropy_with_logits(net(x), m)
        opt.zero_grad()
        loss.backward()
        opt.step()
        return loss.item()

    def eval_fn():
        g = torch.Generator().manual_seed(1234)
        ious = []
        for s in range(0, len(va), 16):
            idx = torch.arange(s, min(s + 16, len(va)))
            x, m = batch(va, idx, g)
            p = torch.sigmoid(net(x)) > 0.5
            t = m > 0.5
            inter = (p & t).flatten(1).sum(1).float()
            union = (p | t).flatten(1).sum(1).float()
            ious.append(torch.where(union > 0, inter / union.clamp(min=1), torch.ones_like(union)))
        iou = torch.cat(ious)
        return {"mask_iou_mean": iou.mean().item(), "mask_iou_min": iou.min().item(), "images": len(iou)}

    return loop(run, {"seg": net}, opt, args.steps, step_fn, eval_fn, {"gen": gen})


def train_shape(args):
    torch.manual_seed(args.seed)
    gen = torch.Generator().manual_seed(args.seed)
    xtr, ptr, otr, _, _, _ = cropped_cached(args.data, "train")
    xva, pva, ova, _, _, _ = cropped_cached(args.data, "val")
    enc, mlp, zenc = make_shape(args.variant)
    ohem = OhemState(len(xtr), ptr.shape[1], args.ohem)
    params = list(enc.parameters()) + list(mlp.parameters())
    opt = torch.optim.Adam(params, lr=args.lr)
    run = Run(args.out, args)

    def forward(x, pts):
        feat = enc(x)
        f = sample_features(feat, pts[..., :2])  # [B, P, F]
        b, p, c = f.shape
        logit = mlp(f.reshape(b * p, c), encode_z(pts[..., 2].reshape(b * p), zenc))
        return logit.reshape(b, p)

    def step_fn(step):
        items = ohem.sample_items(args.batch, gen)
        pidx = ohem.sample_points(items, args.points, gen)
        pts = torch.gather(ptr[items], 1, pidx.unsqueeze(-1).expand(-1, -1, 3))
        lab = torch.gather(otr[items], 1, pidx)
        logit = forward(xtr[items], pts)
        bce = F.binary_cross_entropy_with_logits(logit, lab, reduction="none")
        loss = bce.mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        ohem.update(items, pidx, bce, torch.sigmoid(logit), lab)
        return loss.item()

    def eval_fn():
        ious, bces = [], []
        for s in range(0, len(xva), 8):
            sl = slice(s, s + 8)
            logit = forward(xva[sl], pva[sl])
            lab = ova[sl]
            bces.append(F.binary_cross_entropy_with_logits(logit, lab, reduction="none").mean(1))
            p, t = logit > 0, lab > 0.5
            ious.append(((p & t).sum(1).float() / (p | t).sum(1).clamp(min=1).float()).cpu())
        iou = torch.cat(ious)
        return {"point_iou_mean": iou.mean().item(), "point_iou_worst10": iou.sort().values[:10].mean().item(), "bce": torch.cat(bces).mean().item(), "images": len(iou)}

    return loop(run, {"enc": enc, "mlp": mlp}, opt, args.steps, step_fn, eval_fn, {"gen": gen, "ohem": ohem})


def exposure_targets(x: torch.Tensor, surf: torch.Tensor, albedo: torch.Tensor, batch: int = 64) -> torch.Tensor:
    """Colour targets at the input's exposure: per image and channel, the least-squares gain
    that maps the albedo of the surface samples nearest the camera (the even ones of a
    `"surface": "seen"` dataset: where each sampled pixel's ray first meets the person) onto
    the input pixels there, times every sample's albedo, in [0, 1]. Encoder inputs x [B, 4,
    S, S], crop-NDC samples [B, M, 3], albedo [B, M, 3]. The back then has the brightness and
    tint the input shows the front in (what `volcap eval`'s colour columns compare against)."""
    out = []
    for s in range(0, len(x), batch):
        sl = slice(s, s + batch)
        front = surf[sl, 0::2]
        pix = sample_features(x[sl, :3] * 0.5 + 0.5, front[..., :2])
        a = albedo[sl, 0::2]
        gain = ((pix * a).sum(1) / (a * a).sum(1).clamp_min(1e-6)).clamp(0.05, 20.0)
        out.append((albedo[sl] * gain[:, None, :]).clamp(0.0, 1.0))
    return torch.cat(out)


def seen_surface_dataset(root: Path) -> None:
    """Refuse a dataset whose coloured surface samples hold the body under the clothes (made
    before `volcap sim dataset` sampled the surface the views show: no `"surface": "seen"` in
    its dataset.json): a colour network learns skin no view shows from it."""
    manifest = Path(root) / "dataset.json"
    seen = manifest.exists() and json.loads(manifest.read_text()).get("surface") == "seen"
    if not seen:
        raise SystemExit(
            f'{manifest}: no "surface": "seen": its colour samples cover the whole clothed surface, the body under '
            "the clothes too; make the dataset again with this volcap (`volcap sim dataset`) to train colour"
        )


def train_color(args):
    torch.manual_seed(args.seed)
    gen = torch.Generator().manual_seed(args.seed)
    seen_surface_dataset(args.data)
    xtr, _, _, str_, ctr, _ = cropped_cached(args.data, "train")
    xva, _, _, sva, cva, _ = cropped_cached(args.data, "val")
    ctr, cva = exposure_targets(xtr, str_, ctr), exposure_targets(xva, sva, cva)
    enc, mlp = ColorEncoder(), ColorMlp()
    opt = torch.optim.Adam(list(enc.parameters()) + list(mlp.parameters()), lr=args.lr)
    run = Run(args.out, args)

    def forward(x, pts):
        f = sample_features(enc(x), pts[..., :2])
        rgb = sample_features(x[:, :3] * 0.5 + 0.5, pts[..., :2])
        b, p, c = f.shape
        out = mlp(f.reshape(b * p, c), rgb.reshape(b * p, 3), pts[..., 2].reshape(b * p, 1))
        return out.reshape(b, p, 3)

    def step_fn(step):
        items = torch.randint(0, len(xtr), (args.batch,), generator=gen)
        pidx = torch.randint(0, str_.shape[1], (args.batch, args.points), generator=gen)
        pts = torch.gather(str_[items], 1, pidx.unsqueeze(-1).expand(-1, -1, 3))
        col = torch.gather(ctr[items], 1, pidx.unsqueeze(-1).expand(-1, -1, 3))
        loss = (forward(xtr[items], pts) - col).abs().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        return loss.item()

    def eval_fn():
        l1 = []
        for s in range(0, len(xva), 8):
            sl = slice(s, s + 8)
            l1.append((forward(xva[sl], sva[sl]) - cva[sl]).abs().mean((1, 2)))
        l1 = torch.cat(l1)
        return {"color_l1_mean": l1.mean().item(), "images": len(l1)}

    return loop(run, {"enc": enc, "mlp": mlp}, opt, args.steps, step_fn, eval_fn, {"gen": gen})


def mirror_some(t: torch.Tensor, flips: torch.Tensor | None) -> torch.Tensor:
    """Images or maps [B, C, H, W] mirrored left-right where `flips` [B] is true (None: as
    they are). Exact in crop NDC on any grid with align_corners=True: pixel i of W sits at
    x = -1 + 2 i / (W - 1), pixel W - 1 - i at -x, so the 256 px input and the 128 px maps
    mirror about the same axis."""
    if flips is None:
        return t
    return torch.where(flips.view(-1, 1, 1, 1), t.flip(-1), t)


def items_bytes(sets) -> int:
    return sum(v.numel() * v.element_size() for d in sets for v in d.values() if torch.is_tensor(v))


def data_on_device(choice: str, dev: torch.device, sets) -> bool:
    """`--data-device`: whether the items go to the training device. `host`: never; `device`:
    always (a CPU device is the host); `auto`: on a GPU when they take at most half of its
    free memory (the rest is the net's: activations, gradients, optimizer state)."""
    if dev.type == "cpu" or choice == "host":
        return False
    if choice == "device":
        return True
    free, _ = torch.cuda.mem_get_info(dev)
    need = items_bytes(sets)
    print(f"items {need / 2**30:.2f} GiB, device free {free / 2**30:.2f} GiB")
    return need <= free // 2


# With torch 2.15 on this CPU every encoder weight's gradient came out non-finite after the
# first backward of the compiled bfloat16 graph (eager bfloat16 and compiled float32 are finite).
COMPILE_BF16_REFUSED = "--compile with --amp bf16: the compiled bfloat16 backward gives non-finite gradients (torch's inductor on CPU, measured with torch 2.15); use one of them"


def training_forward(fn, modules, amp: str = "off", compile: bool = False):
    """The training steps' forward of `fn` (input [B, C, H, W] -> a tuple of tensors or None).
    `amp` "bf16": under autocast in bfloat16 (AMX or AVX-512 BF16 on a CPU that has them,
    tensor cores on a GPU), each output brought back to float32, so every loss, its
    exponentials and the optimizer stay float32. `compile`: the forward graph compiled
    (torch.compile; the backward follows it). Either puts the modules' weights and the input
    in channels-last order (what oneDNN's convolutions want on a CPU). Both at once are
    refused (COMPILE_BF16_REFUSED; `main` refuses them before any data is read)."""
    if amp not in ("off", "bf16"):
        raise ValueError(f"amp {amp!r}: off or bf16")
    if compile and amp != "off":
        raise ValueError(COMPILE_BF16_REFUSED)
    if not compile and amp == "off":
        return fn
    for m in modules:
        m.to(memory_format=torch.channels_last)
    f = torch.compile(fn, dynamic=False) if compile else fn

    def forward(x):
        x = x.contiguous(memory_format=torch.channels_last)
        with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=amp == "bf16"):
            out = f(x)
        return tuple(None if t is None else t.float() for t in out)

    return forward


def load_teacher(path: Path, variant: str, k: int) -> nn.Module:
    """--teacher: a trained Fourier net (a light checkpoint or a run's ckpt.pt: its moving
    average where it has one) of `variant`, frozen in inference mode; refused, naming the file,
    where it is missing, is not a checkpoint, does not fit the variant or has another K."""
    if variant not in FOURIER_VARIANTS:
        raise SystemExit(f"--teacher-variant {variant}: not a Fourier variant ({', '.join(sorted(FOURIER_VARIANTS))})")
    tk = fourier_variant(variant)[0]
    if tk != k:
        raise SystemExit(f"--teacher-variant {variant}: K = {tk}, the student's K = {k}: their maps cannot be compared")
    if not path.exists():
        raise SystemExit(f"--teacher {path}: no such checkpoint")
    net = make_fourier(variant)
    try:
        net.load_state_dict(init_weights(torch.load(path, weights_only=False, map_location="cpu"), path))
    except RuntimeError as e:
        raise SystemExit(f"--teacher {path}: not a {variant} checkpoint ({str(e).splitlines()[0]})")
    net.eval().requires_grad_(False)
    return net


def teacher_forward(teacher: nn.Module, amp: str = "off"):
    """The teacher's coefficient maps of an encoder input, without gradients, through the
    student's `training_forward` (bfloat16 and channels-last with --amp bf16; float32 out)."""
    forward = training_forward(lambda x: (teacher(x),), [teacher], amp)

    def maps(x: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return forward(x)[0]

    return maps


def distill_loss(pred: torch.Tensor, teacher_pred: torch.Tensor, flips: torch.Tensor | None = None) -> torch.Tensor:
    """The Parseval L2 of the net's maps against the teacher's (`teacher_pred` from the mirrored
    input where `flips` says so, mirrored back here), over every pixel."""
    return FO.parseval_l2(pred, mirror_some(teacher_pred, flips), dim=1).mean()


def train_fourier(args):
    """The Fourier head, densely supervised: every pixel's whole ray (Parseval L2 on the
    coefficients) plus BCE on labelled 3D points through the basis (OHEM on points and images).
    The BCE uses the series' occupancy as a logit around the 0.5 level, tau (occ - 0.5), which
    is what the surface needs and stays finite for any series value."""
    if args.upper_masks == "seg" and not args.seg:
        raise SystemExit("--upper-masks seg: the cut images' masks come from --seg's model, and no --seg was given")
    torch.manual_seed(args.seed)
    gen = torch.Generator().manual_seed(args.seed)
    k, width, shift = fourier_variant(args.variant)
    # --teacher: checked before the data are read.
    teacher = load_teacher(args.teacher, args.teacher_variant, k) if args.teacher else None
    # --seg: the crops and mask channels from the product's segmentation (what the engine
    # feeds the encoder), for training and validation alike; targets stay the ground truth's.
    # --more-data: further datasets' training images (new poses of the same identities, or new
    # identities from another seed), one set of items; validation stays --data's.
    tr = fourier_union([args.data, *args.more_data], "train", k, args.seg, args.segment_passes)
    va = fourier_cached(args.data, "val", k, args.seg, args.segment_passes)
    if args.upper_every:
        # Upper bodies cut by the frame's lower edge (a webcam at a desk): added to the
        # training images (the validation set stays whole bodies, the product's eval).
        # With --seg their masks are the product's of the cut images (`--upper-masks seg`).
        up_seg = args.seg if args.upper_masks == "seg" else None
        up = fourier_upper_cached(args.data, "train", k, args.upper_every, up_seg, args.segment_passes)
        tr = {n: (torch.cat([tr[n], up[n] + (len(tr["keep"]) if n == "keep" else 0)]) if torch.is_tensor(tr[n]) else tr[n]) for n in tr}
        print(f"training on {len(tr['rgb'])} images, {len(up['rgb'])} of them upper-body crops")
    if args.depth_frame == "body":
        # Depth relative to the body (FO.centre_depth): where the camera stood is not learnable.
        for d in (tr, va):
            FO.centre_depth(d["coeff"], d["points"], k)
    net = make_fourier(args.variant)
    modules = {"net": net}
    two_nets = isinstance(net, FourierGeomNet)
    if two_nets and args.geom_weight <= 0:
        raise SystemExit(f"--variant {args.variant}: its surface net needs --geom-weight (the weight of its supervision)")
    if args.geom_weight > 0:
        # --geom-weight: the front and back surfaces' depth maps (surfaces.py), from the
        # targets as the net learns them (after the body depth frame), once per item. Their
        # predictor: FourierGeomNet's surface net, or a training-only head on the series
        # head's features.
        for d in (tr, va):
            g, ins = surface_depths(d["coeff"], k)
            d["geom"], d["geom_in"] = g.half(), ins
        if not two_nets:
            modules["geom"] = GeomHead(2 * width)

    def predict_f32(x, n=net):
        """(series, depth centre or None, surfaces or None) of an encoder input, through `n`
        (the net, or its moving average for the validation)."""
        if two_nets:
            surf = n.surfaces(x)
            return n.series_of(x, surf), None, surf
        feat = n.features(x)
        pred, d = n.head(feat, with_centre=True)
        return pred, d, (modules["geom"](feat) if "geom" in modules else None)

    train_forward = training_forward(predict_f32, modules.values(), args.amp, args.compile)

    def predict(x, train=True):
        # The validation runs in float32, uncompiled, so runs compare on one footing, and on
        # the weights that ship (the moving average with --ema).
        return train_forward(x) if train else predict_f32(x, modules["ema"].module if "ema" in modules else net)

    ohem = OhemState(len(tr["rgb"]), tr["points"].shape[1], args.ohem)
    opt = torch.optim.Adam([p for m in modules.values() for p in m.parameters()], lr=args.lr)
    sched_total = max(args.steps, 1)
    run = Run(args.out, args)
    if args.init and not run.ckpt.exists():
        light = torch.load(args.init, weights_only=False, map_location="cpu")
        sd = init_weights(light, args.init)
        if two_nets and not any(n.startswith("series.") for n in sd):
            # A FourierNet checkpoint (fourier-small's): both halves start from it.
            net.from_small(sd)
        else:
            own = net.state_dict()
            for n, v in sd.items():
                if n in own and own[n].shape != v.shape and own[n].shape[1:] == v.shape[1:]:
                    # A shift variant from an unshifted checkpoint: the head gains the centre
                    # channel, zeroed (d = 0: the old series unrotated, so the net starts as the
                    # checkpoint's function); the series channels start from the old ones.
                    w = torch.zeros_like(own[n])
                    w[: v.shape[0]] = v
                    sd[n] = w
            for n, v in own.items():
                if n.split(".")[0] in ("e0x", "d0x") and n not in sd:
                    # An -hr variant from a plain checkpoint: its blocks at the maps'
                    # resolution keep their identity start (nets.FourierNet's `hr`).
                    sd[n] = v
            net.load_state_dict(sd)
        print(f"initialized from {args.init} (trained {light.get('step', '?')} steps before; optimizer state restarts)")
    tau = 10.0
    # --device: the net, the batches' augmentation and the losses there; --data-device: the
    # items too (a GPU then makes each batch without the host: the H100 recipe run, with the
    # batches made on the host, trained at 16 steps/s, and augmenting a batch of 8 takes
    # 63-80 ms of one CPU core). OHEM's sampling stays on the host.
    dev = device(args.device)
    for m in modules.values():
        m.to(dev)
    on_dev = data_on_device(args.data_device, dev, [tr, va])
    if on_dev:
        tr, va = ({n: v.to(dev) if torch.is_tensor(v) else v for n, v in d.items()} for d in (tr, va))
    if args.ema != 0:
        # --ema: a moving average of the weights and BatchNorm statistics, updated after every
        # step from the starting weights (--init's); it is what validates and ships (export,
        # light checkpoints, --init from this run). A checkpoint keeps it beside the net.
        modules["ema"] = make_ema(net, args.ema)
    if teacher is not None:
        teacher_maps = teacher_forward(teacher.to(dev), args.amp)
    # The augmentations draw on the device they run on (`gen` stays the host's: OHEM, flips).
    agen = gen if dev.type == "cpu" else torch.Generator(device=dev).manual_seed(args.seed + 1)
    print(f"training on {dev}, items on {'the device' if on_dev else 'the host'}")

    def inputs(d, idx, g):
        idx = idx.to(d["rgb"].device)
        rgb = d["rgb"][idx].to(dev).float() / 255.0
        m = d["mask"][idx].to(dev).float() / 255.0
        if g is not None:
            rgb = sensor(photometric(rgb, g), g)
            # --mask-aug: the draws are made at any fraction (0 included), so a run differs
            # from its control in the masks alone.
            m = perturb_mask(m, g, args.mask_aug)
        return encoder_input(rgb, m)

    def targets(d, idx):
        """The batch's target maps on the training device (once per step: the dense, moment
        and centre losses share them)."""
        return d["coeff"][idx.to(d["coeff"].device)].to(dev).float()

    def losses(pred, target, d, idx, pidx, thin=0.0, align=False):
        at = d["points"].device
        idx, pidx = idx.to(at), pidx.to(at)
        pts = torch.gather(d["points"][idx], 1, pidx.unsqueeze(-1).expand(-1, -1, 3)).to(dev)
        lab = torch.gather(d["occ"][idx], 1, pidx).to(dev)
        centre_l1 = None
        if align:
            # --centre-align: each ray's profile judged at the depth the net put it (the
            # target and the labelled points moved there), its depth by the centroid's L1.
            only = thin_mask(target, args.align_radius)[:, 0] > 0.5 if args.align_radius > 0 else None
            target, shift, centre_l1 = centre_aligned(pred, target, k, only=only)
            pts = pts.clone()
            pts[..., 2] = pts[..., 2] + sample_features(shift, pts[..., :2])[..., 0] / FO.ZETA_SCALE
        l2 = FO.parseval_l2(pred, target, dim=1)
        occ = fourier_query(pred, pts, k)
        bce = F.binary_cross_entropy_with_logits(tau * (occ - 0.5), lab, reduction="none")
        if thin > 0:
            # --thin-weight: thin parts' rays and points count (1 + thin) times; the means
            # are normalized by the weights so the loss scale stays the unweighted one's.
            t = thin_mask(target, args.thin_radius)
            w = 1.0 + thin * t[:, 0]
            dense = (l2 * w).sum() / w.sum()
            wp = 1.0 + thin * sample_features(t, pts[..., :2])[..., 0]  # the query's sampling rule
            bce = bce * wp / wp.mean()
        else:
            dense = l2.mean()
        if centre_l1 is not None:
            dense = dense + args.align_weight * centre_l1
        return dense, bce, occ, lab

    # Host seconds inside the steps (budget.json time_s): the batch made (OHEM sampling,
    # augmentation, the input to the device) and the OHEM statistics updated (which waits for
    # the device's losses). The rest of "steps" is the net's forward and backward.
    parts = {"batch": 0.0, "ohem update": 0.0}

    def synced():
        # --sync-parts: the device's queue drained at a part's edges (asynchronous launches
        # otherwise land in whichever part next waits for the device).
        if args.sync_parts and dev.type == "cuda":
            torch.cuda.synchronize(dev)

    def step_fn(step):
        for gparam in opt.param_groups:
            gparam["lr"] = args.lr * 0.5 * (1 + math.cos(math.pi * run.progress(step, sched_total)))
        synced()
        tb = time.time()
        items = ohem.sample_items(args.batch, gen)
        pidx = ohem.sample_points(items, args.points, gen)
        x = inputs(tr, items, None if args.no_aug else agen)
        target = targets(tr, items)
        synced()
        parts["batch"] += time.time() - tb
        flips = (torch.rand(len(items), generator=gen) < 0.5).to(dev) if args.flip else None
        xin = mirror_some(x, flips)
        pred, d, geo = predict(xin)
        # A mirrored image's maps, mirrored back, are compared with the image's own targets:
        # the same as training on the mirrored person with mirrored targets.
        pred = mirror_some(pred, flips)
        d = mirror_some(d, flips) if d is not None else None
        dense, bce, occ, lab = losses(pred, target, tr, items, pidx, args.thin_weight, args.centre_align)
        loss = dense + args.point_weight * bce.mean()
        if teacher is not None:
            # --teacher: the teacher's maps of the same (augmented, mirrored) input, mirrored
            # back as the net's are, a second dense target beside the truth's.
            loss = loss + args.teacher_weight * distill_loss(pred, teacher_maps(xin), flips)
        # --peak-weight, --over-weight, --empty-weight: the thin and empty rays' hinges.
        loss = loss + ray_hinges(pred, target, k, args)
        if args.ray_bce_weight > 0:
            loss = loss + args.ray_bce_weight * ray_level_bce(pred, target, k, args.ray_samples, gen, tau)
        if args.moment_weight > 0:
            # Depth order: L1 on each ray's first moment int z f dz (linear in the sine terms),
            # whose L2 share in the Parseval loss is small next to the ray length's.
            loss = loss + args.moment_weight * (FO.first_moment(pred, k) - FO.first_moment(target, k)).abs().mean()
        if geo is not None:
            geo = mirror_some(geo, flips)  # depths do not change sign in a mirror
            at = tr["geom"].device
            gt, gin = tr["geom"][items.to(at)].to(dev).float(), tr["geom_in"][items.to(at)].to(dev)
            loss = loss + args.geom_weight * geometry_loss(geo, gt, gin, slope_weight=args.geom_slope_weight)
        if d is not None:
            # The shift variants: the depth centre supervised directly (L1, zeta units) on
            # the rays that hold the body, so the phase starts near the right depth.
            dt, ok = FO.centroid(target, k)
            if ok.any():
                loss = loss + args.centre_weight * (d[:, 0] - dt).abs()[ok].mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if "ema" in modules:
            modules["ema"].update_parameters(net)
        synced()
        tb = time.time()
        ohem.update(items, pidx, bce.detach().cpu(), occ.detach().cpu(), lab.cpu())
        parts["ohem update"] += time.time() - tb
        return loss.item()

    def eval_fn():
        ious, l2s, geos = [], [], []
        for s in range(0, len(va["rgb"]), 8):
            idx = torch.arange(s, min(s + 8, len(va["rgb"])))
            pred, _, geo = predict(inputs(va, idx, None), train=False)
            if geo is not None:
                at = va["geom"].device
                gt, gin = va["geom"][idx.to(at)].to(dev).float(), va["geom_in"][idx.to(at)].to(dev)
                geos.append(geometry_loss(geo, gt, gin, slope_weight=args.geom_slope_weight).item())
            pidx = torch.arange(va["points"].shape[1]).expand(len(idx), -1)
            target = targets(va, idx)
            dense, _, occ, lab = losses(pred, target, va, idx, pidx)
            l2s.append(FO.parseval_l2(pred, target, dim=1).mean((1, 2)).cpu())
            p, t = occ > 0.5, lab > 0.5
            ious.append(((p & t).sum(1).float() / (p | t).sum(1).clamp(min=1).float()).cpu())
        iou = torch.cat(ious)
        out = {"point_iou_mean": iou.mean().item(), "point_iou_worst10": iou.sort().values[:10].mean().item(), "ray_l2": torch.cat(l2s).mean().item(), "images": len(iou), "k": k}
        if geos:
            out["geom_loss"] = sum(geos) / len(geos)
        return out

    def ema_statistics():
        # --ema-bn-images: the average's BatchNorm statistics recomputed for its weights on a
        # seeded draw of training images as the engine gives them (no augmentation).
        n = min(args.ema_bn_images, len(tr["rgb"]))
        idx = torch.randperm(len(tr["rgb"]), generator=torch.Generator().manual_seed(args.seed + 2))[:n]
        layers = recompute_bn(modules["ema"].module, (inputs(tr, idx[s : s + args.batch], None) for s in range(0, n, args.batch)))
        print(f"--ema: BatchNorm statistics of the average recomputed on {n} training images ({layers} layers)")

    finish = ema_statistics if "ema" in modules and args.ema_bn_images > 0 else None
    extra = {"gen": gen, "agen": agen if agen is not gen else None, "ohem": ohem, "parts": parts, "before_last_checkpoint": finish}
    return loop(run, modules, opt, args.steps, step_fn, eval_fn, extra, ckpt_every=args.ckpt_every)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.train")
    ap.add_argument("task", choices=["seg", "shape", "color", "fourier"])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--more-data", type=Path, nargs="*", default=[], help="fourier: more datasets whose training images join --data's (fourier_union): the same identities and split in new poses or lighting (`--pose-seed`), or new identities (another `--seed`; never --data's held-out ones, so only their train split is read); validation stays --data's")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--variant", default="compact")
    ap.add_argument("--ohem", default="P+I", choices=["none", "P", "P+I"])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--points", type=int, default=1024)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--width", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--point-weight", type=float, default=0.1)
    ap.add_argument("--centre-weight", type=float, default=1.0, help="Fourier shift variants: weight of the L1 loss on the ray's depth centre")
    ap.add_argument("--centre-align", action="store_true", help="fourier: judge each ray's profile at the depth the net put its mass (the target and labelled points moved to the predicted centroid) and the depth by the centroid's L1 (--align-weight): meant to let a thin part unsure in depth by its own thickness be learnt sharp instead of as a low blur; measured, it did not, and cost every ray's depth (hands.md section 31: not adopted)")
    ap.add_argument("--align-weight", type=float, default=0.2, help="fourier --centre-align: weight of the L1 on each ray's depth centroid (zeta), over the rays where both series hold mass")
    ap.add_argument("--align-radius", type=int, default=0, help="fourier --centre-align: move only the thin parts' rays (those an opening of this many map pixels removes, as --thin-radius); 0: every ray")
    ap.add_argument("--moment-weight", type=float, default=0.0, help="Fourier: weight of the L1 loss on each ray's first depth moment (depth order)")
    ap.add_argument("--depth-frame", default="body", choices=["body", "camera"], help="Fourier: targets with each image's mean depth at z = 0 (body, fourier.centre_depth) or as the camera saw them (camera: runs before 2026-11-23 evening)")
    ap.add_argument("--no-aug", action="store_true", help="no photometric/mask augmentation (the overfit check)")
    ap.add_argument("--mask-aug", type=float, default=0.5, help="fourier: the fraction of training images whose input mask is dilated or eroded by 1-3 pixels (perturb_mask) on top of the masks the data hold (with --seg: the product's own segmentation's); 0: none (the draws still made, so the batches match a run without it)")
    ap.add_argument("--flip", action="store_true", help="fourier: mirror half the training images left-right (their maps mirrored back before the losses): a mirrored person is a person")
    ap.add_argument("--upper-masks", choices=["true", "seg"], default="true", help="Fourier --upper-every: the cut images' crops and mask channels from their true masks (runs (77)-(82)) or from --seg's masks of the cut images, as the engine segments such a frame")
    ap.add_argument("--upper-every", type=int, default=0, help="Fourier: add the upper-body variant (fourier_upper_cached: the person cut by the frame's lower edge) of every N-th training image; 0: none")
    ap.add_argument("--init", type=Path, default=None, help="start from a light checkpoint (weights only, e.g. models/checkpoints/*.pt) or another run's ckpt.pt (its optimizer state dropped) when --out has none")
    ap.add_argument("--segment-passes", type=int, choices=[1, 2], default=1, help="Fourier with --seg: the engine's segmentation passes (`[model] segment_passes`): 2 segments each person's crop again (seg_masks.second_pass)")
    ap.add_argument("--seg", type=Path, default=None, help="Fourier: crops and mask channels from this ONNX segmentation model's masks (e.g. ../../models/seg.onnx, the product's) instead of the ground truth's (seg_masks)")
    ap.add_argument("--ckpt-every", type=int, default=100)
    ap.add_argument("--sync-parts", action="store_true", help="fourier on a GPU: wait for the device before and after each timed part of a step (budget.json time_s), so a part holds its own work and not the device's queue; costs some rate")
    ap.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"], help="fourier: where the net trains (auto: CUDA when present)")
    ap.add_argument("--data-device", default="auto", choices=["auto", "host", "device"], help="fourier: where the training items live (auto: on the --device when it is a GPU and they take at most half its free memory; the batches are made there without the host)")
    ap.add_argument("--thin-weight", type=float, default=0.0, help="fourier: extra weight of thin parts' rays and points (thin_mask: what an opening of --thin-radius map pixels removes; hands, wrists, ankles); 0: off")
    ap.add_argument("--thin-radius", type=int, default=2, help="fourier: the opening's radius in 128-px map pixels for --thin-weight, --peak-weight and --over-weight")
    ap.add_argument("--peak-weight", type=float, default=0.0, help="fourier: weight of the thin rays' peak hinge (peak_hinge: relu(the truth's series peak - the net's), depth-free, read at --ray-samples depths, on the rays --thin-radius's opening removes); 0: off")
    ap.add_argument("--peak-window", type=float, default=None, help="fourier --peak-weight: read the net's peak only within this many zeta of the truth's peak depth (0.05 is about 2.5 cm); default: anywhere along the ray")
    ap.add_argument("--peak-cap", type=float, default=None, help="fourier --peak-weight: ask each thin ray for at most this height (e.g. 0.65, just over the surface level); default: the truth's own peak")
    ap.add_argument("--max-minutes", type=float, default=0.0, help="stop at this wall-clock budget (a checkpoint, the validation and budget.json as at the last step; fourier: the learning rate anneals by it); 0: none")
    ap.add_argument("--over-weight", type=float, default=0.0, help="fourier: weight of the thin rays' over-level hinge (over_level: how far the net's series rises above --over-level at depths where the truth's stays under it; a false or too thick surface), read at --ray-samples depths on --thin-radius's rays; 0: off")
    ap.add_argument("--empty-weight", type=float, default=0.0, help="fourier: weight of the over-level hinge (over_level) on the rays the truth leaves empty within --empty-band map pixels of the person (empty_band: the background beside it and the gaps between the legs or an arm and the body): a surface filled in where there is none; 0: off")
    ap.add_argument("--empty-band", type=int, default=None, help="fourier --empty-weight: the band's width in 128-px map pixels (default 3)")
    ap.add_argument("--over-level", type=float, default=None, help="fourier --over-weight / --empty-weight: the surface level (default 0.55, the exported models' --iso-level)")
    ap.add_argument("--ray-bce-weight", type=float, default=0.0, help="fourier: weight of the surface-level BCE on every ray (ray_level_bce: both series decoded at --ray-samples depths, the target's reading above 0.5 the label); 0: off")
    ap.add_argument("--geom-weight", type=float, default=0.0, help="fourier: weight of the front/back surface loss (surfaces.py: depths and slopes, i.e. normals) on a training-only head on the series head's features, or on the surface net of --variant fourier-geom (required there); 0: off")
    ap.add_argument("--geom-slope-weight", type=float, default=1.0, help="fourier: the slopes' (normals') share of --geom-weight's loss beside the depths' (0: depths only)")
    ap.add_argument("--amp", default="off", choices=["off", "bf16"], help="fourier: the training steps' forward in bfloat16 (autocast), outputs and losses in float32; validation in float32")
    ap.add_argument("--compile", action="store_true", help="fourier: the training forward compiled (torch.compile, channels-last weights and input); the first steps pay the compilation")
    ap.add_argument("--ema", type=float, default=0.0, help="fourier: keep a moving average of the weights with this decay per step (e.g. 0.999: about the last 1,000 steps) and validate, export and resume --init from it; 0: off")
    ap.add_argument("--ema-bn-images", type=int, default=800, help="fourier with --ema: at the run's end, the average's BatchNorm statistics recomputed on this many training images (its weights' own, not the average of the net's); 0: keep the averaged statistics")
    ap.add_argument("--teacher", type=Path, default=None, help="fourier: distil from this trained Fourier net (a light checkpoint, e.g. ../../models/checkpoints/shape-fourier-medium.pt, or a run's ckpt.pt): its maps of each training input are a second dense target (Parseval L2, --teacher-weight) beside the truth's")
    ap.add_argument("--teacher-variant", default="fourier-medium", help="fourier --teacher: the teacher's variant (its K must be the student's)")
    ap.add_argument("--teacher-weight", type=float, default=1.0, help="fourier --teacher: weight of the L2 to the teacher's maps (the truth's dense loss has weight 1)")
    ap.add_argument("--ray-samples", type=int, default=48, help="fourier: depths per ray for --ray-bce-weight (stratified), --peak-weight, --over-weight and --empty-weight (the cells' centres)")
    args = ap.parse_args(argv)
    if args.compile and args.amp != "off":
        ap.error(COMPILE_BF16_REFUSED)
    if not 0.0 <= args.mask_aug <= 1.0:
        ap.error(f"--mask-aug {args.mask_aug}: a fraction of the images, 0 to 1")
    refused = check_hinge_options(args)
    if refused:
        ap.error(refused)
    if args.teacher and not args.teacher_weight > 0:
        ap.error(f"--teacher-weight {args.teacher_weight}: must be above 0 with --teacher")
    if args.threads:
        torch.set_num_threads(args.threads)
    return {"seg": train_seg, "shape": train_shape, "color": train_color, "fourier": train_fourier}[args.task](args)


if __name__ == "__main__":
    main()
