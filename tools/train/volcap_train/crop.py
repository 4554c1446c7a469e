"""The person crop, one rule shared with the engine (service/engine/src/model/preprocess.rs).

From a mask (> 0.5 is person) on the 256x256 input square, take the bounding box of person
pixels in NDC (pixel centres, align_corners=True: pixel i is at -1 + 2 i / (S - 1)), its centre
``t = (tx, ty)`` and ``s = max(w, h) / 2 / FILL`` (at least MIN_SCALE). A crop NDC point
``u`` maps to input NDC ``x = s u + t`` (x, y) and ``z = s u_z`` (depth scaled alike, so that the
crop cube stays metric). No person pixel: no crop (the caller reports "no person").
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

FILL = 0.8
MIN_SCALE = 0.125


def crop_params(mask: torch.Tensor):
    """mask [H, W] -> (s, tx, ty) as floats, or None if empty."""
    h, w = mask.shape
    ys, xs = torch.nonzero(mask > 0.5, as_tuple=True)
    if len(xs) == 0:
        return None
    x0, x1 = -1 + 2 * xs.min().item() / (w - 1), -1 + 2 * xs.max().item() / (w - 1)
    y0, y1 = -1 + 2 * ys.min().item() / (h - 1), -1 + 2 * ys.max().item() / (h - 1)
    s = max(max(x1 - x0, y1 - y0) / 2 / FILL, MIN_SCALE)
    return s, 0.5 * (x0 + x1), 0.5 * (y0 + y1)


def apply_crop(img: torch.Tensor, params) -> torch.Tensor:
    """img [C, H, W] -> the crop resampled to the same size (bilinear, zeros outside)."""
    s, tx, ty = params
    theta = torch.tensor([[[s, 0.0, tx], [0.0, s, ty]]], dtype=img.dtype)
    grid = F.affine_grid(theta, (1, *img.shape), align_corners=True)
    return F.grid_sample(img[None], grid, mode="bilinear", padding_mode="zeros", align_corners=True)[0]


def to_crop(points: torch.Tensor, params) -> torch.Tensor:
    """Input-view NDC points [.., 3] -> crop NDC."""
    s, tx, ty = params
    out = points.clone()
    out[..., 0] = (points[..., 0] - tx) / s
    out[..., 1] = (points[..., 1] - ty) / s
    out[..., 2] = points[..., 2] / s
    return out
