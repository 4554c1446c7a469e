"""peak_hinge (`train fourier --peak-weight`): a thin ray's blurred, low series is charged by how
far its peak stays under the truth's, wherever its depth; a ray at or above the truth's height
costs nothing; only the selected rays count; wild or empty maps stay finite. over_level
(`--over-weight`), its other side: a surface the truth does not have on the ray (a false decode,
or a decoded interval longer in depth than the truth's) is charged its height over the level."""
import torch
from series_maps import interval_maps

from volcap_train import fourier as FO
from volcap_train.ray_losses import empty_band, over_level, peak_hinge, thin_mask

K = 15


def _maps(intervals):
    return interval_maps(intervals, K)


def _peak(series, n=4096):
    z = torch.linspace(-1, 1, n, dtype=torch.float64)
    return float((FO.basis(z, K) @ series.double()).max())


def test_a_low_blur_costs_its_missing_height_and_the_gradient_raises_the_peak():
    target = _maps({(1, 1): (-0.05, 0.03)})  # a hand's ray, about 4 cm thick
    only = torch.zeros(1, 4, 4, dtype=torch.bool)
    only[0, 1, 1] = True
    blurred = target.clone()
    blurred[0, :, 1, 1] = target[0, :, 1, 1] * 0.6
    v = peak_hinge(blurred, target, K, only, 256)
    # f64 reference: the truth's peak minus the blur's, both read finely.
    ref = _peak(target[0, :, 1, 1]) - _peak(blurred[0, :, 1, 1])
    assert abs(float(v) - ref) < 0.01, (float(v), ref)
    assert ref > 0.2
    p = blurred.clone().requires_grad_(True)
    peak_hinge(p, target, K, only, 256).backward()
    stepped = (p - 0.5 * p.grad).detach()
    assert _peak(stepped[0, :, 1, 1]) > _peak(blurred[0, :, 1, 1]) + 0.05


def test_depth_free_and_zero_at_the_truths_height():
    target = _maps({(1, 1): (-0.05, 0.03)})
    only = torch.zeros(1, 4, 4, dtype=torch.bool)
    only[0, 1, 1] = True
    moved = _maps({(1, 1): (0.15, 0.23)})  # the same pulse 10 cm deeper: the hinge does not see depth
    assert float(peak_hinge(moved, target, K, only, 512)) < 0.01
    higher = target * 1.3
    p = higher.clone().requires_grad_(True)
    v = peak_hinge(p, target, K, only, 64)
    v.backward()
    assert v.item() == 0.0 and p.grad.abs().max().item() == 0.0


def test_only_the_selected_rays_count():
    target = _maps({(1, 1): (-0.05, 0.03), (2, 2): (-0.05, 0.03)})
    only = torch.zeros(1, 4, 4, dtype=torch.bool)
    only[0, 1, 1] = True
    pred = torch.zeros_like(target).requires_grad_(True)
    peak_hinge(pred, target, K, only, 64).backward()
    assert float(pred.grad[0, :, 1, 1].abs().sum()) > 0
    g = pred.grad.clone()
    g[0, :, 1, 1] = 0
    assert float(g.abs().max()) == 0.0
    none = torch.zeros_like(only)
    p = torch.zeros_like(target).requires_grad_(True)
    v = peak_hinge(p, target, K, none, 64)
    v.backward()
    assert v.item() == 0.0 and torch.isfinite(p.grad).all()


def test_wild_and_saturated_maps_stay_finite():
    target = _maps({(1, 1): (-0.05, 0.03)})
    only = thin_mask(target, 1)[:, 0] > 0.5
    assert only[0, 1, 1]
    for wild in (torch.full_like(target, 1e6), torch.full_like(target, -1e6), torch.full_like(target, float(torch.finfo(torch.float32).max) / 1e3)):
        p = wild.clone().requires_grad_(True)
        v = peak_hinge(p, target, K, only, 48)
        v.backward()
        assert torch.isfinite(v) and torch.isfinite(p.grad).all()
        p = wild.clone().requires_grad_(True)
        v = over_level(p, target, K, only, 48)
        v.backward()
        assert torch.isfinite(v) and torch.isfinite(p.grad).all()


def test_a_window_counts_only_height_near_the_truths_depth():
    target = _maps({(1, 1): (-0.05, 0.03)})
    only = torch.zeros(1, 4, 4, dtype=torch.bool)
    only[0, 1, 1] = True
    moved = _maps({(1, 1): (0.15, 0.23)})  # the truth's height, 10 cm (0.2 zeta) deeper
    far = float(peak_hinge(moved, target, K, only, 512, window=0.05))
    assert far > 0.5  # nearly the truth's whole peak is missing where it should be
    near = _maps({(1, 1): (-0.03, 0.05)})  # 1 cm deeper: inside the window
    assert float(peak_hinge(near, target, K, only, 512, window=0.05)) < 0.05
    # The gradient raises the series at the truth's depth, not at the moved pulse's.
    p = moved.clone().requires_grad_(True)
    peak_hinge(p, target, K, only, 512, window=0.05).backward()
    stepped = (p - 0.5 * p.grad).detach()
    z = torch.tensor([-0.01, 0.19], dtype=torch.float64)
    before, after = FO.basis(z, K) @ moved[0, :, 1, 1].double(), FO.basis(z, K) @ stepped[0, :, 1, 1].double()
    assert after[0] > before[0] + 0.05
    assert abs(float(after[1] - before[1])) < abs(float(after[0] - before[0]))


