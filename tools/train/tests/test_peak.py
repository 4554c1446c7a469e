"""peak_hinge (`train fourier --peak-weight`): a thin ray's blurred, low series is charged by how
far its peak stays under the truth's, wherever its depth; a ray at or above the truth's height
costs nothing; only the selected rays count; wild or empty maps stay finite."""
import torch
from series_maps import interval_maps

from volcap_train import fourier as FO
from volcap_train.ray_losses import peak_hinge, thin_mask

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


def test_bad_values_are_refused_by_name_before_any_data_are_read(tmp_path, capsys):
    import pytest

    from volcap_train.train import main

    for flag, value in (("--peak-weight", "-1"), ("--peak-window", "-0.1"), ("--peak-cap", "0"), ("--mask-aug", "1.5")):
        with pytest.raises(SystemExit):
            main(["fourier", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "run"), "--peak-weight", "0.1", flag, value])
        assert f"{flag} {float(value)}" in capsys.readouterr().err
        assert not (tmp_path / "run").exists()
    # A window or cap without the hinge would be silently ignored: refused instead.
    with pytest.raises(SystemExit):
        main(["fourier", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "run"), "--peak-cap", "0.65"])
    assert "give --peak-weight too" in capsys.readouterr().err
