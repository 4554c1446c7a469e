"""OHEM: weights and normalization stay finite and correct at the extremes (METHOD.md)."""

import math

import pytest
import torch

from volcap_train import ohem
from volcap_train.ohem import OhemState, log_item_weight, log_point_weight, normalize

BCES = [0.0, 1e-30, 1.0, 50.0, 1e4]


def test_point_weight_is_exp_loss_over_alpha_in_log_domain():
    lw = log_point_weight(torch.tensor(BCES, dtype=torch.float64))
    for l, w in zip(BCES, lw.tolist()):
        assert math.isfinite(w)
        assert w == pytest.approx(l / ohem.ALPHA_P, rel=1e-12, abs=1e-300)


def test_point_weight_with_beta_matches_f64_reference():
    for beta in (0.5, 1.0):
        lw = log_point_weight(torch.tensor(BCES, dtype=torch.float64), beta=beta)
        for l, w in zip(BCES, lw.tolist()):
            ref = -math.log(math.exp(-l / ohem.ALPHA_P) + beta)
            assert w == pytest.approx(ref, rel=1e-12, abs=1e-12)


def test_extreme_losses_never_overflow_float32():
    # exp(1e4 / 0.7) is far beyond float32 (and float64); the log-domain path never forms it.
    assert math.isinf(torch.exp(torch.tensor(1e4 / 0.7, dtype=torch.float32)).item())
    p = normalize(log_point_weight(torch.tensor(BCES)))
    assert torch.isfinite(p).all()
    assert p.sum().item() == pytest.approx(1.0, abs=1e-12)
    # The confidently wrong point takes (essentially) all the mass.
    assert p[-1].item() == pytest.approx(1.0, abs=1e-12)
    assert (p >= 0).all()
    # As float32 too.
    p32 = p.to(torch.float32)
    assert torch.isfinite(p32).all()


def test_infinite_loss_is_clamped_and_nan_refused():
    lw = log_point_weight(torch.tensor([float("inf"), 1.0]))
    assert torch.isfinite(lw).all()
    with pytest.raises(ValueError):
        log_point_weight(torch.tensor([float("nan")]))
    with pytest.raises(ValueError):
        log_point_weight(torch.tensor([-1.0]))


@pytest.mark.parametrize("iou", [0.0, 1.0])
def test_item_weight_at_iou_edges(iou):
    lw = log_item_weight(torch.tensor([iou], dtype=torch.float64))
    assert lw.item() == pytest.approx(-iou / 0.15 + 10.0)
    assert math.isfinite(math.exp(lw.item()))  # exp(10) itself is representable


def test_item_weights_favour_low_iou_with_the_papers_ratio():
    p = normalize(log_item_weight(torch.tensor([0.0, 1.0], dtype=torch.float64)))
    assert p[0] / p[1] == pytest.approx(math.exp(1.0 / 0.15), rel=1e-9)


def test_all_equal_losses_and_single_item_are_uniform():
    p = normalize(log_point_weight(torch.full((7,), 3.0)))
    assert torch.allclose(p, torch.full((7,), 1 / 7, dtype=torch.float64))
    p = normalize(log_item_weight(torch.tensor([0.4])))
    assert p.tolist() == [1.0]
    with pytest.raises(ValueError):
        normalize(torch.tensor([]))
    with pytest.raises(ValueError):
        normalize(torch.tensor([0.0, float("inf")]))


def test_sampling_frequencies_match_probabilities():
    # Chi-square goodness of fit with a fixed seed; 5 bins with known probabilities.
    losses = torch.tensor([0.1, 0.5, 1.0, 1.5, 2.0], dtype=torch.float64)
    p = normalize(log_point_weight(losses))
    st = OhemState(1, 5, "P")
    st.log_point[0] = log_point_weight(losses)
    g = torch.Generator().manual_seed(0)
    n = 200_000
    idx = st.sample_points(torch.tensor([0]), n, g)[0]
    counts = torch.bincount(idx, minlength=5).to(torch.float64)
    expected = p * n
    chi2 = (((counts - expected) ** 2) / expected).sum().item()
    # 4 degrees of freedom: P(chi2 > 18.47) = 0.001.
    assert chi2 < 18.47, (counts, expected)


def test_item_sampling_follows_iou_and_modes():
    st = OhemState(3, 4, "P+I")
    st.log_item = log_item_weight(torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64))
    g = torch.Generator().manual_seed(1)
    items = st.sample_items(30_000, g)
    freq = torch.bincount(items, minlength=3).to(torch.float64) / 30_000
    p = normalize(st.log_item)
    assert torch.allclose(freq, p, atol=0.01)
    st.mode = "P"
    items = st.sample_items(30_000, g)
    freq = torch.bincount(items, minlength=3).to(torch.float64) / 30_000
    assert torch.allclose(freq, torch.full((3,), 1 / 3, dtype=torch.float64), atol=0.01)
    with pytest.raises(ValueError):
        OhemState(1, 1, "bogus")


def test_update_stores_losses_and_iou():
    st = OhemState(2, 4, "P+I")
    items = torch.tensor([1])
    pts = torch.tensor([[0, 3]])
    bce = torch.tensor([[50.0, 0.0]])
    pred = torch.tensor([[0.9, 0.1]])
    lab = torch.tensor([[1.0, 0.0]])
    st.update(items, pts, bce, pred, lab)
    assert st.log_point[1, 0].item() == pytest.approx(50 / 0.7)
    assert st.log_point[1, 3].item() == 0.0
    assert st.log_item[1].item() == pytest.approx(-1.0 / 0.15 + 10)  # IoU 1
    assert torch.isfinite(normalize(st.log_point[1])).all()