def test_a_cap_asks_no_more_than_its_height():
    target = _maps({(1, 1): (-0.3, 0.3)})  # a thick ray: its series peaks near 1
    only = torch.zeros(1, 4, 4, dtype=torch.bool)
    only[0, 1, 1] = True
    half = target * 0.7
    assert float(peak_hinge(half, target, K, only, 256)) > 0.2
    assert float(peak_hinge(half, target, K, only, 256, cap=0.65)) == 0.0  # 0.7 of the peak is over 0.65
    low = target * 0.5
    assert abs(float(peak_hinge(low, target, K, only, 256, cap=0.65)) - (0.65 - _peak(low[0, :, 1, 1]))) < 0.01


def _only():
    only = torch.zeros(1, 4, 4, dtype=torch.bool)
    only[0, 1, 1] = True
    return only


def test_over_level_charges_a_false_surface_and_its_gradient_lowers_it():
    faint = _maps({(1, 1): (0.0, 0.02)})  # thinner than the series resolves: the truth stays under the level
    assert _peak(faint[0, :, 1, 1]) < 0.55
    false = _maps({(1, 1): (-0.04, 0.06)})  # the net decodes a 5 cm hand there
    v = over_level(false, faint, K, _only(), 512)
    assert abs(float(v) - (_peak(false[0, :, 1, 1]) - 0.55)) < 0.01 and float(v) > 0.2
    p = false.clone().requires_grad_(True)
    over_level(p, faint, K, _only(), 512).backward()
    stepped = (p - 0.02 * p.grad).detach()  # a small step: the gradient is a whole basis row
    assert _peak(stepped[0, :, 1, 1]) < _peak(false[0, :, 1, 1]) - 0.05


def test_over_level_is_zero_where_the_truth_crosses_the_level_however_high():
    target = _maps({(1, 1): (-0.05, 0.05)})
    sharper = _maps({(1, 1): (-0.03, 0.03)}) * 1.4  # higher, and over the level only inside the truth's interval
    p = sharper.clone().requires_grad_(True)
    v = over_level(p, target, K, _only(), 512)
    v.backward()
    assert v.item() == 0.0 and p.grad.abs().max().item() == 0.0
    assert float(over_level(target, target, K, _only(), 512)) < 1e-6
    # A ray the truth fills end to end leaves no depth to charge: 0, finite.
    full = _maps({(1, 1): (-1.0, 1.0)})
    p = (full * 1.5).requires_grad_(True)
    v = over_level(p, full, K, _only(), 64)
    v.backward()
    assert v.item() == 0.0 and torch.isfinite(p.grad).all()


def test_over_level_charges_a_thicker_part_outside_the_truths_interval():
    target = _maps({(1, 1): (-0.04, 0.04)})
    thick = _maps({(1, 1): (-0.12, 0.12)})  # three times as long in depth, same centre
    v = float(over_level(thick, target, K, _only(), 512))
    assert v > 0.3
    p = thick.clone().requires_grad_(True)
    over_level(p, target, K, _only(), 512).backward()
    stepped = (p - 0.02 * p.grad).detach()  # a small step: the gradient is a whole basis row
    z = torch.tensor([0.0, 0.1], dtype=torch.float64)  # the centre (inside the truth) and 5 cm off it (outside)
    before, after = FO.basis(z, K) @ thick[0, :, 1, 1].double(), FO.basis(z, K) @ stepped[0, :, 1, 1].double()
    assert after[1] < before[1] - 0.05  # lowered outside
    assert abs(float(after[0] - before[0])) < abs(float(after[1] - before[1]))  # the centre barely moves


def test_the_empty_band_holds_the_gap_between_two_legs_and_a_filled_gap_is_charged():
    # Two legs 4 map pixels apart in a 16 x 16 map: the gap and a band around them, not the
    # legs, not the far background.
    legs = {(r, c): (-0.1, 0.1) for r in range(4, 12) for c in list(range(3, 6)) + list(range(10, 13))}
    target = interval_maps(legs, K, size=16)
    band = empty_band(target, 2)[0, 0] > 0.5
    assert band[8, 7] and band[8, 8]  # the gap
    assert not band[8, 4] and not band[8, 11]  # the legs
    assert not band[0, 0] and not band[8, 15]  # farther than 2 pixels
    filled = target.clone()
    filled[0, :, 4:12, 6:10] = target[0, :, 8, 4:5].reshape(-1, 1, 1)  # a web across the gap
    only = band.unsqueeze(0)
    assert float(over_level(target, target, K, only, 256)) == 0.0
    v = float(over_level(filled, target, K, only, 256))
    assert v > 0.1  # the web's rays, a share of the band's


def test_bad_values_are_refused_by_name_before_any_data_are_read(tmp_path, capsys):
    import pytest

    from volcap_train.train import main

    # (the loss's weight given beside it, the option, a bad value, how the refusal names it)
    bad = [("--peak-weight", f, v) for f, v in (("--peak-weight", "-1"), ("--peak-window", "-0.1"), ("--peak-cap", "0"), ("--mask-aug", "1.5"))]
    bad += [("--over-weight", f, v) for f, v in (("--over-weight", "-0.1"), ("--over-level", "1.0"), ("--over-level", "0"))]
    bad += [("--empty-weight", "--empty-weight", "-1"), ("--empty-weight", "--empty-band", "0")]
    for weight, flag, value in bad:
        with pytest.raises(SystemExit):
            main(["fourier", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "run"), weight, "0.1", flag, value])
        shown = value if flag == "--empty-band" else float(value)
        assert f"{flag} {shown}" in capsys.readouterr().err
        assert not (tmp_path / "run").exists()
    # A window, cap or level without its loss would be silently ignored: refused instead.
    for flag, value, says in (("--peak-cap", "0.65", "give --peak-weight too"), ("--over-level", "0.5", "give --over-weight or --empty-weight too"), ("--empty-band", "2", "give --empty-weight too")):
        with pytest.raises(SystemExit):
            main(["fourier", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "run"), flag, value])
        assert says in capsys.readouterr().err
