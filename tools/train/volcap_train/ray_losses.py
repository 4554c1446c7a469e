"""The Fourier head's per-ray losses beyond the Parseval L2 (`train fourier`): the thin parts'
weighting mask (`--thin-weight`), the surface-level BCE on every ray (`--ray-bce-weight`) and
each ray's profile judged at the depth the net put it (`--centre-align`) and the thin rays'
peak height (`--peak-weight`). Each was measured against the hands (docs/eval/hands.md,
sections 3, 4, 31 and 41)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from . import fourier as FO


def thin_mask(coeff: torch.Tensor, radius: int) -> torch.Tensor:
    """[B, 2K+1, H, W] target maps -> [B, 1, H, W] in {0, 1}: the occupied pixels (c0, half the
    ray's inside length, above 0.005) that a morphological opening of `radius` pixels removes,
    i.e. the parts narrower than about 2 radius + 1 map pixels (hands, wrists, ankles, the
    arms seen edge-on): where the dense loss is small in area and the hands were lost."""
    occ = (coeff[:, :1] > 0.005).float()
    k = 2 * radius + 1
    eroded = -F.max_pool2d(-occ, k, stride=1, padding=radius)
    opened = F.max_pool2d(eroded, k, stride=1, padding=radius)
    return occ * (1.0 - opened)


def empty_band(coeff: torch.Tensor, band: int) -> torch.Tensor:
    """[B, 2K+1, H, W] target maps -> [B, 1, H, W] in {0, 1}: the pixels the truth leaves empty
    (c0 at most 0.005) within `band` map pixels of its occupied ones: the background next to
    the person and the narrow gaps inside the silhouette (between the legs, between an arm and
    the body), where a net that raises thin rays fills in a surface (hands.md section 42)."""
    occ = (coeff[:, :1] > 0.005).float()
    k = 2 * band + 1
    near = F.max_pool2d(occ, k, stride=1, padding=band)
    return near * (1.0 - occ)


def ray_level_bce(pred: torch.Tensor, target: torch.Tensor, k: int, samples: int, gen: torch.Generator, tau: float = 10.0, level: float = 0.5, band: int = 2) -> torch.Tensor:
    """The surface level on every ray (`train fourier --ray-bce-weight`): both series [B, 2K+1,
    H, W] decoded at `samples` stratified depths (one random offset per call), the target's
    reading above `level` the label, BCE on tau (pred - level) as a logit (finite for any
    series value); the mean over the rays the person covers, dilated by `band` map pixels so
    that the silhouette's outside counts too. The Parseval L2 is content with a thin ray's
    blurred, low series (its peak under the level: the hands vanish); this loss is not."""
    dev = pred.device
    z = ((torch.arange(samples, dtype=torch.float32) + torch.rand(samples, generator=gen)) / samples * 2.0 - 1.0).to(dev)
    b = FO.basis(z, k)  # [M, 2K+1]
    c = FO.channels(k)
    p = torch.einsum("bchw,mc->bmhw", pred[:, :c], b)
    lab = (torch.einsum("bchw,mc->bmhw", target[:, :c], b) > level).float()
    occ = (target[:, :1] > 0.005).float()
    ray = F.max_pool2d(occ, 2 * band + 1, stride=1, padding=band) if band > 0 else occ  # [B, 1, H, W]
    bce = F.binary_cross_entropy_with_logits(tau * (p - level), lab, reduction="none")  # [B, M, H, W]
    return (bce * ray).sum() / (ray.sum() * samples).clamp(min=1.0)


def sampled_centroid(coeff: torch.Tensor, k: int, min_mass: float = 0.01, samples: int = 128, floor: float = 0.05):
    """Each ray's depth centroid [B, H, W] (zeta) from its series [B, 2K+1, H, W] decoded at
    `samples` depths, weighted by the occupancy above `floor` (the ringing of a truncated
    series left out), and a mask of the rays whose constant term says they hold at least
    `min_mass`. Not `fourier.centroid`: the series' own first moment (the sine terms' closed
    form) reads a narrow pulse's centre through the truncated sawtooth, off by up to a
    hand's thickness, and by different amounts for a pulse and the same pulse moved."""
    ok = coeff[:, 0] > min_mass
    rays = coeff.permute(0, 2, 3, 1)[ok]  # [N, 2K+1]
    z = (torch.arange(samples, dtype=coeff.dtype, device=coeff.device) + 0.5) / samples * 2.0 - 1.0
    w = (rays @ FO.basis(z, k).T - floor).clamp(min=0.0)  # [N, S]
    mass = w.sum(1)
    held = mass > 1e-6
    c = torch.where(held, (w * z).sum(1) / mass.clamp(min=1e-6), torch.zeros_like(mass))
    return torch.zeros_like(coeff[:, 0]).masked_scatter(ok, c), ok.masked_scatter(ok, held)


