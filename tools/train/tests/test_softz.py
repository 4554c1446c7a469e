"""SoftZ edge cases (the same rules as service/engine/src/softz.rs)."""

import pytest
import torch

from volcap_train.nets import SOFTZ_BINS, soft_z


def test_edges_and_sums():
    z = torch.tensor([-1.0, 1.0, 0.0, -5.0, 7.0, 1.0 - 1e-7, -1.0 + 1e-7])
    v = soft_z(z)
    assert torch.isfinite(v).all()
    assert torch.allclose(v.sum(-1), torch.ones(len(z)))
    assert v[0, 0] == 1.0 and v[1, SOFTZ_BINS - 1] == 1.0
    assert v[3, 0] == 1.0 and v[4, SOFTZ_BINS - 1] == 1.0  # clamped
    assert ((v > 0).sum(-1) <= 2).all()


def test_interpolates_between_two_bins():
    # z such that (N-1) * P'z = 10.25
    pz = 10.25 / (SOFTZ_BINS - 1)
    z = torch.tensor([2 * pz - 1], dtype=torch.float64)
    v = soft_z(z)[0]
    assert v[10].item() == pytest.approx(0.75)
    assert v[11].item() == pytest.approx(0.25)


def test_non_finite_refused():
    for bad in (float("nan"), float("inf"), -float("inf")):
        with pytest.raises(ValueError):
            soft_z(torch.tensor([bad]))
