"""Reading `volcap sim dataset` shards and making training batches.

Shards: ``DIR/{train,val}/<subject>/<pose>_<view>.safetensors`` with ``image`` u8 [H, W, 3],
``mask`` u8 [H, W], ``points`` f32 [N, 3] (input-view NDC), ``occ`` f32 [N], ``surface``
f32 [M, 3], ``surface_rgb`` f32 [M, 3] (see service/sim/src/dataset.rs).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from safetensors.numpy import load_file

from .nets import INPUT_SIZE


class Split:
    """One split held in memory as tensors."""

    def __init__(self, root: Path, split: str, limit: int | None = None):
        files = sorted((root / split).glob("*/*.safetensors"))
        if limit:
            files = files[:limit]
        if not files:
            raise FileNotFoundError(f"{root / split}: no *.safetensors shards (run `volcap sim dataset --out {root}`)")
        imgs, masks, pts, occ, surf, srgb = [], [], [], [], [], []
        # Per-pixel ray intervals (CSR, input NDC z), when the shards have them.
        self.ray_offsets, self.ray_z = [], []
        for f in files:
            t = load_file(str(f))
            img = t["image"]
            if img.shape != (INPUT_SIZE, INPUT_SIZE, 3):
                raise ValueError(f"{f}: image shape {img.shape}, expected ({INPUT_SIZE}, {INPUT_SIZE}, 3)")
            imgs.append(img)
            masks.append(t["mask"])
            pts.append(t["points"])
            occ.append(t["occ"])
            surf.append(t["surface"])
            srgb.append(t["surface_rgb"])
            if "ray_offsets" in t:
                self.ray_offsets.append(torch.from_numpy(t["ray_offsets"].astype(np.int64)))
                self.ray_z.append(torch.from_numpy(t["ray_z"]))
        n = min(len(p) for p in pts)
        m = min(len(s) for s in surf)
        self.files = [str(f) for f in files]
        self.image = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2).contiguous()  # u8 [B,3,H,W]
        self.mask = torch.from_numpy(np.stack(masks)).unsqueeze(1).contiguous()  # u8 [B,1,H,W]
        self.points = torch.from_numpy(np.stack([p[:n] for p in pts]))
        self.occ = torch.from_numpy(np.stack([o[:n] for o in occ]))
        self.surface = torch.from_numpy(np.stack([s[:m] for s in surf]))
        self.surface_rgb = torch.from_numpy(np.stack([s[:m] for s in srgb]))
        for name in ("points", "occ", "surface", "surface_rgb"):
            if not torch.isfinite(getattr(self, name)).all():
                raise ValueError(f"{root / split}: non-finite values in {name}")
        manifest = root / "dataset.json"
        self.manifest = json.loads(manifest.read_text()) if manifest.exists() else {}

    def __len__(self):
        return self.image.shape[0]

    def rgb01(self, idx):
        return self.image[idx].float() / 255.0

    def mask01(self, idx):
        return (self.mask[idx].float() / 255.0).clamp(0, 1) if self.mask.max() > 1 else self.mask[idx].float()


def backgrounds(n: int, size: int, gen: torch.Generator) -> torch.Tensor:
    """Procedural backgrounds [n, 3, size, size] in [0, 1]: smooth gradients, low-frequency
    noise, cluttered rectangles, each tinted, and occasionally near-black or saturated."""
    out = torch.empty(n, 3, size, size)
    yy, xx = torch.meshgrid(torch.linspace(0, 1, size), torch.linspace(0, 1, size), indexing="ij")
    for i in range(n):
        kind = int(torch.randint(0, 4, (1,), generator=gen))
        c0, c1 = torch.rand(3, 1, 1, generator=gen), torch.rand(3, 1, 1, generator=gen)
        if kind == 0:
            a = float(torch.rand(1, generator=gen)) * 2 * math.pi
            t = (xx * math.cos(a) + yy * math.sin(a)).clamp(0, 1)
            bg = c0 + (c1 - c0) * t
        elif kind == 1:
            k = int(torch.randint(2, 9, (1,), generator=gen))
            bg = F.interpolate(torch.rand(1, 3, k, k, generator=gen), size=(size, size), mode="bicubic", align_corners=False)[0]
        elif kind == 2:
            bg = c0.expand(3, size, size).clone()
            for _ in range(int(torch.randint(3, 12, (1,), generator=gen))):
                x0, y0 = torch.randint(0, size, (2,), generator=gen).tolist()
                w, h = torch.randint(8, size // 2, (2,), generator=gen).tolist()
                bg[:, y0 : y0 + h, x0 : x0 + w] = torch.rand(3, 1, 1, generator=gen)
        else:
            bg = F.interpolate(torch.rand(1, 3, 32, 32, generator=gen), size=(size, size), mode="nearest")[0] * 0.5 + c0 * 0.5
        out[i] = bg.clamp(0, 1)
    return out


def _rand(shape, gen: torch.Generator) -> torch.Tensor:
    """Uniform draws on the generator's device (a CUDA generator draws on the GPU: the
    augmentations run where the batch is, `train --device`)."""
    return torch.rand(shape, generator=gen, device=gen.device)


def photometric(rgb: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Random gain/bias/saturation per image; some images pushed to saturation or near black.
    Runs on `rgb`'s device, which must be `gen`'s."""
    b = rgb.shape[0]
    gain = 0.6 + 0.8 * _rand((b, 1, 1, 1), gen)
    bias = 0.1 * (_rand((b, 1, 1, 1), gen) - 0.5)
    gray = rgb.mean(1, keepdim=True)
    sat = 0.5 + _rand((b, 1, 1, 1), gen)
    x = gray + (rgb - gray) * sat
    x = x * gain + bias
    extreme = _rand((b, 1, 1, 1), gen)
    # Over-exposed (p 0.05) and dark (p 0.05), as factors: no boolean indexing, which would
    # wait for the device.
    x = x * torch.where(extreme < 0.05, 2.5, torch.where(extreme < 0.1, 0.15, 1.0))
    return x.clamp(0, 1)


