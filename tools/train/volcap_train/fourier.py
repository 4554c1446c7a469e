"""The Fourier occupancy field (FOF, NeurIPS 2022), one definition shared with the engine
(service/engine/src/model/fourier.rs).

Every pixel of the crop stores the occupancy along its ray as a truncated Fourier series in
the depth coordinate ``zeta`` in [-1, 1] (period 2):

    occ(zeta) = c0 + sum_{k=1..K} a_k cos(k pi zeta) + b_k sin(k pi zeta)

Channel layout of a coefficient map: ``[c0, a_1, b_1, a_2, b_2, ..., a_K, b_K]`` (2K + 1).
``zeta = ZETA_SCALE * u_z`` where ``u_z`` is crop-NDC depth (crop.py: input NDC z / s), so
``zeta = +-1`` is +-1 / ZETA_SCALE of the crop's depth half-extent; outside [-1, 1] the
occupancy is 0 (the series is periodic there, the field is not).

Ground truth in closed form from the intervals ``[lo, hi]`` (in zeta) where the ray is inside:
``c0 = sum (hi - lo) / 2``, ``a_k = sum (sin(k pi hi) - sin(k pi lo)) / (k pi)``,
``b_k = sum (cos(k pi lo) - cos(k pi hi)) / (k pi)``: the L2 projection of the indicator on
the basis (orthonormal up to the factor 2 of the constant term), so by Parseval
``int (f - g)^2 dzeta = 2 dc0^2 + sum (da_k^2 + db_k^2)``.
"""

from __future__ import annotations

import math

import torch

ZETA_SCALE = 2.0


def channels(k: int) -> int:
    return 2 * k + 1


def interval_coeffs(lo: torch.Tensor, hi: torch.Tensor, k: int) -> torch.Tensor:
    """Coefficients [..., 2K+1] of the indicator of each interval [lo, hi] (zeta, clipped to
    [-1, 1] by the caller); sum them over the intervals of one ray."""
    kk = torch.arange(1, k + 1, dtype=lo.dtype, device=lo.device) * math.pi  # [K]
    a = (torch.sin(hi[..., None] * kk) - torch.sin(lo[..., None] * kk)) / kk
    b = (torch.cos(lo[..., None] * kk) - torch.cos(hi[..., None] * kk)) / kk
    c0 = 0.5 * (hi - lo)
    ab = torch.stack([a, b], -1).flatten(-2)  # a1 b1 a2 b2 ...
    return torch.cat([c0[..., None], ab], -1)


def basis(zeta: torch.Tensor, k: int) -> torch.Tensor:
    """[...] -> [..., 2K+1]: 1, cos(pi z), sin(pi z), ..., cos(K pi z), sin(K pi z)."""
    kk = torch.arange(1, k + 1, dtype=zeta.dtype, device=zeta.device) * math.pi
    ang = zeta[..., None] * kk
    cs = torch.stack([torch.cos(ang), torch.sin(ang)], -1).flatten(-2)
    return torch.cat([torch.ones_like(zeta)[..., None], cs], -1)


def decode(coeff: torch.Tensor, zeta: torch.Tensor, k: int) -> torch.Tensor:
    """coeff [..., 2K+1] (at least K), zeta [...] -> occupancy [...]; 0 where |zeta| > 1."""
    occ = (coeff[..., : channels(k)] * basis(zeta, k)).sum(-1)
    return torch.where(zeta.abs() <= 1.0, occ, torch.zeros_like(occ))


def parseval_l2(pred: torch.Tensor, target: torch.Tensor, dim: int = 1) -> torch.Tensor:
    """Integral over the ray of the squared occupancy error, from coefficients along `dim`."""
    d = (pred - target) ** 2
    w = torch.ones(d.shape[dim], dtype=d.dtype, device=d.device)
    w[0] = 2.0
    shape = [1] * d.dim()
    shape[dim] = -1
    return (d * w.view(shape)).sum(dim)


def ray_coeff_maps(offsets: torch.Tensor, z: torch.Tensor, size: int, s: float, k: int) -> torch.Tensor:
    """Coefficient maps [2K+1, size, size] on the input pixel grid of one image, from its ray
    intervals (CSR ``offsets`` [size*size+1], ``z`` [R, 2] input NDC) for a crop of scale s."""
    n = size * size
    counts = (offsets[1:] - offsets[:-1]).long()
    pix = torch.repeat_interleave(torch.arange(n), counts)
    zeta = (z.double() / s * ZETA_SCALE).clamp(-1.0, 1.0)
    c = interval_coeffs(zeta[:, 0], zeta[:, 1], k)
    out = torch.zeros(n, channels(k), dtype=torch.float64)
    out.index_add_(0, pix, c)
    return out.T.reshape(channels(k), size, size).float()


