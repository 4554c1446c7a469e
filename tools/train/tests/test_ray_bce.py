"""ray_level_bce: the surface-level loss of `train fourier --ray-bce-weight` is small where the
prediction reads the target's inside above the level, large where a thin ray's blurred series
stays under it (what the Parseval L2 barely sees), and finite for wild series."""
import torch
from series_maps import interval_maps

from volcap_train import fourier as FO
from volcap_train.ray_losses import ray_level_bce

K = 15


def _maps(intervals):
    """[1, 2K+1, 4, 4] maps: each listed pixel holds one interval (zeta), the rest empty."""
    return interval_maps(intervals, K)


def test_a_blurred_thin_ray_costs_more_than_its_l2_says():
    g = torch.Generator().manual_seed(0)
    target = _maps({(1, 1): (-0.05, 0.15), (2, 2): (-0.6, 0.5)})  # a hand's ray, a torso's ray
    blurred = target.clone()
    blurred[0, :, 1, 1] = target[0, :, 1, 1] * 0.4  # the thin ray's series at 40 %: peak under 0.5
    exact = ray_level_bce(target, target, K, 64, g, band=0)
    bad = ray_level_bce(blurred, target, K, 64, torch.Generator().manual_seed(0), band=0)
    l2 = FO.parseval_l2(blurred, target).mean() - FO.parseval_l2(target, target).mean()
    assert bad > 1.5 * exact
    assert l2 < 0.02  # the dense L2 hardly notices
    # The gradient raises the thin ray's series (its constant term) toward the level.
    p = blurred.clone().requires_grad_(True)
    ray_level_bce(p, target, K, 64, torch.Generator().manual_seed(0), band=0).backward()
    assert p.grad[0, 0, 1, 1] < 0


def test_only_the_person_and_its_band_count_and_wild_series_stay_finite():
    g = torch.Generator().manual_seed(1)
    target = _maps({(1, 1): (-0.3, 0.3)})
    far = torch.zeros_like(target)
    far[0, 0, 3, 3] = 5.0  # a blob three pixels away, outside a band of 1
    assert ray_level_bce(far + target, target, K, 32, g, band=1) <= ray_level_bce(target, target, K, 32, torch.Generator().manual_seed(1), band=1) + 1e-6
    wild = torch.full_like(target, 1e6)
    wild[0, 1::2] = -1e6
    v = ray_level_bce(wild, target, K, 32, g)
    assert torch.isfinite(v) and v > 0
    assert ray_level_bce(torch.zeros_like(target), torch.zeros_like(target), K, 32, g) == 0
