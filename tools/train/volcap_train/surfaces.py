"""The person's front and back surfaces as depth maps, an auxiliary dense target of the
Fourier head (`train fourier --geom-weight`, issue 34 part 3: FOF-X's normal maps as an
intermediate, here as a training-only head).

From a ray's series (the target maps after `fourier.centre_depth`, so in the body depth
frame the head learns) the front surface is the nearest depth where the series reaches the
level (z toward the camera: the largest zeta inside), the back surface the farthest (the
smallest zeta inside); both refined linearly between the two samples around the crossing.
Normals are these maps' slopes: the loss compares the slopes as well as the depths, on
pixels whose neighbour is inside too and where the true surface is not an occlusion edge
(the slope's jump bound), so a hand in front of the torso does not teach a cliff.

Convention: maps [B, 2, H, W] (channel 0 front, 1 back) in zeta; slopes in zeta per crop-NDC
unit (a map pixel is 2 / (W - 1) crop-NDC wide, `align_corners=True` as everywhere)."""

from __future__ import annotations

import torch
import torch.nn as nn

from . import fourier as FO

# The slope past which a step between neighbouring pixels is taken for an occlusion edge
# (zeta per crop-NDC unit; 3 is a surface turned ~72 degrees from the camera at zeta_scale 2).
MAX_SLOPE = 3.0


def surface_depths(coeff: torch.Tensor, k: int, samples: int = 128, level: float = 0.5, chunk: int = 16):
    """[B, 2K+1, H, W] series -> (depths [B, 2, H, W] f32: front, back; inside [B, 1, H, W]
    bool: the rays whose series reaches `level` at one of `samples` depths on [-1, 1])."""
    z = torch.linspace(-1.0, 1.0, samples, dtype=torch.float32, device=coeff.device)
    b = FO.basis(z, k)  # [M, 2K+1]
    c = FO.channels(k)
    depths, inside = [], []
    for s in range(0, coeff.shape[0], chunk):
        occ = torch.einsum("bchw,mc->bmhw", coeff[s : s + chunk, :c].float(), b)  # [b, M, H, W]
        above = occ > level
        ok = above.any(1, keepdim=True)
        m = samples
        # Back: the first sample above; its crossing lies between it and the one before.
        j = above.to(torch.uint8).argmax(1, keepdim=True)
        # Front: the last sample above; its crossing lies between it and the one after.
        i = (m - 1) - above.flip(1).to(torch.uint8).argmax(1, keepdim=True)
        back = _crossing(occ, z, j, (j - 1).clamp(min=0), level)
        front = _crossing(occ, z, i, (i + 1).clamp(max=m - 1), level)
        d = torch.cat([front, back], 1)
        depths.append(torch.where(ok, d, torch.zeros_like(d)))
        inside.append(ok)
    return torch.cat(depths), torch.cat(inside)


def _crossing(occ, z, a, b, level):
    """Where the series crosses `level` between sample a (above) and sample b (its neighbour
    outward, or a itself at the range's end): linear between the two."""
    oa, ob = occ.gather(1, a), occ.gather(1, b)
    za, zb = z[a], z[b]
    t = ((oa - level) / (oa - ob).clamp(min=1e-6)).clamp(0.0, 1.0)
    return torch.where(a == b, za, za + t * (zb - za))


def slopes(d: torch.Tensor):
    """[B, C, H, W] -> (d/dx [B, C, H, W-1], d/dy [B, C, H-1, W]) in zeta per crop-NDC unit."""
    sx = 0.5 * (d.shape[-1] - 1)
    sy = 0.5 * (d.shape[-2] - 1)
    return (d[..., 1:] - d[..., :-1]) * sx, (d[..., 1:, :] - d[..., :-1, :]) * sy


def geometry_loss(pred: torch.Tensor, target: torch.Tensor, inside: torch.Tensor, max_slope: float = MAX_SLOPE, slope_weight: float = 1.0) -> torch.Tensor:
    """L1 of the depths on the inside rays plus `slope_weight` x L1 of the slopes (the normals)
    between inside neighbours whose true step is not an occlusion edge; each term a mean over
    its pixels and both surfaces, 0 where there are none."""
    ins = inside.expand_as(target)
    depth = ((pred - target).abs() * ins).sum() / ins.sum().clamp(min=1)
    if slope_weight == 0:
        return depth
    px, py = slopes(pred)
    tx, ty = slopes(target)
    ox = ins[..., 1:] & ins[..., :-1] & (tx.abs() < max_slope)
    oy = ins[..., 1:, :] & ins[..., :-1, :] & (ty.abs() < max_slope)
    n = (ox.sum() + oy.sum()).clamp(min=1)
    slope = (((px - tx).abs() * ox).sum() + ((py - ty).abs() * oy).sum()) / n
    return depth + slope_weight * slope


class GeomHead(nn.Module):
    """A per-pixel head (1x1 convs, like the series head) from the Fourier head's last decoder
    features to the two depth maps. Training only: the exported network is the series head's."""

    def __init__(self, c: int, hidden: int = 32):
        super().__init__()
        self.net = nn.Sequential(nn.Conv2d(c, hidden, 1), nn.ReLU(inplace=True), nn.Conv2d(hidden, 2, 1))

    def forward(self, feat: torch.Tensor) -> torch.Tensor:
        return self.net(feat)