def centre_aligned(pred: torch.Tensor, target: torch.Tensor, k: int, min_mass: float = 0.01, max_shift: float = 0.25, only: torch.Tensor | None = None):
    """`train fourier --centre-align`: the target series [B, 2K+1, H, W] moved along each ray to
    where the prediction holds its mass, so that the dense loss judges a ray's profile (how
    thick, how sharp) apart from its depth, which the centroid loss judges (L1: a median).

    Under the plain Parseval L2 a thin ray whose depth the image leaves unsure by about its own
    thickness (a hand: 3 cm thick, its depth unsure by 2-3 cm) is best predicted as the mean of
    the pulses it could be: one wide pulse peaking under the surface level, so the hand decodes
    empty. Judged at the predicted depth, the sharp pulse costs nothing for being 2 cm off.

    `only` ([B, H, W] bool, optional): move only these rays (e.g. the thin parts); the rest keep
    the plain L2, depth and all.

    Returns (the moved target, the shift d [B, 1, H, W] in zeta, f(z) -> f(z - d), 0 where either
    series holds under `min_mass` (c0) of occupancy, at most `max_shift`; the prediction's
    centroid detached), and the centroid L1's mean over the rays both hold (0 if none)."""
    from .nets import shift_series

    dp, okp = sampled_centroid(pred, k, min_mass)
    dt, okt = sampled_centroid(target, k, min_mass)
    ok = okp & okt
    if only is not None:
        ok = ok & only
    shift = torch.where(ok, (dp.detach() - dt).clamp(-max_shift, max_shift), torch.zeros_like(dt)).unsqueeze(1)
    l1 = torch.where(ok, (dp - dt).abs(), torch.zeros_like(dt)).sum() / ok.sum().clamp(min=1)
    return shift_series(target, shift, k), shift, l1


def _ray_readings(pred: torch.Tensor, target: torch.Tensor, k: int, only: torch.Tensor, samples: int):
    """Both series [B, 2K+1, H, W] on the rays of `only` ([B, H, W] bool, N of them) read at
    `samples` fixed depths, the cells' centres on [-1, 1]: (z [S], pred [N, S], target [N, S])."""
    c = FO.channels(k)
    rp = pred[:, :c].permute(0, 2, 3, 1)[only]  # [N, 2K+1]
    rt = target[:, :c].permute(0, 2, 3, 1)[only]
    z = ((torch.arange(samples, dtype=pred.dtype, device=pred.device) + 0.5) / samples * 2.0 - 1.0)
    b = FO.basis(z, k)  # [S, 2K+1]
    return z, rp @ b.T, rt @ b.T


def peak_hinge(pred: torch.Tensor, target: torch.Tensor, k: int, only: torch.Tensor, samples: int = 64, window: float | None = None, cap: float | None = None) -> torch.Tensor:
    """`train fourier --peak-weight`: how far each selected ray's series [B, 2K+1, H, W] peaks
    under the target's own peak, relu(max_z target - max_z pred), its mean over the rays of
    `only` ([B, H, W] bool; the thin parts, `thin_mask`); 0 (with a gradient graph) if none.

    Depth-free on purpose: the Parseval L2 and a per-depth BCE (section 4) both prefer, for a
    ray whose depth the image leaves unsure by its own thickness, the mean of the pulses it could
    be, a low blur whose peak stays under the surface level (the thin rays peak at 0.56 against
    the truth's 0.84, hands.md section 31); this asks only that the ray hold its height
    somewhere, and is zero once it does. The maxima are read at `samples` fixed depths (the
    cells' centres on [-1, 1]; no random draw, so a run pairs with its control's batches), both
    series at the same depths.

    `window` (zeta, optional): the prediction's peak is read only within this distance of the
    target's peak depth, so that height raised at the wrong depth does not count (a ray whose
    depth is unsure by about `window` may still put a sharp pulse anywhere inside it).
    `cap` (optional): the height asked for is at most this (e.g. just over the surface level: the
    ray decodes, its inside no thicker than the top of its pulse)."""
    if not bool(only.any()):
        return pred.sum() * 0.0
    z, vp, vt = _ray_readings(pred, target, k, only, samples)
    peak_t, at = vt.max(1)
    if window is not None:
        near = (z.unsqueeze(0) - z[at].unsqueeze(1)).abs() <= window  # [N, S]; the argmax itself always in
        vp = vp.masked_fill(~near, float("-inf"))
    peak_p = vp.amax(1)
    if cap is not None:
        peak_t = peak_t.clamp(max=cap)
    return F.relu(peak_t - peak_p).mean()


