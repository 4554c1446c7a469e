"""The exporter's surface-level calibration (fourier.best_level)."""

import torch

from volcap_train import fourier as FO


def _thin_parts(blur: float):
    """Rays through intervals of random width, labelled points along them, and the series
    of each interval scaled by `blur` (1: the exact series; < 1: a regression's shrunken
    prediction of thin parts)."""
    g = torch.Generator().manual_seed(3)
    k, b, n = 15, 6, 400
    lo = -0.05 - 0.3 * torch.rand(b, generator=g)
    hi = lo + 0.1 + 0.5 * torch.rand(b, generator=g)
    coeff = FO.interval_coeffs(lo, hi, k) * blur  # [B, 2K+1]
    z = torch.rand(b, n, generator=g) * 2 - 1
    lab = (z >= lo[:, None]) & (z <= hi[:, None])
    occ = FO.decode(coeff[:, None, :].expand(b, n, -1), z, k)
    return occ, lab


def test_the_exact_series_is_read_at_one_half():
    occ, lab = _thin_parts(1.0)
    level, ious = FO.best_level(occ, lab)
    assert abs(level - 0.5) <= 0.05, ious
    assert ious[0.5] > 0.9


def test_a_shrunken_prediction_is_read_lower_and_gains_iou():
    occ, lab = _thin_parts(0.6)
    level, ious = FO.best_level(occ, lab)
    assert level < 0.5, ious
    assert ious[level] > ious[0.5] + 0.05, ious


def test_no_labels_and_no_prediction_do_not_divide_by_zero():
    occ = torch.zeros(2, 10)
    lab = torch.zeros(2, 10, dtype=torch.bool)
    level, ious = FO.best_level(occ, lab)
    assert level == 0.5 and all(v == 1.0 for v in ious.values())


def test_near_ties_go_to_the_level_nearest_one_half():
    # IoU 1.0 / 0.5 / 0.25 at 0.30 / 0.40 / 0.50: without tolerance the best; with one
    # that covers 0.40 (not 0.50), the level nearer 0.5.
    occ = torch.tensor([[0.32, 0.37, 0.42, 0.9, 0.1]])
    lab = torch.tensor([[True, True, True, True, False]])
    level, ious = FO.best_level(occ, lab, levels=(0.30, 0.40, 0.50), tol=0.0)
    assert level == 0.30 and ious[0.30] > ious[0.40] > ious[0.50]
    level, _ = FO.best_level(occ, lab, levels=(0.30, 0.40, 0.50), tol=0.6)
    assert level == 0.40