def sensor(rgb: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Camera effects that MakeHuman renders lack and real webcams have, per image: white
    balance (per-channel gain), a gamma curve, defocus blur (p 0.3), sensor noise and a few
    greyscale frames (p 0.1). Input and output [B, 3, H, W] in [0, 1], on `gen`'s device."""
    b = rgb.shape[0]
    wb = 0.8 + 0.4 * _rand((b, 3, 1, 1), gen)
    gamma = torch.exp((_rand((b, 1, 1, 1), gen) - 0.5) * 0.7)  # 0.70 .. 1.42
    x = (rgb * wb).clamp(0, 1).clamp_min(1e-6) ** gamma
    blur = _rand((b,), gen) < 0.3
    if bool(blur.any()):
        k = torch.tensor([1.0, 4.0, 6.0, 4.0, 1.0], device=x.device) / 16.0
        xb = x[blur]
        c = xb.shape[1]
        xb = F.conv2d(F.pad(xb, (2, 2, 0, 0), mode="replicate"), k.view(1, 1, 1, 5).repeat(c, 1, 1, 1), groups=c)
        xb = F.conv2d(F.pad(xb, (0, 0, 2, 2), mode="replicate"), k.view(1, 1, 5, 1).repeat(c, 1, 1, 1), groups=c)
        x[blur] = xb
    sigma = 0.03 * _rand((b, 1, 1, 1), gen)
    x = x + sigma * torch.randn(x.shape, generator=gen, device=gen.device)
    grey = _rand((b,), gen) < 0.1
    x[grey] = x[grey].mean(1, keepdim=True).expand(-1, 3, -1, -1)
    return x.clamp(0, 1)


def random_affine(rgb: torch.Tensor, mask: torch.Tensor, gen: torch.Generator, p: float = 0.5):
    """Scale/shift a fraction p of the images (tiny subjects, subjects cut by the edge)."""
    b = rgb.shape[0]
    theta = torch.zeros(b, 2, 3)
    s = torch.where(torch.rand(b, generator=gen) < p, 0.7 + 2.3 * torch.rand(b, generator=gen), torch.ones(b))
    t = torch.where(torch.rand(b, 1, generator=gen) < p, (torch.rand(b, 2, generator=gen) - 0.5) * 1.2, torch.zeros(b, 2))
    theta[:, 0, 0] = s
    theta[:, 1, 1] = s
    theta[:, :, 2] = t
    grid = F.affine_grid(theta, rgb.shape, align_corners=True)
    rgb = F.grid_sample(rgb, grid, align_corners=True, padding_mode="zeros")
    mask = F.grid_sample(mask, grid, align_corners=True, padding_mode="zeros")
    return rgb, mask, (s, t)
