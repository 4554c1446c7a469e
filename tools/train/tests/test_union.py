"""items.fourier_union: the training items of several datasets as one, built from each
dataset's own cache without two copies in memory."""
import pytest
import torch

from volcap_train.items import fourier_union

K = 3


def items(n, seed):
    g = torch.Generator().manual_seed(seed)
    return {
        "rgb": torch.randint(0, 255, (n, 3, 4, 4), dtype=torch.uint8, generator=g),
        "mask": torch.randint(0, 255, (n, 1, 4, 4), dtype=torch.uint8, generator=g),
        "coeff": torch.randn(n, 2 * K + 1, 2, 2, generator=g).half(),
        "points": torch.randn(n, 6, 3, generator=g),
        "occ": (torch.rand(n, 6, generator=g) > 0.5).float(),
        "keep": torch.arange(n) * 2,  # as if every other image of the split were kept
        "k": K,
    }


def cached(tmp_path, name, d):
    root = tmp_path / name
    root.mkdir()
    torch.save(d, root / f"fourier-train-k{K}-v2.pt")
    return root


def test_the_union_is_the_datasets_in_order(tmp_path):
    a, b = items(5, 0), items(3, 1)
    u = fourier_union([cached(tmp_path, "a", a), cached(tmp_path, "b", b)], "train", K)
    for name in ("rgb", "mask", "coeff", "points", "occ"):
        assert torch.equal(u[name], torch.cat([a[name], b[name]])), name
    # keep indexes the concatenated images: b's follow a's five
    assert u["keep"].tolist() == [0, 2, 4, 6, 8, 5, 7, 9]
    assert u["k"] == K


def test_one_dataset_is_its_own_cache(tmp_path):
    a = items(4, 2)
    u = fourier_union([cached(tmp_path, "a", a)], "train", K)
    assert all(torch.equal(u[n], a[n]) for n in ("rgb", "coeff", "keep"))


def test_datasets_of_different_shapes_are_refused_by_name(tmp_path):
    a, b = items(2, 0), items(2, 1)
    b["rgb"] = torch.zeros(2, 3, 8, 8, dtype=torch.uint8)
    with pytest.raises(ValueError, match="rgb"):
        fourier_union([cached(tmp_path, "a", a), cached(tmp_path, "b", b)], "train", K)