def first_moment(coeff: torch.Tensor, k: int, dim: int = 1) -> torch.Tensor:
    """int_{-1}^{1} z f(z) dz of each ray's series along `dim` (only the sine terms contribute:
    int z sin(k pi z) = 2 (-1)^(k+1) / (k pi)); its sign says whether the ray's occupancy lies
    in front of or behind the crop's z = 0 plane."""
    c = coeff.movedim(dim, -1)
    kk = torch.arange(1, k + 1, dtype=c.dtype, device=c.device)
    w = 2.0 * ((-1.0) ** (kk + 1)) / (kk * math.pi)
    return (c[..., 2 : 2 * k + 1 : 2] * w).sum(-1)


def centroid(coeff: torch.Tensor, k: int, dim: int = 1, eps: float = 1e-3):
    """Depth centre of the occupancy along each ray, int z f / int f over [-1, 1], from its
    series along `dim` (int z cos = 0, int z sin(k pi z) = 2 (-1)^(k+1) / (k pi), int f =
    2 c0); and a mask of the rays with at least `eps` of occupancy (c0 > eps)."""
    num = 0.5 * first_moment(coeff, k, dim)
    c0 = coeff.movedim(dim, -1)[..., 0]
    ok = c0 > eps
    return torch.where(ok, num / c0.clamp(min=eps), torch.zeros_like(c0)).clamp(-1.0, 1.0), ok


def body_depth_centre(coeff: torch.Tensor, k: int) -> torch.Tensor:
    """Per image of coefficient maps [B, 2K+1, H, W]: the mean depth (zeta) of all its
    occupancy, sum over pixels of int z f dz over the sum of int f dz (each ray weighted by
    its length; 0 for an image without occupancy)."""
    num = 0.5 * first_moment(coeff, k, 1).sum((1, 2))
    den = coeff[:, 0].sum((1, 2))
    return torch.where(den > 1e-6, num / den.clamp(min=1e-6), torch.zeros_like(den))


def centre_depth(coeff: torch.Tensor, points: torch.Tensor, k: int, chunk: int = 64) -> torch.Tensor:
    """Move every image's occupancy along depth so that its mean depth
    (`body_depth_centre`) is at zeta = 0, in place: the coefficient maps rotated by the shift
    (the series of f(z + delta)) and the labelled points' crop z moved alike. Returns the
    shifts (zeta) [B].

    Why: under the weak-perspective crop, a person's depth relative to the crop's z = 0
    plane is where the camera happened to stand (the simulator's subjects are off the orbit
    centre; opposite views get opposite offsets), which no image shows. Only depth relative
    to the body is learnable; the engine places the body's mean depth at z = 0."""
    from .nets import shift_series

    shifts = []
    for s in range(0, coeff.shape[0], chunk):
        c = coeff[s : s + chunk].float()
        d = body_depth_centre(c, k)
        coeff[s : s + chunk] = shift_series(c, -d.view(-1, 1, 1, 1), k).to(coeff.dtype)
        points[s : s + chunk, :, 2] -= (d / ZETA_SCALE).view(-1, 1).to(points.dtype)
        shifts.append(d)
    return torch.cat(shifts) if shifts else torch.zeros(0)


ISO_LEVELS = (0.30, 0.35, 0.40, 0.45, 0.50, 0.55)


def level_iou(occ: torch.Tensor, lab: torch.Tensor, level: float) -> torch.Tensor:
    """Per-image IoU [B] of `occ > level` against the labels (`occ`, `lab` [B, N], lab bool);
    1 where both are empty."""
    p = occ > level
    inter = (p & lab).sum(1).float()
    union = (p | lab).sum(1).float()
    return torch.where(union > 0, inter / union.clamp(min=1), torch.ones_like(union))


def best_level(occ: torch.Tensor, lab: torch.Tensor, levels=ISO_LEVELS, tol: float = 0.005) -> tuple[float, dict]:
    """The series level to read as the surface: of `levels`, the one whose `occ > level`
    gives the highest mean per-image IoU against the labels (`occ`, `lab` [B, N], lab bool),
    and the IoU at every level. A coefficient regression under uncertainty blurs thin parts
    (arms, hands) below 0.5, which point IoU rewards reading lower; on a sharp prediction
    the best is 0.5 or near it. (Point IoU weighs little the surface a lower level adds in
    front of and behind the body; the committed models' levels come from the pipeline's
    Chamfer + P2S on training subjects instead, see their cards.) Levels within `tol` of the best IoU count as tied and
    the one nearest 0.5 wins (a lower level also adds surface in front of and behind the
    body, which point IoU weighs little: keep the smallest move that buys the IoU)."""
    ious = {float(t): float(level_iou(occ, lab, t).mean()) for t in levels}
    top = max(ious.values())
    best = min((t for t in ious if ious[t] >= top - tol), key=lambda t: abs(t - 0.5))
    return best, ious
