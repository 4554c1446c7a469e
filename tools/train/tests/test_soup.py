"""soup: the weighted mean of fine-tuned runs' weights, written as a light checkpoint."""
import pytest
import torch

from volcap_train import soup
from volcap_train.nets import FourierNet, fourier_variant


def sd(seed, shape=(3, 2)):
    g = torch.Generator().manual_seed(seed)
    return {"w": torch.randn(*shape, generator=g), "b": torch.randn(shape[0], generator=g)}


def test_uniform_mean_matches_an_f64_reference():
    a, b, c = sd(0), sd(1), sd(2)
    out = soup.average([a, b, c], [1, 1, 1], ["a", "b", "c"])
    for t in a:
        ref = (a[t].double() + b[t].double() + c[t].double()) / 3
        assert out[t].dtype == torch.float32
        assert torch.allclose(out[t].double(), ref, atol=1e-6), t


def test_weights_are_normalised_and_a_zero_weight_drops_an_input():
    a, b = sd(0), sd(1)
    out = soup.average([a, b], [3, 1], ["a", "b"])
    assert torch.allclose(out["w"], 0.75 * a["w"] + 0.25 * b["w"], atol=1e-6)
    only_a = soup.average([a, b], [1, 0], ["a", "b"])
    assert torch.equal(only_a["w"], a["w"])


def test_mismatched_inputs_are_refused_by_name():
    with pytest.raises(SystemExit, match="other.pt: tensor w has shape"):
        soup.average([sd(0), sd(1, (4, 2))], [1, 1], ["first.pt", "other.pt"])
    with pytest.raises(SystemExit, match="other tensors"):
        soup.average([sd(0), {"w": sd(1)["w"]}], [1, 1], ["first.pt", "other.pt"])
    with pytest.raises(SystemExit, match="--weights"):
        soup.average([sd(0), sd(1)], [1, -1], ["a", "b"])
    with pytest.raises(SystemExit, match="at least two"):
        soup.average([sd(0)], [1], ["a"])


def test_soup_of_real_checkpoints_loads_into_the_network(tmp_path):
    k, width, shift = fourier_variant("fourier-small")
    torch.manual_seed(0)
    n1, n2 = FourierNet(k, width, shift), FourierNet(k, width, shift)
    torch.save({"net": n1.state_dict(), "step": 5, "variant": "fourier-small"}, tmp_path / "a.pt")
    (tmp_path / "run").mkdir()  # a run folder holding a full checkpoint
    torch.save({"modules": {"net": n2.state_dict()}, "opt": {}, "step": 7}, tmp_path / "run" / "ckpt.pt")
    soup.main([str(tmp_path / "s.pt"), str(tmp_path / "a.pt"), str(tmp_path / "run"), "--variant", "fourier-small"])
    st = torch.load(tmp_path / "s.pt", weights_only=False)
    assert st["variant"] == "fourier-small"
    net = FourierNet(k, width, shift)
    net.load_state_dict(st["net"])  # every tensor present, every shape right
    p1, p2 = dict(n1.named_parameters()), dict(n2.named_parameters())
    for name, p in net.named_parameters():
        assert torch.allclose(p, (p1[name] + p2[name]) / 2, atol=1e-6), name


def test_bn_recomputed_on_a_datasets_items_is_the_soups_own(tmp_path):
    """--bn-data: the statistics are the soup's on the drawn images (its first BatchNorm's
    running mean equals the mean, in f64, of that layer's inputs over the images), whatever
    the averaged statistics were, and a missing cache is named."""
    from volcap_train.items import fourier_cache_path
    from volcap_train.nets import make_fourier

    seg = tmp_path / "seg.onnx"
    seg.write_bytes(b"a segmenter")  # the cache's name carries the file's hash
    g = torch.Generator().manual_seed(3)
    items = {"rgb": torch.randint(0, 256, (20, 3, 64, 64), generator=g, dtype=torch.uint8), "mask": torch.randint(0, 256, (20, 1, 64, 64), generator=g, dtype=torch.uint8)}
    torch.save(items, fourier_cache_path(tmp_path, "train", 15, seg, 2))
    torch.manual_seed(0)
    net = make_fourier("fourier-small")
    weights = {n: v.float() for n, v in net.state_dict().items()}
    bns = [n for n, m in net.named_modules() if isinstance(m, torch.nn.BatchNorm2d)]
    assert bns
    weights[bns[0] + ".running_mean"] += 100.0  # averaged statistics far off
    out, layers, seen = soup.with_bn_recomputed(weights, "fourier-small", soup.bn_batches(tmp_path, "fourier-small", seg, 2, 16, 1, batch=4))
    assert layers == len(bns) and seen == 16
    # reference: the first BatchNorm's inputs on the same 16 images, the soup's weights
    net.load_state_dict(out)
    net.eval()
    first = dict(net.named_modules())[bns[0]]
    got = []
    h = first.register_forward_hook(lambda m, i, o: got.append(i[0].double()))
    with torch.no_grad():
        for b in soup.bn_batches(tmp_path, "fourier-small", seg, 2, 16, 1, batch=4):
            net(b)
    h.remove()
    ref = torch.cat(got).mean((0, 2, 3))
    assert torch.allclose(out[bns[0] + ".running_mean"].double(), ref, rtol=1e-4, atol=1e-5)
    with pytest.raises(SystemExit, match="no cached training items"):
        list(soup.bn_batches(tmp_path / "none", "fourier-small", seg, 2, 16, 1))
