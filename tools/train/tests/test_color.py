"""Colour training's targets: the seen surface at the input's exposure."""

import json

import pytest
import torch

from volcap_train.train import exposure_targets, seen_surface_dataset


def test_targets_take_the_inputs_exposure_and_tint_per_channel():
    s, m = 32, 200
    gen = torch.Generator().manual_seed(0)
    # Input pixels: the front's albedo (0.6, 0.4, 0.8) seen at gains (0.5, 1.0, 0.25).
    albedo_front = torch.tensor([0.6, 0.4, 0.8])
    gain = torch.tensor([0.5, 1.0, 0.25])
    rgb = (albedo_front * gain)[:, None, None].expand(3, s, s)
    x = torch.cat([rgb * 2 - 1, torch.ones(1, s, s)])[None]
    surf = torch.rand(1, m, 3, generator=gen) * 1.6 - 0.8
    albedo = torch.empty(1, m, 3)
    albedo[:, 0::2] = albedo_front
    # The back (odd samples) in another colour: its target is its albedo at the same gains.
    back = torch.tensor([0.9, 0.2, 1.0])
    albedo[:, 1::2] = back
    t = exposure_targets(x, surf, albedo)
    assert torch.allclose(t[0, 0::2], albedo_front * gain, atol=1e-4)
    assert torch.allclose(t[0, 1::2], back * gain, atol=1e-4)
    # Brighter than white is white; a black input (gain clamped) stays finite and in [0, 1].
    t2 = exposure_targets(x * 0 + 1, surf, albedo * 0.05)
    assert torch.isfinite(t2).all() and t2.min() >= 0 and t2.max() <= 1
    t3 = exposure_targets(torch.cat([-torch.ones(1, 3, s, s), torch.ones(1, 1, s, s)], 1), surf, torch.zeros_like(albedo))
    assert torch.isfinite(t3).all() and (t3 == 0).all()


def test_a_dataset_without_the_seen_surface_is_refused_by_name(tmp_path):
    (tmp_path / "dataset.json").write_text(json.dumps({"format": "volcap-sim-dataset/1"}))
    with pytest.raises(SystemExit, match="dataset.json"):
        seen_surface_dataset(tmp_path)
    (tmp_path / "dataset.json").write_text(json.dumps({"format": "volcap-sim-dataset/1", "surface": "seen"}))
    seen_surface_dataset(tmp_path)
