"""Test helper: small coefficient maps whose listed pixels hold true intervals along their rays."""
import torch

from volcap_train import fourier as FO


def interval_maps(intervals, k: int = 15, size: int = 4) -> torch.Tensor:
    """{(y, x): (lo, hi) or [(lo, hi), ...]} (zeta) -> [1, 2K+1, size, size] float32 maps: each
    listed pixel the series of its intervals (summed in float64), the rest empty."""
    c = torch.zeros(1, FO.channels(k), size, size, dtype=torch.float64)
    for (y, x), ivs in intervals.items():
        for lo, hi in [ivs] if isinstance(ivs[0], (int, float)) else ivs:
            c[0, :, y, x] += FO.interval_coeffs(torch.tensor(lo, dtype=torch.float64), torch.tensor(hi, dtype=torch.float64), k)
    return c.float()
