"""The Fourier occupancy field: closed-form coefficients against numerical projection, the
series against the indicator, Parseval, the crop scaling of ray intervals, and the network's
output on hard inputs."""

import math

import torch

from volcap_train import fourier as FO
from volcap_train.nets import FourierNet


def indicator(z, intervals):
    out = torch.zeros_like(z)
    for lo, hi in intervals:
        out = torch.where((z >= lo) & (z <= hi), torch.ones_like(z), out)
    return out


def test_closed_form_equals_numerical_projection():
    iv = [(-0.7, -0.35), (-0.1, 0.42)]
    k = 15
    c = FO.interval_coeffs(torch.tensor([a for a, _ in iv], dtype=torch.float64), torch.tensor([b for _, b in iv], dtype=torch.float64), k).sum(0)
    z = torch.linspace(-1, 1, 400001, dtype=torch.float64)
    f = indicator(z, iv)
    dz = z[1] - z[0]
    num = [0.5 * torch.trapz(f, dx=dz)]
    for n in range(1, k + 1):
        num.append(torch.trapz(f * torch.cos(n * math.pi * z), dx=dz))
        num.append(torch.trapz(f * torch.sin(n * math.pi * z), dx=dz))
    assert torch.allclose(c, torch.stack(num), atol=2e-5)


def test_series_converges_to_the_indicator_and_parseval_holds():
    iv = [(-0.5, 0.3)]
    lo, hi = torch.tensor([-0.5], dtype=torch.float64), torch.tensor([0.3], dtype=torch.float64)
    z = torch.linspace(-1, 1, 20001, dtype=torch.float64)
    f = indicator(z, iv)
    errs = []
    for k in (7, 15, 31, 63):
        c = FO.interval_coeffs(lo, hi, k).sum(0)
        g = FO.decode(c.expand(len(z), -1), z, k)
        errs.append(torch.trapz((f - g) ** 2, z).item())
        # Parseval: the L2 error of a truncation equals the energy of the dropped terms.
        c_hi = FO.interval_coeffs(lo, hi, 400).sum(0)
        tail = (c_hi[FO.channels(k) :] ** 2).sum().item()
        assert abs(errs[-1] - tail) < 2e-3, (k, errs[-1], tail)
        # Crossing 0.5 at the edges of a wide interval.
        at = FO.decode(c[None].expand(2, -1), torch.tensor([-0.5, 0.3], dtype=torch.float64), k)
        assert (at - 0.5).abs().max() < 0.05
    assert errs == sorted(errs, reverse=True), errs
    # zeta outside [-1, 1]: zero occupancy.
    c = FO.interval_coeffs(torch.tensor([-1.0]), torch.tensor([1.0]), 7)
    assert FO.decode(c.expand(3, -1), torch.tensor([1.5, -3.0, 1.0]), 7).tolist()[:2] == [0.0, 0.0]


def test_parseval_l2_is_the_ray_integral():
    torch.manual_seed(0)
    a, b = torch.randn(1, 31, 1, 1, dtype=torch.float64), torch.randn(1, 31, 1, 1, dtype=torch.float64)
    z = torch.linspace(-1, 1, 200001, dtype=torch.float64)
    fa = FO.decode(a[0, :, 0, 0].expand(len(z), -1), z, 15)
    fb = FO.decode(b[0, :, 0, 0].expand(len(z), -1), z, 15)
    integral = torch.trapz((fa - fb) ** 2, z)
    assert torch.allclose(FO.parseval_l2(a, b, dim=1)[0, 0, 0], integral, rtol=1e-4)


def test_ray_maps_scale_depth_by_the_crop():
    # One pixel of a 2x2 image with the interval [-0.1, 0.2] in input NDC.
    offsets = torch.tensor([0, 1, 1, 1, 1])
    z = torch.tensor([[-0.1, 0.2]])
    for s in (0.5, 1.0):
        m = FO.ray_coeff_maps(offsets, z, 2, s, 7)
        assert m.shape == (15, 2, 2)
        assert torch.allclose(m[0, 0, 0], torch.tensor(0.5 * 0.3 / s * FO.ZETA_SCALE))
        assert m[:, 0, 1].abs().max() == 0
    # Intervals beyond the depth range are clipped, never NaN.
    m = FO.ray_coeff_maps(offsets, torch.tensor([[-5.0, 5.0]]), 2, 0.125, 7)
    assert torch.isfinite(m).all() and abs(m[0, 0, 0].item() - 1.0) < 1e-6


def test_network_output_is_finite_on_hard_inputs():
    torch.manual_seed(0)
    net = FourierNet(k=7, c=4).eval()
    s = 256
    black = torch.zeros(1, 4, s, s)
    white = torch.cat([torch.ones(1, 3, s, s), torch.ones(1, 1, s, s)], 1)
    noise = torch.cat([torch.rand(1, 3, s, s) * 2 - 1, (torch.rand(1, 1, s, s) > 0.5).float()], 1)
    tiny = black.clone()
    tiny[:, :, 120:124, 126:128] = 1.0
    with torch.no_grad():
        for x in (black, white, noise, tiny):
            out = net(x)
            assert out.shape == (1, 15, 128, 128)
            assert torch.isfinite(out).all()
            occ = FO.decode(out[0, :, 64, 64].expand(5, -1), torch.tensor([-1.0, -0.5, 0.0, 0.5, 1.0]), 7)
            assert torch.isfinite(occ).all()


