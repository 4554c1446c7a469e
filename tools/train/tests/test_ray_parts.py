"""point_iou.ray_parts: the split of a volumetric IoU into silhouette, placement and the
surfaces along rays finds each kind of error where it was put."""
import pytest
import torch

from volcap_train import fourier as FO
from volcap_train.nets import shift_series
from volcap_train.point_iou import ray_parts

K = 15


def maps(lo, hi):
    """Coefficient maps [B, 2K+1, H, W] of one interval per pixel (lo > hi: empty)."""
    c = FO.interval_coeffs(lo.clamp(-1, 1), hi.clamp(-1, 1), K) * (hi > lo).unsqueeze(-1)
    return c.permute(0, 3, 1, 2).contiguous()


@pytest.fixture
def intervals():
    g = torch.Generator().manual_seed(0)
    centre = torch.rand(2, 8, 8, generator=g) * 0.4 - 0.2
    half = torch.rand(2, 8, 8, generator=g) * 0.25 + 0.15
    half[:, :2] = -1.0  # two empty rows: background
    return centre - half, centre + half


def test_a_perfect_prediction_scores_one_everywhere(intervals):
    t = maps(*intervals)
    r = ray_parts(t, t, K)
    for key in ("iou", "best_iou", "sil_iou", "ray_iou"):
        assert torch.allclose(r[key], torch.ones(2)), key
    assert torch.equal(r["best_shift"], torch.zeros(2))
    assert torch.allclose(r["thick_pred"], r["thick_true"])


def test_a_depth_shift_is_found_and_undone(intervals):
    t = maps(*intervals)
    p = shift_series(t, torch.full((2, 1, 1, 1), 0.1), K)  # the prediction 0.1 zeta too far
    r = ray_parts(p, t, K)
    assert (r["iou"] < 0.85).all()
    assert torch.allclose(r["best_shift"], torch.full((2,), -0.1), atol=0.011)
    assert (r["best_iou"] > 0.97).all()
    assert torch.allclose(r["sil_iou"], torch.ones(2))


def test_a_lost_silhouette_is_not_blamed_on_the_rays(intervals):
    lo, hi = intervals
    t = maps(lo, hi)
    p = t.clone()
    p[:, :, :, :3] = 0  # three columns missing
    r = ray_parts(p, t, K)
    assert (r["sil_iou"] < 0.7).all()
    assert torch.allclose(r["ray_iou"], torch.ones(2))


def test_thick_rays_show_as_thickness_inside_a_right_silhouette(intervals):
    lo, hi = intervals
    t = maps(lo, hi)
    p = maps(lo - 0.1, hi + 0.1)
    r = ray_parts(p, t, K)
    assert torch.allclose(r["sil_iou"], torch.ones(2))
    assert (r["thick_pred"] > r["thick_true"] + 4).all()  # 0.2 zeta = 6.4 bins of 64
    assert (r["ray_iou"] < 0.8).all()
    # Moving it along depth buys (almost) nothing: the error is the surfaces, not the place.
    assert (r["best_iou"] - r["iou"] < 0.02).all()


def test_a_wrong_hidden_surface_is_told_from_a_wrong_visible_one(intervals):
    lo, hi = intervals
    t = maps(lo, hi)
    # The back (far, low zeta) surface 0.1 zeta (3.2 bins) farther; the front exact.
    r = ray_parts(maps(lo - 0.1, hi), t, K)
    assert (r["front_err"] < 0.6).all()
    assert (r["back_err"] > 2.5).all() and (r["back_bias"] < -2.5).all()
    # The front (near) surface 0.1 zeta nearer the camera; the back exact.
    r = ray_parts(maps(lo, hi + 0.1), t, K)
    assert (r["back_err"] < 0.6).all()
    assert (r["front_err"] > 2.5).all() and (r["front_bias"] > 2.5).all()
    assert (r["gross"] == 0).all()  # 3.2 bins is surface error, not a limb out of place


def test_limbs_out_of_place_count_as_gross(intervals):
    lo, hi = intervals
    t = maps(lo, hi)
    lo2, hi2 = lo.clone(), hi.clone()
    lo2[:, 2:4], hi2[:, 2:4] = lo[:, 2:4] + 0.5, hi[:, 2:4] + 0.5  # two rows 16 bins nearer
    r = ray_parts(maps(lo2, hi2), t, K)
    # those rows' rays, of the six body rows, and no other
    assert torch.allclose(r["gross"], torch.full((2,), 2 / 6), atol=0.02)
