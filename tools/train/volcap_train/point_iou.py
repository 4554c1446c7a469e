"""Point IoU of Fourier checkpoints on held-out whole bodies and on their upper-body crops
(items.fourier_upper_cached: the person cut by the frame's lower edge), at surface levels.

  python -m volcap_train.point_iou --data /work/data/ds2 --ckpt RUN [RUN ...] [--levels 0.5,0.55] [--seg ../../models/seg.onnx] [--mirrored] [--facing] [--ray-parts]

`--mirrored` also scores the whole bodies mirrored left-right (`mirrored`): a person of the
other handedness. People are mirror symmetric, so a net trained on symmetric data scores both
alike; a gap means it reads a chirality of its data. It also scores the mirrored inputs
against the labels turned around (`turned`: depth negated as well, the same silhouette seen
from the other side): high there means the net takes a mirrored person for one facing the other
way, i.e. it reads which way a person faces from that chirality. (The simulator's left elbow
bent backward until 2026-11-28: the default then scored 0.814 plain, 0.503 mirrored, and its
mirrored maps matched the turned-around truth as well as its plain maps matched the truth.)

`--facing` counts the facing errors (`facing_errors`): the images whose maps match the truth
with its depth reversed (front and back swapped: the person facing the other way) better than
the truth. The default of run (16) made them on 9.8 % of DS16's held-out images (point IoU
0.61 there, 0.76 on the rest) and on 3 % of its training images: which way a person faces was
the most of what it failed to carry to people it had not seen. Run (17), trained on 127 more
identities with mirrored images, makes them on 4.8 % (docs/eval/hands.md section 18).

RUN is a run folder (its ckpt.pt) or a light checkpoint (models/checkpoints/*.pt). Depth in the
body frame (fourier.centre_depth), as the committed models are trained.

`--ray-parts` also splits a volumetric IoU in the crop's frame (each crop pixel's predicted
series against the ground-truth one, on depth bins, whole bodies with true masks) into where
it is lost (`ray_parts`): the silhouette, the placement along depth (the best global shift
per image), and the surfaces along each ray inside the shared silhouette (and the thickness
bias there)."""
from __future__ import annotations

import argparse
from pathlib import Path

import torch
from . import fourier as FO
from .nets import FourierNet, fourier_variant, make_fourier, shift_series
from .runs import init_weights
from .items import fourier_cached, fourier_upper_cached
from .train import encoder_input, predict_points


def load(path: Path, variant: str) -> FourierNet:
    net = make_fourier(variant)
    ck = path / "ckpt.pt" if path.is_dir() else path
    net.load_state_dict(init_weights(torch.load(ck, weights_only=False), ck))
    return net.eval()


def point_iou(net: FourierNet, d: dict, levels) -> dict:
    """level -> (mean, mean of the 10 worst) per-image point IoU over the items of `d`."""
    occ, lab = predict_points(net, d["rgb"], d["mask"], d["points"], 16), d["occ"] > 0.5
    out = {}
    for level in levels:
        iou = FO.level_iou(occ, lab, level)
        out[level] = (iou.mean().item(), iou.sort().values[:10].mean().item())
    return out


def mirrored(d: dict) -> dict:
    """The items of `d` mirrored left-right: crops and masks flipped (train.mirror_some: exact
    in crop NDC) and the labelled points' x negated, labels unchanged."""
    pts = d["points"].clone()
    pts[..., 0] = -pts[..., 0]
    return {**d, "rgb": d["rgb"].flip(-1), "mask": d["mask"].flip(-1), "points": pts}


def turned(d: dict) -> dict:
    """The items of `d` mirrored left-right (`mirrored`) and scored as the same people turned
    around: the labelled points' depth negated as well (body frame: about the mean depth;
    x and z negated is a half turn about the vertical axis, as an orthographic camera sees
    it), labels unchanged."""
    return depth_reversed(mirrored(d))


def depth_reversed(d: dict) -> dict:
    """The items of `d` with the labelled points' depth negated (body frame: about the mean
    depth), inputs and labels unchanged: the same silhouette with its front and back swapped,
    i.e. the person turned around and mirrored (people being near mirror symmetric, the same
    person facing the other way)."""
    pts = d["points"].clone()
    pts[..., 2] = -pts[..., 2]
    return {**d, "points": pts}


