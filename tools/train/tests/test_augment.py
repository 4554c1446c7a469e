"""The trainer's camera-effect augmentation (data.sensor): bounded, finite, seeded, real."""

import torch

from volcap_train.data import sensor


def test_sensor_effects_stay_in_range_and_are_reproducible():
    x = torch.rand(32, 3, 48, 48, generator=torch.Generator().manual_seed(0))
    a = sensor(x.clone(), torch.Generator().manual_seed(5))
    b = sensor(x.clone(), torch.Generator().manual_seed(5))
    assert a.shape == x.shape
    assert torch.isfinite(a).all() and a.min() >= 0 and a.max() <= 1
    assert torch.equal(a, b)
    # Every image changes (white balance, gamma and noise apply to all of them).
    assert ((a - x).abs().mean((1, 2, 3)) > 1e-3).all()


def test_extreme_frames_stay_finite():
    # Black and saturated frames: gamma of 0 and of 1 must not give NaN or Inf.
    for v in (0.0, 1.0):
        y = sensor(torch.full((8, 3, 16, 16), v), torch.Generator().manual_seed(1))
        assert torch.isfinite(y).all() and y.min() >= 0 and y.max() <= 1


def test_some_frames_are_greyscale():
    x = torch.rand(200, 3, 8, 8, generator=torch.Generator().manual_seed(2))
    y = sensor(x, torch.Generator().manual_seed(3))
    grey = ((y[:, 0] - y[:, 1]).abs().amax((1, 2)) == 0) & ((y[:, 1] - y[:, 2]).abs().amax((1, 2)) == 0)
    assert 5 <= int(grey.sum()) <= 40  # p = 0.1 of 200