def test_a_shifted_series_is_the_profile_moved_in_depth():
    from volcap_train.nets import shift_series

    torch.manual_seed(3)
    k = 7
    rel = torch.randn(1, 2 * k + 1, 2, 3)
    d = torch.rand(1, 1, 2, 3) * 1.6 - 0.8
    out = shift_series(rel, d, k)
    z = torch.linspace(-1.0, 1.0, 41)
    for i in range(2):
        for j in range(3):
            zz = z - d[0, 0, i, j]
            # g is periodic (period 2): evaluate the profile at the wrapped depth.
            wrapped = torch.remainder(zz + 1.0, 2.0) - 1.0
            want = FO.decode(rel[0, :, i, j].expand(len(z), -1), wrapped, k)
            got = FO.decode(out[0, :, i, j].expand(len(z), -1), z, k)
            assert torch.allclose(got, want, atol=1e-5)


def test_centroid_of_a_box_is_its_centre():
    k = 15
    lo, hi = torch.tensor([-0.3, 0.1, -0.9]), torch.tensor([0.1, 0.5, -0.5])
    c = FO.interval_coeffs(lo.double(), hi.double(), k)
    d, ok = FO.centroid(c, k, dim=-1)
    assert ok.all()
    # Truncation at K = 15 moves the centre by well under a tenth of the box.
    assert torch.allclose(d, (lo + hi).double() / 2, atol=0.02), d
    empty, ok = FO.centroid(torch.zeros(1, 2 * k + 1), k, dim=-1)
    assert not ok.any() and empty.item() == 0.0


def test_first_moment_converges_to_the_box_integral():
    # int z 1[lo, hi] dz = (hi^2 - lo^2) / 2; the series' moment converges to it as K grows.
    lo, hi = torch.tensor([-0.3, 0.1, -0.9]).double(), torch.tensor([0.1, 0.5, -0.5]).double()
    want = (hi**2 - lo**2) / 2
    errs = []
    for k in (15, 255):
        got = FO.first_moment(FO.interval_coeffs(lo, hi, k), k, dim=-1)
        errs.append((got - want).abs().max().item())
    assert errs[1] < 2e-3 and errs[1] < errs[0], errs
    # A box symmetric about z = 0 has no first moment at any order.
    sym = FO.interval_coeffs(torch.tensor([-0.4]).double(), torch.tensor([0.4]).double(), 15)
    assert FO.first_moment(sym, 15, dim=-1).abs().item() < 1e-12


def test_centring_moves_each_image_to_zero_mean_depth_and_keeps_the_labels():
    # Two images of 2x3 rays: boxes at different depths (image 0 mostly in front, image 1
    # behind, one empty ray), K = 31 so the series is close to the boxes.
    k = 31
    lo = torch.tensor([[[0.1, 0.2, 0.0], [0.3, -0.1, 0.15]], [[-0.6, -0.5, -0.4], [-0.55, 0.0, -0.45]]])
    hi = lo + torch.tensor([[[0.3, 0.2, 0.0], [0.25, 0.4, 0.2]], [[0.3, 0.25, 0.2], [0.35, 0.0, 0.3]]])
    coeff = FO.interval_coeffs(lo, hi, k).permute(0, 3, 1, 2).contiguous()
    # The exact mean depth of each image: sum of (hi^2 - lo^2) / 2 over sum of (hi - lo).
    want = ((hi**2 - lo**2) / 2).sum((1, 2)) / (hi - lo).sum((1, 2))
    got = FO.body_depth_centre(coeff, k)
    assert torch.allclose(got, want, atol=1e-3), (got, want)
    # Points (crop NDC: zeta = 2 z) at ray (0, 0) of each image, labelled by the original boxes.
    zeta = torch.linspace(-0.9, 0.9, 37)
    pts = torch.zeros(2, len(zeta), 3)
    pts[..., 2] = zeta / FO.ZETA_SCALE
    before = torch.stack([FO.decode(coeff[b, :, 0, 0].expand(len(zeta), -1), zeta, k) for b in range(2)])
    moved = coeff.clone()
    shifts = FO.centre_depth(moved, pts, k)
    assert torch.allclose(shifts, got)
    assert FO.body_depth_centre(moved, k).abs().max() < 1e-3  # the truncated series wraps a little
    after = torch.stack([FO.decode(moved[b, :, 0, 0].expand(len(zeta), -1), pts[b, :, 2] * FO.ZETA_SCALE, k) for b in range(2)])
    # The same occupancy at the moved points (away from the period's wrap at |zeta| = 1).
    keep = (pts[..., 2] * FO.ZETA_SCALE).abs() < 0.95
    assert (after - before)[keep].abs().max() < 1e-4
    assert torch.isfinite(moved).all()
