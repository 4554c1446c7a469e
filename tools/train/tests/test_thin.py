"""thin_mask: the thin-part weighting of `train fourier --thin-weight` finds what is narrow
(a finger-wide bar) and leaves what is wide (a torso-wide block) and the background alone."""
import torch

from volcap_train.ray_losses import thin_mask


def test_thin_mask_marks_narrow_parts_only():
    c = torch.zeros(1, 31, 64, 64)
    c[0, 0, 10:50, 10:40] = 0.3  # a wide block: kept by the opening
    c[0, 0, 20:24, 45:60] = 0.1  # a bar 4 px thick: removed by an opening of radius 2
    t = thin_mask(c, 2)
    assert t.shape == (1, 1, 64, 64)
    assert t[0, 0, 20:24, 45:60].min() == 1.0
    assert t[0, 0, 15:45, 15:35].max() == 0.0  # the block's inside
    assert t[0, 0, :8].max() == 0.0 and t[0, 0, 55:].max() == 0.0  # background
    assert set(t.unique().tolist()) <= {0.0, 1.0}


def test_a_larger_radius_calls_more_thin():
    c = torch.zeros(1, 31, 64, 64)
    c[0, 0, 20:28, 10:50] = 0.2  # 8 px thick
    assert thin_mask(c, 2).sum() == 0
    assert thin_mask(c, 5).sum() == 8 * 40
