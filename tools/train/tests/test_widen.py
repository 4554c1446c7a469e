"""volcap_train.widen: a widened Fourier head computes what the narrow one did (eval and
train mode, batch-norm statistics that are not the defaults), then trains like any net."""
import pytest
import torch

from volcap_train.nets import FourierNet
from volcap_train.widen import main, widen


def narrow_net():
    torch.manual_seed(0)
    net = FourierNet(15, 8)
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-1, 1)
            m.running_var.uniform_(0.5, 2)
            m.weight.data.uniform_(0.5, 1.5)
            m.bias.data.uniform_(-0.5, 0.5)
    return net


@pytest.mark.parametrize("c", [12, 16])  # fourier-medium, fourier-wide
def test_widened_net_computes_the_narrow_ones_function(c):
    a = narrow_net()
    b = widen(a, FourierNet(15, c), 8, c)
    assert sum(p.numel() for p in b.parameters()) > 2 * sum(p.numel() for p in a.parameters())
    x = torch.randn(2, 4, 256, 256)
    for mode in ("eval", "train"):
        a.train(mode == "train")
        b.train(mode == "train")
        with torch.no_grad():
            ya, yb = a(x), b(x)
        assert ya.abs().max() > 0.1
        assert torch.allclose(ya, yb, atol=1e-5), (mode, (ya - yb).abs().max())
    # The new channels are live: the first step opens the zero weights that read them, the
    # second reaches the first layer's new filters.
    b.train()
    opt = torch.optim.SGD(b.parameters(), lr=0.1)
    w_new = b.e0[0].weight[8:].clone()
    for _ in range(2):
        opt.zero_grad()
        b(x).square().mean().backward()
        opt.step()
    assert not torch.equal(w_new, b.e0[0].weight[8:])


def test_more_harmonics_start_at_zero_and_then_learn():
    """fourier-small -> fourier-small-k31: the first 31 maps are the narrow net's, the 32 new
    ones zero (so the decoded occupancy is the same along every ray), and they train."""
    from volcap_train import fourier as FO

    a = narrow_net().eval()
    b = widen(a, FourierNet(31, 8), 8, 8).eval()
    x = torch.randn(2, 4, 256, 256)
    with torch.no_grad():
        ya, yb = a(x), b(x)
    assert yb.shape[1] == 63 and ya.shape[1] == 31
    assert torch.allclose(ya, yb[:, :31], atol=1e-5)
    assert yb[:, 31:].abs().max() == 0.0
    z = torch.linspace(-1, 1, 97)
    rays = lambda y: y[:, :, ::16, ::16].permute(0, 2, 3, 1).unsqueeze(-2)  # [2, 8, 8, 1, 2K+1]
    occ_a = FO.decode(rays(ya), z, 15)
    occ_b = FO.decode(rays(yb), z, 31)
    assert occ_a.abs().max() > 0.1 and torch.allclose(occ_a, occ_b, atol=1e-4)
    b.train()
    opt = torch.optim.SGD(b.parameters(), lr=0.1)
    opt.zero_grad()
    b(x).sub(1.0).square().mean().backward()
    opt.step()
    with torch.no_grad():
        assert b.eval()(x)[:, 31:].abs().max() > 0.0


def test_cli_refuses_a_narrower_or_different_target(tmp_path):
    ck = tmp_path / "n.pt"
    torch.save({"net": narrow_net().state_dict(), "step": 5}, ck)
    out = tmp_path / "w.pt"
    main(["--init", str(ck), "--from", "fourier-small", "--to", "fourier-medium", "--out", str(out)])
    wide = FourierNet(15, 12)
    wide.load_state_dict(torch.load(out)["net"])
    main(["--init", str(ck), "--from", "fourier-small", "--to", "fourier-small-k31", "--out", str(out)])
    FourierNet(31, 8).load_state_dict(torch.load(out)["net"])
    for bad in ("fourier-tiny", "fourier-k7", "fourier-small", "fourier-geom"):
        try:
            main(["--init", str(ck), "--from", "fourier-small", "--to", bad, "--out", str(out)])
        except SystemExit as e:
            assert bad in str(e)
        else:
            raise AssertionError(bad)


def test_an_hr_net_loaded_from_a_plain_checkpoint_computes_the_same_maps():
    """fourier-medium-hr (hands.md section 32): the blocks at the maps' resolution start as the
    identity, so `train fourier --init PLAIN.pt --variant fourier-medium-hr` starts as PLAIN."""
    from volcap_train.nets import make_fourier

    torch.manual_seed(0)
    plain = FourierNet(15, 12)
    with torch.no_grad():
        for m in plain.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.5, 0.5)
                m.running_var.uniform_(0.5, 2.0)
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.2, 0.2)
    hr = make_fourier("fourier-medium-hr")
    assert hr.hr and sum(p.numel() for p in hr.parameters()) > sum(p.numel() for p in plain.parameters())
    sd = hr.state_dict()
    sd.update(plain.state_dict())
    hr.load_state_dict(sd)
    x = torch.randn(2, 4, 256, 256)
    plain.eval(), hr.eval()
    with torch.no_grad():
        assert torch.allclose(hr(x), plain(x), atol=1e-5)
    # ... and once trained a step, the blocks are no longer the identity
    hr.train()
    opt = torch.optim.SGD(hr.parameters(), lr=0.1)
    hr(x).square().mean().backward()
    opt.step()
    hr.eval()
    with torch.no_grad():
        assert not torch.allclose(hr(x), plain(x), atol=1e-4)
