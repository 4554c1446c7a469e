"""surfaces.py: the front and back surfaces found in a ray's series where the true intervals
put them, the geometry loss zero at the truth, blind to occlusion edges' cliffs and finite on
wild input, and a GeomHead on the series head's features that learns a subject's surfaces."""
import torch
from series_maps import interval_maps

from volcap_train import fourier as FO
from volcap_train.nets import FourierNet
from volcap_train.surfaces import GeomHead, geometry_loss, slopes, surface_depths

K = 15


def _maps(intervals, n=4):
    """[1, 2K+1, n, n] maps: each listed pixel holds its intervals (zeta), the rest empty."""
    return interval_maps(intervals, K, n)


def test_front_and_back_are_the_outer_ends_of_the_inside():
    # z toward the camera: the front is the largest zeta inside, the back the smallest.
    ivs = {(0, 0): [(-0.4, 0.3)], (1, 2): [(-0.7, -0.5), (0.1, 0.45)], (3, 3): [(0.6, 0.95)]}
    d, ins = surface_depths(_maps(ivs), K)
    assert d.shape == (1, 2, 4, 4) and ins.shape == (1, 1, 4, 4)
    for (y, x), iv in ivs.items():
        assert ins[0, 0, y, x]
        front, back = max(h for _, h in iv), min(lo for lo, _ in iv)
        # The truncated series crosses one half within a fraction of its shortest wavelength.
        assert abs(d[0, 0, y, x] - front) < 0.03, (y, x, d[0, :, y, x])
        assert abs(d[0, 1, y, x] - back) < 0.03, (y, x, d[0, :, y, x])
    # Every other ray is empty, with depths 0.
    assert int(ins.sum()) == len(ivs)
    assert d[0, :, 2, 1].abs().max() == 0


def test_the_loss_is_zero_at_the_truth_and_ignores_occlusion_cliffs():
    # A smooth surface, then a cliff of 1.0 zeta between columns 3 and 4 (a hand in front).
    h, w = 6, 8
    xs = torch.linspace(-1, 1, w)
    front = (0.2 * xs).expand(h, w).clone()
    front[:, 4:] += 1.0
    target = torch.stack([front, front - 0.5])[None]
    inside = torch.ones(1, 1, h, w, dtype=torch.bool)
    assert geometry_loss(target, target, inside) == 0
    # A constant offset costs its size in the depth term and nothing in the slopes.
    assert torch.isclose(geometry_loss(target + 0.1, target, inside), torch.tensor(0.1), atol=1e-6)
    # The far side of the cliff placed 0.05 off: its depths cost that (half the pixels), its
    # step over the cliff nothing (past the slope bound), unless the bound is lifted.
    tx, _ = slopes(target)
    assert tx.abs().max() > 3.0
    off = target.clone()
    off[..., 4:] += 0.05
    assert torch.isclose(geometry_loss(off, target, inside), torch.tensor(0.025), atol=1e-6)
    assert geometry_loss(off, target, inside, max_slope=1e9) > 0.025 + 0.01
    # Depths only (`--geom-slope-weight 0`): the step is free even without the bound.
    assert torch.isclose(geometry_loss(off, target, inside, max_slope=1e9, slope_weight=0.0), torch.tensor(0.025), atol=1e-6)
    # Only inside rays count: wrong depths outside are free.
    out = target.clone()
    out[..., 0] = 7.0
    part = inside.clone()
    part[..., 0] = False
    assert geometry_loss(out, target, part) == 0
    # Wild predictions stay finite; nothing inside gives 0.
    wild = torch.full_like(target, 1e30)
    assert torch.isfinite(geometry_loss(wild, target, inside))
    assert geometry_loss(wild, target, torch.zeros_like(inside)) == 0


def test_a_geom_head_on_the_series_features_learns_one_subjects_surfaces():
    torch.manual_seed(0)
    net = FourierNet(K, 4)
    head = GeomHead(8)
    x = torch.rand(1, 4, 256, 256)
    # The target: a tilted slab over the middle of the 128-px maps.
    ivs = {(y, x): [(-0.3 + 0.002 * x, 0.2 + 0.003 * y)] for y in range(40, 88, 4) for x in range(40, 88, 4)}
    target, ins = surface_depths(_maps(ivs, 128), K)
    assert int(ins.sum()) == len(ivs)
    opt = torch.optim.Adam([*net.parameters(), *head.parameters()], lr=3e-3)
    first = None
    for _ in range(60):
        loss = geometry_loss(head(net.features(x)), target, ins)
        first = loss.item() if first is None else first
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < 0.3 * first, (first, loss.item())
    # The series head's output is the network's as before (features, then head).
    with torch.no_grad():
        assert torch.equal(net(x), net.head(net.features(x)))


def _trained_bn(net, seed):
    """Non-trivial batch-norm statistics (three training-mode batches), then eval mode."""
    torch.manual_seed(seed)
    net.train()
    with torch.no_grad():
        for _ in range(3):
            net(torch.randn(2, 4, 256, 256))
    return net.eval()


def test_the_surface_variant_starts_as_the_small_net_and_exports_like_it(tmp_path):
    import numpy as np
    import onnxruntime as ort

    from volcap_train.export import export
    from volcap_train.nets import FourierGeomNet, make_fourier

    small = _trained_bn(FourierNet(7, 4), 3)
    pair = FourierGeomNet(7, 4, 4)
    pair.from_small(small.state_dict())
    pair.eval()
    x = torch.randn(1, 4, 256, 256)
    x[:, 3] = (x[:, 3] > 0).float()  # a mask channel
    with torch.no_grad():
        # The series net reads the surfaces through zero weights: the small net's series.
        assert torch.allclose(pair(x), small(x), atol=1e-5)
        # The surface net is the small net's trunk.
        assert torch.equal(pair.geom.features(x), small.features(x))
    # Its surfaces do reach the series once the new weights move.
    with torch.no_grad():
        pair.series.e0[0].weight[:, 4:] += 0.5
        ref = pair(x)
    assert not torch.allclose(ref, small(x), atol=1e-3)
    # The ONNX file has the Fourier head's input and output (the engine loads it as one).
    export(pair, (x,), ["image"], ["coeff"], tmp_path / "g.onnx", {"kind": "shape-fourier"}, False)
    out = ort.InferenceSession(str(tmp_path / "g.onnx")).run(None, {"image": x.numpy()})[0]
    assert out.shape == (1, 15, 128, 128)
    np.testing.assert_allclose(out, ref.numpy(), rtol=1e-4, atol=1e-4)
    assert isinstance(make_fourier("fourier-geom"), FourierGeomNet)
    assert type(make_fourier("fourier-small")) is FourierNet
