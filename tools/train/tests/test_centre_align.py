"""`train fourier --centre-align` (ray_losses.centre_aligned): a thin ray whose depth is unsure
by its own thickness must be learnt as a sharp pulse, not as the low blur the plain L2 favours."""

import torch

from volcap_train import fourier as FO
from volcap_train.ray_losses import centre_aligned

K = 15


def pulse(centre: float, width: float) -> torch.Tensor:
    """[1, 2K+1, 1, 1]: one interval's series, as the maps hold it."""
    lo = torch.tensor([[centre - width / 2]], dtype=torch.float64)
    return FO.interval_coeffs(lo, lo + width, K).permute(2, 0, 1)[None]


def aligned_loss(pred: torch.Tensor, target: torch.Tensor) -> float:
    moved, _, l1 = centre_aligned(pred, target, K)
    return float(FO.parseval_l2(pred, moved, dim=1).mean() + 0.2 * l1)


def plain_loss(pred: torch.Tensor, target: torch.Tensor) -> float:
    return float(FO.parseval_l2(pred, target, dim=1).mean())


def test_a_sharp_pulse_beats_the_blur_when_the_depth_is_unsure():
    # A hand 0.055 zeta thick (3 cm) whose depth the image leaves unsure by +-0.04.
    truths = [pulse(0.10 + dz, 0.055) for dz in (-0.04, 0.0, 0.04)]
    sharp = pulse(0.10, 0.055)
    blur = sum(truths) / 3
    mean_plain = lambda p: sum(plain_loss(p, t) for t in truths) / 3
    mean_aligned = lambda p: sum(aligned_loss(p, t) for t in truths) / 3
    # The plain L2's optimum is the blur, whose peak falls under the surface level 0.55 ...
    assert mean_plain(blur) < mean_plain(sharp)
    z = torch.linspace(-1, 1, 2001, dtype=torch.float64)
    peak = lambda c: float(FO.decode(c[0, :, 0, 0], z[:, None], K).max())
    assert peak(blur) < 0.55 < peak(sharp)
    # ... the aligned loss prefers the sharp pulse.
    assert mean_aligned(sharp) < mean_aligned(blur)


def test_the_moved_target_sits_at_the_predicted_centroid_and_keeps_its_profile():
    target, pred = pulse(0.10, 0.06), pulse(0.16, 0.06)
    moved, shift, l1 = centre_aligned(pred, target, K)
    assert abs(float(shift) - 0.06) < 1e-3
    assert abs(float(l1) - 0.06) < 1e-3
    assert float(FO.parseval_l2(pred, moved, dim=1).max()) < 1e-6
    # the profile's energy (Parseval) is unchanged by the move
    assert abs(float((moved ** 2).sum() - (target ** 2).sum())) < 1e-9


def test_rays_without_mass_are_not_moved_and_shifts_are_bounded():
    target = torch.cat([pulse(0.0, 0.3), torch.zeros(1, 2 * K + 1, 1, 1, dtype=torch.float64)], 3)
    pred = torch.cat([pulse(0.9, 0.1), pulse(0.2, 0.2)], 3)
    moved, shift, l1 = centre_aligned(pred, target, K, max_shift=0.25)
    assert float(shift[0, 0, 0, 0]) == 0.25  # clamped (a 0.9 move asked)
    assert float(shift[0, 0, 0, 1]) == 0.0  # no truth on the ray: nothing to move
    assert torch.equal(moved[..., 1], target[..., 1])
    assert torch.isfinite(l1)


def test_gradients_stay_finite_on_empty_and_saturated_maps():
    for fill in (0.0, 1e-7, 50.0, -50.0):
        pred = torch.full((2, 2 * K + 1, 4, 4), fill, requires_grad=True)
        target = torch.zeros(2, 2 * K + 1, 4, 4)
        target[:, :, 1:3, 1:3] = pulse(0.1, 0.2).float()
        moved, _, l1 = centre_aligned(pred, target, K)
        loss = FO.parseval_l2(pred, moved, dim=1).mean() + l1
        loss.backward()
        assert torch.isfinite(loss) and torch.isfinite(pred.grad).all()


def test_the_thin_ray_diagnostic_tells_a_blur_from_a_miss():
    from volcap_train.fourier_diag import thin_rays
    from volcap_train.nets import shift_series

    # One image: a torso 20 map pixels wide and a hand 2 pixels wide beside it.
    coeff = torch.zeros(1, 2 * K + 1, 128, 128)
    coeff[..., 40:90, 50:70] = pulse(0.0, 0.4).float()
    coeff[..., 60:66, 75:77] = pulse(0.1, 0.055).float()
    d = {"rgb": torch.zeros(1, 3, 256, 256, dtype=torch.uint8), "mask": torch.full((1, 1, 256, 256), 255, dtype=torch.uint8), "coeff": coeff}
    exact = thin_rays(lambda x: coeff, d, K, 1)
    assert exact["rays"] == 12 and exact["peak_depth_error_median"] < 0.01
    assert exact["peak_median"] == exact["truth_peak_median"] > 0.55
    blur = lambda x: sum(shift_series(coeff, torch.full((1, 1, 128, 128), dz), K) for dz in (-0.04, 0.0, 0.04)) / 3
    b = thin_rays(blur, d, K, 1)
    assert b["peak_median"] < 0.55 < b["truth_peak_median"]
    assert b["decoded_share"] == 0.0 and b["peak_depth_error_median"] < 0.01  # right depth, under the level
    assert exact["missed_share"] == exact["false_decoded_share"] == 0.0 and exact["length_ratio_median"] == 1.0
    assert b["missed_share"] == 1.0 and b["false_decoded_share"] == 0.0
    # The hand twice as thick in depth: decoded, at its depth, twice as long above the level.
    thick = coeff.clone()
    thick[..., 60:66, 75:77] = pulse(0.1, 0.11).float()
    t = thin_rays(lambda x: thick, d, K, 1)
    assert t["missed_share"] == t["false_decoded_share"] == 0.0
    assert 1.6 < t["length_ratio_median"] < 2.4, t["length_ratio_median"]
    # A hand the truth leaves under the level (thinner than the series resolves), decoded by the net.
    faint = coeff.clone()
    faint[..., 60:66, 75:77] = pulse(0.1, 0.025).float()
    f = thin_rays(lambda x: coeff, {**d, "coeff": faint}, K, 1)
    assert f["truth_decoded_share"] == 0.0 and f["false_decoded_share"] == 1.0 and f["missed_share"] == 0.0


def test_only_the_chosen_rays_are_moved():
    target = torch.cat([pulse(0.0, 0.3), pulse(0.1, 0.05)], 3)
    pred = torch.cat([pulse(0.1, 0.3), pulse(0.15, 0.05)], 3)
    only = torch.tensor([[[False, True]]])
    moved, shift, _ = centre_aligned(pred, target, K, only=only)
    assert float(shift[0, 0, 0, 0]) == 0.0 and torch.equal(moved[..., 0], target[..., 0])
    assert abs(float(shift[0, 0, 0, 1]) - 0.05) < 2e-3
