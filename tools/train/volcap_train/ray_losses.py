"""The Fourier head's per-ray losses beyond the Parseval L2 (`train fourier`): the thin parts'
weighting mask (`--thin-weight`) and the surface-level BCE on every ray (`--ray-bce-weight`).
Both were measured against the hands (docs/eval/hands.md, sections 3 and 4)."""

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