def facing_split(iou_plain: torch.Tensor, iou_reversed: torch.Tensor) -> dict:
    """Per-image point IoU against the truth and against the depth-reversed truth
    (`depth_reversed`) -> the facing errors: the images whose maps match the person facing the
    other way better than the person (`errors` of `images`), and the mean plain IoU on them and
    on the rest (nan where a group is empty)."""
    wrong = iou_reversed > iou_plain
    mean = lambda v: v.mean().item() if len(v) else float("nan")
    return {"errors": int(wrong.sum()), "images": len(wrong), "iou_errors": mean(iou_plain[wrong]), "iou_rest": mean(iou_plain[~wrong])}


def facing_errors(net: FourierNet, d: dict, levels) -> dict:
    """level -> `facing_split` of a net on the items of `d`: one pass of the encoder, its maps
    read at the labelled points and at the same points with their depth reversed."""
    lab, n = d["occ"] > 0.5, d["points"].shape[1]
    both = torch.cat([d["points"], depth_reversed(d)["points"]], 1)
    occ = predict_points(net, d["rgb"], d["mask"], both, 16)
    return {lv: facing_split(FO.level_iou(occ[:, :n], lab, lv), FO.level_iou(occ[:, n:], lab, lv)) for lv in levels}


GROSS_BINS = 8  # of 64 over zeta [-1, 1]: 0.25 zeta

COARSE_SHIFTS = torch.linspace(-0.2, 0.2, 9)  # zeta, then refined in 0.01 steps


def _iou(a: torch.Tensor, b: torch.Tensor, dims) -> torch.Tensor:
    return (a & b).sum(dims).float() / (a | b).sum(dims).clamp(min=1).float()


def ray_parts(pred: torch.Tensor, truth: torch.Tensor, k: int, level: float = 0.5, bins: int = 64) -> dict:
    """Per image of coefficient maps [B, 2K+1, H, W] (prediction, truth, same grid): occupancy
    on `bins` depth bins in zeta [-1, 1] above `level`, and
      iou       the volumetric IoU;
      best_iou, best_shift  the IoU after the best global depth shift of the prediction
                (zeta, within +-0.2 to 0.01, coarse to fine; what placement alone would buy);
      sil_iou   the silhouette IoU (pixels with any bin occupied);
      ray_iou   the IoU over the pixels inside both silhouettes (the surfaces along rays);
      thick_pred, thick_true  mean occupied bins per ray there;
      front_err, back_err  mean absolute error (bins) there of the nearest occupied bin (the
                visible surface; z toward the camera) and of the farthest (the hidden one);
      front_bias, back_bias  their mean signed errors (bins, + = prediction nearer the camera);
      gross     the fraction of those rays with either surface off by more than GROSS_BINS
                (a limb put on the wrong side of the body: depth order, not surface detail)."""
    z = torch.linspace(-1 + 1 / bins, 1 - 1 / bins, bins, dtype=pred.dtype)
    basis = FO.basis(z, k)  # [bins, 2K+1]
    vol = lambda c: torch.einsum("bchw,zc->bhwz", c[:, : FO.channels(k)], basis) > level
    vp, vt = vol(pred), vol(truth)
    dims = (1, 2, 3)
    iou = _iou(vp, vt, dims)
    best, best_shift = iou.clone(), torch.zeros_like(iou)

    def search(offsets, centre):
        nonlocal best, best_shift
        for off in offsets:
            d = centre + float(off)
            u = _iou(vol(shift_series(pred, d.view(-1, 1, 1, 1).to(pred.dtype), k)), vt, dims)
            better = u > best
            best, best_shift = torch.where(better, u, best), torch.where(better, d, best_shift)

    search(COARSE_SHIFTS, torch.zeros_like(iou))
    search(torch.linspace(-0.04, 0.04, 9), best_shift.clone())
    sp, st = vp.any(-1), vt.any(-1)
    both = (sp & st).unsqueeze(-1)
    nb = both.squeeze(-1).sum((1, 2)).clamp(min=1).float()
    idx = torch.arange(bins)
    # nearest occupied bin = the largest index; farthest = the smallest (z toward the camera)
    front = lambda v: torch.where(v, idx, -1).amax(-1).float()
    back = lambda v: torch.where(v, idx, bins).amin(-1).float()
    per_img = lambda e: (e * both.squeeze(-1)).sum((1, 2)) / nb
    df, db = front(vp) - front(vt), back(vp) - back(vt)
    return {
        "iou": iou,
        "best_iou": best,
        "best_shift": best_shift,
        "sil_iou": _iou(sp, st, (1, 2)),
        "ray_iou": _iou(vp & both, vt & both, dims),
        "thick_pred": (vp & both).sum(dims).float() / both.sum(dims).clamp(min=1).float(),
        "thick_true": (vt & both).sum(dims).float() / both.sum(dims).clamp(min=1).float(),
        "front_err": per_img(df.abs()),
        "back_err": per_img(db.abs()),
        "front_bias": per_img(df),
        "back_bias": per_img(db),
        "gross": per_img(((df.abs() > GROSS_BINS) | (db.abs() > GROSS_BINS)).float()),
    }