def over_level(pred: torch.Tensor, target: torch.Tensor, k: int, only: torch.Tensor, samples: int = 64, level: float = 0.55) -> torch.Tensor:
    """`train fourier --over-weight` and `--empty-weight`: how far each selected ray's series
    [B, 2K+1, H, W] rises above the surface `level` at depths where the target's series stays
    under it, relu(max over those depths of the prediction - level), its mean over the rays of
    `only` ([B, H, W] bool: the thin parts, `thin_mask`, or the empty rays beside the person,
    `empty_band`); 0 (with a gradient graph) if none.

    The other side of `peak_hinge`: a surface the truth does not have on that ray, whether the
    whole ray is decoded where the truth's is not (a false hand) or a decoded interval is longer
    in depth than the truth's (a part thicker than it is); both cost P2S (hands.md section 42).
    Zero for a series that crosses the level only where the truth does, however high its peak
    there. Read at the same `samples` fixed depths as `peak_hinge`; a ray the truth never raises
    over the level is charged its whole height above it."""
    if not bool(only.any()):
        return pred.sum() * 0.0
    _, vp, vt = _ray_readings(pred, target, k, only, samples)
    outside = vt < level
    vp = vp.masked_fill(~outside, float("-inf"))
    excess = F.relu(vp.amax(1) - level)  # a ray the truth covers end to end: -inf -> 0
    return excess.mean()


def ray_hinges(pred: torch.Tensor, target: torch.Tensor, k: int, args) -> torch.Tensor:
    """`train fourier`'s ray hinges, each at its weight (0: off): `--peak-weight` (the thin rays'
    series held to the truth's peak height, `peak_hinge`), `--over-weight` (and kept under the
    level where the truth's is, `over_level`), `--empty-weight` (under it on the empty rays
    beside the person, the gaps, `empty_band`). `args` as `check_hinge_options` left it."""
    loss = pred.sum() * 0.0
    if args.peak_weight > 0 or args.over_weight > 0:
        only = thin_mask(target, args.thin_radius)[:, 0] > 0.5
    if args.peak_weight > 0:
        loss = loss + args.peak_weight * peak_hinge(pred, target, k, only, args.ray_samples, window=args.peak_window, cap=args.peak_cap)
    if args.over_weight > 0:
        loss = loss + args.over_weight * over_level(pred, target, k, only, args.ray_samples, args.over_level)
    if args.empty_weight > 0:
        gaps = empty_band(target, args.empty_band)[:, 0] > 0.5
        loss = loss + args.empty_weight * over_level(pred, target, k, gaps, args.ray_samples, args.over_level)
    return loss


def check_hinge_options(args) -> str | None:
    """The refusal of a bad ray-hinge option of `train` (named with its value), or None; fills
    the defaults of `--empty-band` (3) and `--over-level` (0.55), which are refused without
    their loss (they would be ignored)."""
    if args.peak_window is not None and not args.peak_window >= 0:
        return f"--peak-window {args.peak_window}: a distance in zeta, 0 or above"
    if args.peak_cap is not None and not 0.0 < args.peak_cap <= 2.0:
        return f"--peak-cap {args.peak_cap}: an occupancy height, above 0 and at most 2"
    if not args.peak_weight >= 0:
        return f"--peak-weight {args.peak_weight}: must be 0 (off) or above"
    if args.peak_weight == 0 and (args.peak_window is not None or args.peak_cap is not None):
        return "--peak-window / --peak-cap shape the thin rays' peak hinge: give --peak-weight too"
    if not args.over_weight >= 0:
        return f"--over-weight {args.over_weight}: must be 0 (off) or above"
    if args.over_level is not None and not 0.0 < args.over_level < 1.0:
        return f"--over-level {args.over_level}: a surface level, between 0 and 1"
    if not args.empty_weight >= 0:
        return f"--empty-weight {args.empty_weight}: must be 0 (off) or above"
    if args.empty_band is not None and not args.empty_band >= 1:
        return f"--empty-band {args.empty_band}: map pixels, 1 or more"
    if args.empty_weight == 0 and args.empty_band is not None:
        return "--empty-band is the empty rays' band: give --empty-weight too"
    if args.over_weight == 0 and args.empty_weight == 0 and args.over_level is not None:
        return "--over-level is the over-level hinges' level: give --over-weight or --empty-weight too"
    args.empty_band = 3 if args.empty_band is None else args.empty_band
    args.over_level = 0.55 if args.over_level is None else args.over_level
    return None
