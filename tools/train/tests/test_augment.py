"""The trainer's camera-effect augmentation (data.sensor): bounded, finite, seeded, real."""

import torch

from volcap_train.data import photometric, sensor
from volcap_train.train import data_on_device, items_bytes, perturb_mask


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


def test_photometric_is_seeded_bounded_and_pushes_some_frames_to_the_extremes():
    x = torch.full((400, 3, 4, 4), 0.5)
    a = photometric(x.clone(), torch.Generator().manual_seed(7))
    b = photometric(x.clone(), torch.Generator().manual_seed(7))
    assert torch.equal(a, b)
    assert torch.isfinite(a).all() and a.min() >= 0 and a.max() <= 1
    mean = a.mean((1, 2, 3))
    # Dark frames (x 0.15, p 0.05) fall under every other frame's lowest gain (0.6 x 0.5 - 0.05).
    dark = int((mean < 0.2).sum())
    assert 5 <= dark <= 40, dark


def test_perturbed_masks_grow_or_shrink_by_at_most_three_pixels_on_about_half_the_images():
    m = torch.zeros(200, 1, 32, 32)
    m[:, :, 10:22, 12:20] = 1.0
    out = perturb_mask(m, torch.Generator().manual_seed(4))
    assert torch.equal(out, perturb_mask(m, torch.Generator().manual_seed(4)))
    changed = (out != m).flatten(1).any(1)
    assert 70 <= int(changed.sum()) <= 130  # p = 0.5 of 200
    area = out.sum((1, 2, 3))
    grown, shrunk = area > m[0].sum(), area < m[0].sum()
    assert bool((grown | shrunk)[changed].all()) and int(grown.sum()) > 20 and int(shrunk.sum()) > 20
    # Dilated masks hold the original, eroded ones lie inside it; by at most 3 pixels.
    assert bool(((out[grown] >= m[grown]).all())) and bool((out[shrunk] <= m[shrunk]).all())
    assert float(out[grown].sum((1, 2, 3)).max()) <= (12 + 6) * (8 + 6)
    assert float(out[shrunk].sum((1, 2, 3)).min()) >= (12 - 6) * (8 - 6)


def test_items_stay_on_the_host_unless_a_gpu_trains():
    items = [{"rgb": torch.zeros(2, 3, 4, 4, dtype=torch.uint8), "k": 15}]
    assert items_bytes(items) == 96
    for choice in ("auto", "host", "device"):
        assert not data_on_device(choice, torch.device("cpu"), items)


def test_mask_aug_zero_leaves_the_masks_and_draws_as_many_numbers():
    # `train fourier --mask-aug 0`: no mask changed, and the generator left where p = 0.5 leaves
    # it, so the run draws the same batches, flips and photometric changes as its control.
    m = torch.zeros(50, 1, 32, 32)
    m[:, :, 10:22, 12:20] = 1.0
    g0, g5 = torch.Generator().manual_seed(7), torch.Generator().manual_seed(7)
    assert torch.equal(perturb_mask(m, g0, 0.0), m)
    perturb_mask(m, g5, 0.5)
    assert torch.equal(torch.rand(4, generator=g0), torch.rand(4, generator=g5))
    # Every image changed at p = 1.
    assert bool((perturb_mask(m, torch.Generator().manual_seed(7), 1.0) != m).flatten(1).any(1).all())