def net_ray_parts(net: FourierNet, d: dict, level: float = 0.5, batch: int = 8) -> dict:
    """`ray_parts` of a net's maps against the ground-truth maps of the items of `d`, means and
    standard deviations over the images."""
    parts = []
    with torch.no_grad():
        for s in range(0, len(d["rgb"]), batch):
            x = encoder_input(d["rgb"][s : s + batch].float() / 255, d["mask"][s : s + batch].float() / 255)
            parts.append(ray_parts(net(x).float(), d["coeff"][s : s + batch].float(), net.k, level))
    out = {}
    for key in parts[0]:
        v = torch.cat([p[key] for p in parts])
        out[key] = (v.mean().item(), v.std(unbiased=False).item())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.point_iou")
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--ckpt", type=Path, nargs="+", required=True)
    ap.add_argument("--variant", default="fourier-small")
    ap.add_argument("--split", default="val")
    ap.add_argument("--levels", default="0.5,0.55")
    ap.add_argument("--seg", type=Path, default=None, help="also score the whole bodies with this ONNX segmentation model's masks and crops (the engine's input; seg_masks)")
    ap.add_argument("--mirrored", action="store_true", help="also score the whole bodies mirrored left-right (true masks)")
    ap.add_argument("--facing", action="store_true", help="also count the facing errors on the whole bodies (true masks): the images whose maps match the truth with its depth reversed (the person facing the other way) better than the truth (facing_errors)")
    ap.add_argument("--ray-parts", action="store_true", help="also split a volumetric IoU of the whole bodies (true masks) into silhouette, placement and surfaces along rays (ray_parts)")
    args = ap.parse_args(argv)
    levels = [float(v) for v in args.levels.split(",")]
    k = fourier_variant(args.variant)[0]
    sets = {"whole": fourier_cached(args.data, args.split, k), "upper": fourier_upper_cached(args.data, args.split, k, 1)}
    if args.seg is not None:
        sets[f"whole, {args.seg.stem} masks"] = fourier_cached(args.data, args.split, k, args.seg)
    for d in sets.values():
        FO.centre_depth(d["coeff"], d["points"], k)
    if args.mirrored:
        sets["whole, mirrored"] = mirrored(sets["whole"])
        sets["whole, mirrored, scored as turned around"] = turned(sets["whole"])
    for ck in args.ckpt:
        net = load(ck, args.variant)
        for name, d in sets.items():
            r = point_iou(net, d, levels)
            print(f"{ck} {name} ({len(d['rgb'])} images): " + ", ".join(f"level {lv}: {m:.3f} (worst-10 {w:.3f})" for lv, (m, w) in r.items()), flush=True)
        if args.facing:
            for lv, r in facing_errors(net, sets["whole"], levels).items():
                print(f"{ck} whole, facing errors at level {lv}: {r['errors']} of {r['images']} images ({r['errors'] / max(r['images'], 1):.1%}) match the person facing the other way better; point IoU on them {r['iou_errors']:.3f}, on the rest {r['iou_rest']:.3f}", flush=True)
        if args.ray_parts:
            for lv in levels:
                r = net_ray_parts(net, sets["whole"], lv)
                print(f"{ck} whole, volumetric IoU in the crop at level {lv}: " + ", ".join(f"{key} {m:.3f} (sd {sd:.3f})" for key, (m, sd) in r.items()), flush=True)


if __name__ == "__main__":
    main()
