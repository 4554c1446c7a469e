"""The networks (MonoPort's design, sized for an edge CPU).

Coordinate convention (the engine's, ARCHITECTURE.md): NDC [-1, 1]^3 of the input view,
x right, y down, z toward the camera. Features are sampled with
``grid_sample(align_corners=True, padding_mode="border")``: NDC -1 / +1 are the centres of
the first / last feature pixels, points outside are clamped to the border. The engine
implements the same rule (service/engine/src/model/sample.rs) and a golden test checks it.
"""

from __future__ import annotations

import math

import torch
import torch.nn as nn
import torch.nn.functional as F

SOFTZ_BINS = 64
INPUT_SIZE = 256


def soft_z(z: torch.Tensor, n: int = SOFTZ_BINS) -> torch.Tensor:
    """SoftZ (METHOD.md): [..] -> [.., n]. Non-finite z is refused; z is clamped to [-1, 1];
    at z = 1 the last bin is 1."""
    if not torch.isfinite(z).all():
        raise ValueError("SoftZ input must be finite")
    p = 0.5 * (z.clamp(-1.0, 1.0) + 1.0) * (n - 1)
    k = torch.floor(p).clamp(0, n - 1)
    t = (p - k).clamp(0.0, 1.0)
    k = k.long()
    out = torch.zeros(*z.shape, n, dtype=z.dtype, device=z.device)
    last = k == n - 1
    k1 = (k + 1).clamp(max=n - 1)
    out.scatter_(-1, k.unsqueeze(-1), torch.where(last, torch.ones_like(t), 1.0 - t).unsqueeze(-1))
    out.scatter_add_(-1, k1.unsqueeze(-1), torch.where(last, torch.zeros_like(t), t).unsqueeze(-1))
    return out


