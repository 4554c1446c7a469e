"""What a Fourier head has and has not learned, per coefficient, on a dataset split.

    python -m volcap_train.fourier_diag --data /work/data/ds2 --ckpt RUN/ckpt.pt --variant fourier

Prints, on ray pixels that hold the body (c0 > 0.01): the mean ray length c0 predicted
against the truth (a thickness bias), the correlation of each cosine and sine coefficient
with the truth (the cosine terms carry the symmetric profile, the sine terms the depth
offset from the crop's z = 0 plane: which limb is in front), the depth centre's error, and
how labelled points fall (inside points decoded > 0.5, outside points decoded > 0.5) for
the prediction and for the ground-truth series of the same order. Accepts the trainer's
checkpoints (`ckpt.pt`) and the light ones (`models/checkpoints/*.pt`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
import torch.nn.functional as F

from . import fourier as FO
from .nets import FourierNet, encoder_input, fourier_variant, make_fourier
from .items import fourier_cached
from .ray_losses import thin_mask
from .train import fourier_query


def corr(a: torch.Tensor, b: torch.Tensor) -> float:
    if a.numel() < 2 or a.std() == 0 or b.std() == 0:
        return 0.0
    return float(torch.corrcoef(torch.stack([a, b]))[0, 1])


def diagnose(net: FourierNet, d: dict, k: int, images: int) -> dict:
    n = len(d["rgb"])
    idx = torch.arange(0, n, max(1, n // images))[:images]
    out = {"images": len(idx)}
    preds = []
    with torch.no_grad():
        for s in range(0, len(idx), 8):
            i = idx[s : s + 8]
            preds.append(net(encoder_input(d["rgb"][i].float() / 255, d["mask"][i].float() / 255)))
    pred = torch.cat(preds)
    tgt = d["coeff"][idx].float()
    body = tgt[:, 0] > 0.01
    out["c0_pred"] = float(pred[:, 0][body].mean())
    out["c0_true"] = float(tgt[:, 0][body].mean())
    out["corr_cos"] = [corr(tgt[:, 2 * j - 1][body], pred[:, 2 * j - 1][body]) for j in range(1, k + 1)]
    out["corr_sin"] = [corr(tgt[:, 2 * j][body], pred[:, 2 * j][body]) for j in range(1, k + 1)]
    ct, ok_t = FO.centroid(tgt, k)
    cp, _ = FO.centroid(pred, k)
    out["centre_err"] = float((cp - ct)[ok_t].abs().mean())
    out["centre_true_std"] = float(ct[ok_t].std())
    lab = d["occ"][idx] > 0.5
    for name, c in (("pred", pred), ("truth_series", tgt)):
        occ = fourier_query(c, d["points"][idx], k)
        out[f"{name}_inside_hit"] = float((occ > 0.5)[lab].float().mean())
        out[f"{name}_outside_hit"] = float((occ > 0.5)[~lab].float().mean())
    return out


def thin_rays(net, d: dict, k: int, images: int, radius: int = 2) -> dict:
    """The thin parts' rays (`ray_losses.thin_mask`: hands, wrists, ankles; hands.md section
    31): how high the predicted series peaks against the truth series (the surface level is
    0.55), how far its peak lies from the truth's in depth (zeta), and how much of them the
    input's mask covers. A thin ray whose peak sits at the right depth but under the level is
    a blur in depth, not a miss. Where they disagree: `false_decoded_share` (the net decodes a
    ray the truth leaves under the level: a surface where there is none), `missed_share` (the
    reverse), and `length_ratio_median` (on rays both decode, the net's length above the level
    over the truth's: over 1, the part thicker in depth than it is)."""
    n = len(d["rgb"])
    idx = torch.arange(0, n, max(1, n // images))[:images]
    z = torch.linspace(-1, 1, 512)
    basis = FO.basis(z, k)
    peak, tpeak, err, cover, plen, tlen = [], [], [], [], [], []
    with torch.no_grad():
        for s in range(0, len(idx), 8):
            i = idx[s : s + 8]
            m = d["mask"][i].float() / 255
            pred = net(encoder_input(d["rgb"][i].float() / 255, m))
            tgt = d["coeff"][i].float()
            thin = (thin_mask(tgt, radius)[:, 0] > 0.5) & (tgt[:, 0] > 0.01)
            op = pred.permute(0, 2, 3, 1)[thin] @ basis.T
            ot = tgt.permute(0, 2, 3, 1)[thin] @ basis.T
            peak.append(op.max(1).values)
            tpeak.append(ot.max(1).values)
            err.append((z[op.argmax(1)] - z[ot.argmax(1)]).abs())
            cover.append(F.interpolate(m, size=tgt.shape[-2:], mode="area")[:, 0][thin])
            plen.append((op > 0.55).sum(1))
            tlen.append((ot > 0.55).sum(1))
    peak, tpeak, err, cover, plen, tlen = (torch.cat(t) for t in (peak, tpeak, err, cover, plen, tlen))
    if len(peak) == 0:
        return {"rays": 0}
    both = (plen > 0) & (tlen > 0)
    return {
        "rays": len(peak),
        "peak_median": float(peak.median()),
        "truth_peak_median": float(tpeak.median()),
        "decoded_share": float((peak > 0.55).float().mean()),
        "truth_decoded_share": float((tpeak > 0.55).float().mean()),
        "false_decoded_share": float(((peak > 0.55) & (tpeak <= 0.55)).float().mean()),
        "missed_share": float(((peak <= 0.55) & (tpeak > 0.55)).float().mean()),
        "length_ratio_median": float((plen[both].float() / tlen[both].float()).median()) if bool(both.any()) else float("nan"),
        "peak_depth_error_median": float(err.median()),
        "peak_depth_within_0.05": float((err < 0.05).float().mean()),
        "mask_covers": float((cover > 0.5).float().mean()),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.fourier_diag", description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--ckpt", type=Path, required=True)
    ap.add_argument("--variant", default="fourier")
    ap.add_argument("--images", type=int, default=64)
    ap.add_argument("--split", default="val", choices=["train", "val"])
    ap.add_argument("--seg", type=Path, default=None, help="the input masks from this segmentation model (as `train --seg`; default: the true masks)")
    ap.add_argument("--segment-passes", type=int, default=1)
    ap.add_argument("--depth-frame", default="body", choices=["body", "camera"], help="truth with each image's mean depth at z = 0 (as `train --depth-frame body` trains) or as the camera saw it")
    a = ap.parse_args(argv)
    k, c, shift = fourier_variant(a.variant)
    st = torch.load(a.ckpt, weights_only=False)
    sd = st["net"] if "net" in st else st["modules"]["net"]
    net = make_fourier(a.variant)
    net.load_state_dict({n: v.float() for n, v in sd.items()})
    net.eval()
    d = fourier_cached(a.data, a.split, k, a.seg, a.segment_passes)
    if a.depth_frame == "body":
        FO.centre_depth(d["coeff"], d["points"], k)
    r = diagnose(net, d, k, a.images)
    r["thin"] = thin_rays(net, d, k, a.images)
    r["step"] = st.get("step")
    print(json.dumps(r))
    print(f"c0 on the body: predicted {r['c0_pred']:.3f}, true {r['c0_true']:.3f}")
    print("cosine terms, correlation with the truth: " + " ".join(f"{v:.2f}" for v in r["corr_cos"][:8]))
    print("sine terms,   correlation with the truth: " + " ".join(f"{v:.2f}" for v in r["corr_sin"][:8]))
    print(f"depth centre error {r['centre_err']:.3f} (zeta; the truth varies by {r['centre_true_std']:.3f})")
    print(f"points decoded inside: inside {r['pred_inside_hit']:.3f}, outside {r['pred_outside_hit']:.3f} "
          f"(ground-truth series: {r['truth_series_inside_hit']:.3f}, {r['truth_series_outside_hit']:.3f})")
    t = r["thin"]
    if t["rays"]:
        print(f"thin rays ({t['rays']}): series peak median {t['peak_median']:.3f} (truth {t['truth_peak_median']:.3f}), "
              f"decoded at 0.55 {t['decoded_share']:.3f} (truth {t['truth_decoded_share']:.3f}), peak depth off the truth's "
              f"by {t['peak_depth_error_median']:.3f} (median; within 0.05: {t['peak_depth_within_0.05']:.3f}), mask covers {t['mask_covers']:.3f}; "
              f"decoded where the truth is not {t['false_decoded_share']:.3f}, missed {t['missed_share']:.3f}, "
              f"length above the level against the truth's {t['length_ratio_median']:.2f} (median, rays both decode)")


if __name__ == "__main__":
    main()