def sample_features(feat: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
    """feat [B, C, H, W], xy [B, N, 2] (NDC x right, y down) -> [B, N, C]."""
    g = xy.unsqueeze(2)  # [B, N, 1, 2]
    s = F.grid_sample(feat, g, mode="bilinear", padding_mode="border", align_corners=True)
    return s.squeeze(-1).transpose(1, 2)


def conv_bn(cin, cout, stride=1):
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class Block(nn.Module):
    def __init__(self, c):
        super().__init__()
        self.a = nn.Conv2d(c, c, 3, 1, 1, bias=False)
        self.an = nn.BatchNorm2d(c)
        self.b = nn.Conv2d(c, c, 3, 1, 1, bias=False)
        self.bn = nn.BatchNorm2d(c)

    def forward(self, x):
        return F.relu(x + self.bn(self.b(F.relu(self.an(self.a(x))))))


class SegNet(nn.Module):
    """Compact U-Net: 256x256 RGB in [0, 1] -> soft person mask (logit in training)."""

    def __init__(self, c=12):
        super().__init__()
        self.e0 = conv_bn(3, c, 2)  # 128
        self.e1 = conv_bn(c, 2 * c, 2)  # 64
        self.e2 = conv_bn(2 * c, 4 * c, 2)  # 32
        self.e3 = nn.Sequential(conv_bn(4 * c, 8 * c, 2), Block(8 * c))  # 16
        self.d2 = conv_bn(8 * c + 4 * c, 4 * c)
        self.d1 = conv_bn(4 * c + 2 * c, 2 * c)
        self.d0 = conv_bn(2 * c + c, c)
        self.out = nn.Conv2d(c, 1, 3, 1, 1)

    def forward(self, x):
        x = x * 2.0 - 1.0
        e0 = self.e0(x)
        e1 = self.e1(e0)
        e2 = self.e2(e1)
        e3 = self.e3(e2)
        up = lambda t: F.interpolate(t, scale_factor=2.0, mode="nearest")
        d2 = self.d2(torch.cat([up(e3), e2], 1))
        d1 = self.d1(torch.cat([up(d2), e1], 1))
        d0 = self.d0(torch.cat([up(d1), e0], 1))
        return F.interpolate(self.out(d0), scale_factor=2.0, mode="bilinear", align_corners=False)


class HREncoder(nn.Module):
    """HRNetV2-small in spirit: a stride-4 stem, then two stages of parallel resolutions
    (1/4 and 1/8) exchanging information, fused into one 1/4-resolution feature map.
    Input: [B, 4, 256, 256] (masked RGB in [-1, 1] and the mask); output [B, F, 64, 64]."""

    def __init__(self, c=16, f=32, cin=4):
        super().__init__()
        self.stem = nn.Sequential(conv_bn(cin, c, 2), conv_bn(c, c, 2))
        self.hi1 = Block(c)
        self.down1 = conv_bn(c, 2 * c, 2)
        self.lo1 = Block(2 * c)
        self.hi2, self.lo2 = Block(c), Block(2 * c)
        self.lo_to_hi = nn.Sequential(nn.Conv2d(2 * c, c, 1, bias=False), nn.BatchNorm2d(c))
        self.hi_to_lo = nn.Sequential(nn.Conv2d(c, 2 * c, 3, 2, 1, bias=False), nn.BatchNorm2d(2 * c))
        self.hi3, self.lo3 = Block(c), Block(2 * c)
        self.head = nn.Sequential(nn.Conv2d(3 * c, f, 1, bias=False), nn.BatchNorm2d(f), nn.ReLU(inplace=True), nn.Conv2d(f, f, 1))

    def forward(self, x):
        h = self.hi1(self.stem(x))
        l = self.lo1(self.down1(h))
        h, l = self.hi2(h), self.lo2(l)
        up = F.interpolate(self.lo_to_hi(l), scale_factor=2.0, mode="nearest")
        h, l = F.relu(h + up), F.relu(l + self.hi_to_lo(h))
        h, l = self.hi3(h), self.lo3(l)
        fused = torch.cat([h, F.interpolate(l, scale_factor=2.0, mode="nearest")], 1)
        return self.head(fused)


class CBN(nn.Module):
    """Conditional batch norm: gamma(c) * (f - mu) / sqrt(var + 1e-5) + beta(c)."""

    def __init__(self, ch, cond):
        super().__init__()
        self.bn = nn.BatchNorm1d(ch, affine=False, eps=1e-5)
        self.gamma = nn.Linear(cond, ch)
        self.beta = nn.Linear(cond, ch)
        nn.init.zeros_(self.gamma.weight)
        nn.init.ones_(self.gamma.bias)
        nn.init.zeros_(self.beta.weight)
        nn.init.zeros_(self.beta.bias)

    def forward(self, f, c):
        return self.gamma(c) * self.bn(f) + self.beta(c)


class CbnMlp(nn.Module):
    """Occupancy MLP with conditional batch norm: input the depth code (SoftZ [N, 64] or scalar
    z [N, 1]), conditioned on the pixel-aligned feature [N, F]; 5 blocks, ReLU after each;
    output occupancy in [0, 1] (logit in training)."""

    def __init__(self, f=32, hidden=64, zdim=SOFTZ_BINS, blocks=5):
        super().__init__()
        self.inp = nn.Linear(zdim, hidden)
        self.lin = nn.ModuleList([nn.Linear(hidden, hidden) for _ in range(blocks - 1)])
        self.cbn = nn.ModuleList([CBN(hidden, f) for _ in range(blocks)])
        self.out = nn.Linear(hidden, 1)

    def forward(self, feat, z):
        h = F.relu(self.cbn[0](self.inp(z), feat))
        for lin, cbn in zip(self.lin, self.cbn[1:]):
            h = F.relu(cbn(lin(h), feat))
        return self.out(h)


class PlainMlp(nn.Module):
    """PIFu's plain MLP: [feature, scalar z] -> occupancy (the ablation baseline)."""

    def __init__(self, f=32, hidden=64, zdim=1, blocks=5):
        super().__init__()
        layers, cin = [], f + zdim
        for _ in range(blocks):
            layers += [nn.Linear(cin, hidden), nn.ReLU(inplace=True)]
            cin = hidden
        self.net = nn.Sequential(*layers, nn.Linear(hidden, 1))

    def forward(self, feat, z):
        return self.net(torch.cat([feat, z], 1))


class ColorEncoder(nn.Module):
    """Colour encoder g_T: [B, 4, 256, 256] -> [B, F, 64, 64]."""

    def __init__(self, c=16, f=24):
        super().__init__()
        self.net = nn.Sequential(conv_bn(4, c, 2), conv_bn(c, c, 2), Block(c), Block(c), nn.Conv2d(c, f, 1))

    def forward(self, x):
        return self.net(x)


class ColorMlp(nn.Module):
    """f_T: [feature, pixel RGB, z] -> RGB in [0, 1]; skip connections re-inject the input,
    LeakyReLU, tanh at the end (rescaled to [0, 1])."""

    def __init__(self, f=24, widths=(128, 96, 64, 32)):
        super().__init__()
        cin = f + 3 + 1
        self.layers = nn.ModuleList()
        prev = cin
        for i, w in enumerate(widths):
            self.layers.append(nn.Linear(prev + (cin if i in (1, 2) else 0), w))
            prev = w
        self.out = nn.Linear(prev, 3)

    def forward(self, feat, rgb, z):
        x = torch.cat([feat, rgb, z], 1)
        h = x
        for i, lin in enumerate(self.layers):
            if i in (1, 2):
                h = torch.cat([h, x], 1)
            h = F.leaky_relu(lin(h), 0.2)
        return 0.5 * (torch.tanh(self.out(h)) + 1.0)


class FourierNet(nn.Module):
    """The Fourier occupancy head (FOF): a U-Net from the encoder input [B, 4, 256, 256] to the
    2K+1 coefficient maps [B, 2K+1, 128, 128] of the occupancy along each pixel's ray
    (fourier.py). Five scales down to 8x8 so that every pixel sees the whole person (depth
    needs global context), skips at every scale, a per-pixel MLP head (1x1 convs)."""

    def __init__(self, k=15, c=12, shift=False, in_ch=4, out_ch=None, hr=False):
        super().__init__()
        self.k = k
        self.shift = shift
        self.hr = hr
        self.e0 = conv_bn(in_ch, c, 2)  # 128
        if hr:
            # `hr` (the -hr variants, hands.md section 32): a residual block on the encoder's
            # and on the decoder's 128-px level, the maps' own resolution, where a hand is 2-5
            # pixels wide and the plain net has one convolution of the input. Their last batch
            # norms start at zero: the blocks start as the identity (the input is a ReLU's), so
            # a plain checkpoint loads into an -hr net as the same function.
            self.e0x, self.d0x = Block(c), Block(2 * c)
            for b in (self.e0x, self.d0x):
                nn.init.zeros_(b.bn.weight)
        self.e1 = nn.Sequential(conv_bn(c, 2 * c, 2), Block(2 * c))  # 64
        self.e2 = nn.Sequential(conv_bn(2 * c, 4 * c, 2), Block(4 * c))  # 32
        self.e3 = nn.Sequential(conv_bn(4 * c, 8 * c, 2), Block(8 * c), Block(8 * c))  # 16
        self.e4 = nn.Sequential(conv_bn(8 * c, 8 * c, 2), Block(8 * c))  # 8
        self.d3 = conv_bn(16 * c, 8 * c)
        self.d2 = conv_bn(8 * c + 4 * c, 4 * c)
        self.d1 = conv_bn(4 * c + 2 * c, 2 * c)
        self.d0 = conv_bn(2 * c + c, 2 * c)
        # A per-pixel MLP head: a 1x1 conv straight from 2c channels would confine the 2K+1
        # coefficients of every pixel to a (2c)-dimensional affine subspace.
        # With `shift`, one more channel: the ray's depth centre d (tanh, zeta units), and the
        # 2K+1 channels are the series of the occupancy *relative to d*, rotated into place
        # below (`shift_series`): depth enters as a phase, so the network predicts d (smooth
        # in the image) and a nearly depth-free profile instead of cos/sin(k pi d) itself.
        # `out_ch`: another per-pixel output instead of the series (FourierGeomNet's surfaces).
        self.out = nn.Sequential(nn.Conv2d(2 * c, 64, 1), nn.ReLU(inplace=True), nn.Conv2d(64, out_ch or 2 * k + 1 + int(shift), 1))

    def forward(self, x, with_centre: bool = False):
        return self.head(self.features(x), with_centre)

    def features(self, x):
        """The last decoder level [B, 2c, 128, 128], which the series head reads per pixel
        (and, in training, `surfaces.GeomHead`)."""
        e0 = self.e0(x)
        if self.hr:
            e0 = self.e0x(e0)
        e1 = self.e1(e0)
        e2 = self.e2(e1)
        e3 = self.e3(e2)
        e4 = self.e4(e3)
        up = lambda t: F.interpolate(t, scale_factor=2.0, mode="bilinear", align_corners=False)
        d3 = self.d3(torch.cat([up(e4), e3], 1))
        d2 = self.d2(torch.cat([up(d3), e2], 1))
        d1 = self.d1(torch.cat([up(d2), e1], 1))
        d0 = self.d0(torch.cat([up(d1), e0], 1))
        return self.d0x(d0) if self.hr else d0

    def head(self, d0, with_centre: bool = False):
        out = self.out(d0)
        if not self.shift:
            return (out, None) if with_centre else out
        d = torch.tanh(out[:, 2 * self.k + 1 :])
        coeff = shift_series(out[:, : 2 * self.k + 1], d, self.k)
        return (coeff, d) if with_centre else coeff


class FourierGeomNet(nn.Module):
    """Issue 34 part 3 (FOF-X: a geometric intermediate fed to the coefficient regressor): a
    first U-Net predicts the person's front and back surfaces as two depth maps [B, 2, 128,
    128] (zeta, the body depth frame; supervised by `surfaces.geometry_loss`: depths and their
    slopes, the normals), which are masked, brought to the input's size and given to the
    series U-Net beside the image and mask. Same input and output as FourierNet (the engine
    loads it as any Fourier head); about twice fourier-small's work, a GPU board's model.

    `from_small` starts both halves from a trained FourierNet of the same width: the surface
    net from its trunk (a new 2-channel head), the series net from all of it with zero weights
    on the two new input channels, so the pair computes the small net's series at the start."""

    def __init__(self, k=15, c=8, g=8):
        super().__init__()
        self.k = k
        self.shift = False
        self.geom = FourierNet(k, g, out_ch=2)
        self.series = FourierNet(k, c, in_ch=6)

    def surfaces(self, x):
        return self.geom(x)

    def series_of(self, x, surf):
        up = F.interpolate(surf, scale_factor=2.0, mode="bilinear", align_corners=False)
        return self.series(torch.cat([x, up * x[:, 3:4]], 1))

    def forward(self, x, with_centre: bool = False):
        out = self.series_of(x, self.surfaces(x))
        return (out, None) if with_centre else out

    @torch.no_grad()
    def from_small(self, sd: dict):
        """Both halves from a FourierNet state dict `sd` (see the class docs)."""
        own = self.state_dict()
        for n, v in sd.items():
            g, s = "geom." + n, "series." + n
            # (The surface net's last layer has 2 outputs, not the series': it stays fresh.)
            if g in own and own[g].shape == v.shape:
                own[g] = v.clone()
            if s in own:
                if own[s].shape == v.shape:
                    own[s] = v.clone()
                elif n == "e0.0.weight":
                    w = torch.zeros_like(own[s])
                    w[:, : v.shape[1]] = v
                    own[s] = w
                else:
                    raise ValueError(f"{n}: {tuple(v.shape)} does not fit {tuple(own[s].shape)}")
        self.load_state_dict(own)


def make_fourier(variant: str) -> nn.Module:
    """The network of a Fourier variant (FOURIER_VARIANTS)."""
    k, c, shift = fourier_variant(variant)
    if variant in GEOM_VARIANTS:
        return FourierGeomNet(k, c, GEOM_VARIANTS[variant])
    return FourierNet(k, c, shift, hr=variant in HR_VARIANTS)


def shift_series(rel: torch.Tensor, d: torch.Tensor, k: int) -> torch.Tensor:
    """Series of f(z) = g(z - d) from the series of g ([B, 2K+1, H, W], channels c0, a1, b1,
    ...) and the shift d [B, 1, H, W]: each (a_k, b_k) pair rotated by k pi d."""
    kk = torch.arange(1, k + 1, dtype=rel.dtype, device=rel.device).view(1, k, 1, 1) * math.pi
    ang = kk * d
    cs, sn = torch.cos(ang), torch.sin(ang)
    a, b = rel[:, 1::2], rel[:, 2::2]
    na = a * cs - b * sn
    nb = a * sn + b * cs
    ab = torch.stack([na, nb], 2).flatten(1, 2)
    return torch.cat([rel[:, :1], ab], 1)


FOURIER_VARIANTS = {
    # name: (K, encoder width c)
    "fourier": (15, 12),
    "fourier-k7": (7, 12),
    "fourier-k31": (31, 12),
    "fourier-small": (15, 8),
    # fourier-small with 31 harmonics (63 maps): the series' K as a knob of accuracy against
    # time (widen.py grows a K = 15 checkpoint into it with the new harmonics at zero)
    "fourier-small-k31": (31, 8),
    # fourier-small widened (volcap_train.widen) and trained on: more capacity, same K
    "fourier-medium": (15, 12),
    # ... and wider still (hands.md section 26, run (28): a candidate for the GPU boards, 3.5x fourier-small's MACs)
    "fourier-wide": (15, 16),
    "fourier-tiny": (15, 6),
    # fourier-medium with a residual block at the maps' resolution in the encoder and the
    # decoder (HR_VARIANTS; hands.md section 32)
    "fourier-medium-hr": (15, 12),
    # name: (K, c, depth as a phase shift)
    "fourier-shift": (15, 12, True),
    # FourierGeomNet: (K, series width c); its surface net's width in GEOM_VARIANTS
    "fourier-geom": (15, 8),
}
# Surface net width of the FourierGeomNet variants.
GEOM_VARIANTS = {"fourier-geom": 8}
# Variants with the residual blocks at the maps' resolution (FourierNet's `hr`).
HR_VARIANTS = {"fourier-medium-hr"}


def fourier_variant(name: str):
    """(K, c, shift) of a Fourier variant."""
    v = FOURIER_VARIANTS[name]
    return (v[0], v[1], v[2] if len(v) > 2 else False)


def encoder_input(rgb01: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """[B, 3, H, W] RGB in [0, 1] and [B, 1, H, W] mask in [0, 1] -> the encoders' 4-channel input."""
    return torch.cat([(rgb01 * 2.0 - 1.0) * mask, mask], 1)


SHAPE_VARIANTS = {
    # name: (encoder c, feature channels, mlp kind, hidden, z encoding)
    "compact": (16, 32, "cbn", 64, "softz"),
    "large": (24, 48, "cbn", 128, "softz"),
    "compact-plain-z": (16, 32, "plain", 64, "scalar"),
    "compact-cbn-z": (16, 32, "cbn", 64, "scalar"),
}


def make_shape(variant: str):
    c, f, kind, hidden, zenc = SHAPE_VARIANTS[variant]
    zdim = SOFTZ_BINS if zenc == "softz" else 1
    enc = HREncoder(c, f)
    mlp = CbnMlp(f, hidden, zdim) if kind == "cbn" else PlainMlp(f, hidden, zdim)
    return enc, mlp, zenc


def encode_z(z: torch.Tensor, zenc: str) -> torch.Tensor:
    return soft_z(z) if zenc == "softz" else z.unsqueeze(-1)
