"""`train fourier --ema`: the weights' moving average (make_ema), what a run with one ships
(run_net: export, light checkpoints and --init read it), and the decay refused by value."""
import pytest
import torch
import torch.nn as nn

from volcap_train.runs import ema_weights, init_weights, make_ema, run_net


def small_net():
    torch.manual_seed(0)
    return nn.Sequential(nn.Conv2d(2, 3, 3), nn.BatchNorm2d(3), nn.ReLU())


def test_the_average_follows_its_recurrence_for_weights_and_batchnorm_statistics():
    net, d = small_net(), 0.75
    ema = make_ema(net, d)
    want_w, want_m = None, None
    for i in range(4):
        with torch.no_grad():
            net[0].weight.add_(torch.randn_like(net[0].weight))
        net.train()
        net(torch.randn(2, 2, 5, 5) + i)  # moves BatchNorm's running mean
        ema.update_parameters(net)
        w, m = net[0].weight.detach().double(), net[1].running_mean.double()
        want_w = w.clone() if want_w is None else d * want_w + (1 - d) * w
        want_m = m.clone() if want_m is None else d * want_m + (1 - d) * m
    got = ema_weights({"ema": ema.state_dict()})
    assert torch.allclose(got["0.weight"].double(), want_w, atol=1e-6)
    assert torch.allclose(got["1.running_mean"].double(), want_m, atol=1e-6)
    # Not the last weights: the average lags them.
    assert not torch.allclose(got["0.weight"], net[0].weight.detach())
    assert "n_averaged" not in got and set(got) == set(net.state_dict())


def test_a_run_ships_its_average_when_it_has_one():
    net, other = small_net().state_dict(), {k: v + 1 if v.is_floating_point() else v for k, v in small_net().state_dict().items()}
    ema = {"n_averaged": torch.tensor(5), **{f"module.{k}": v for k, v in other.items()}}
    assert run_net({"net": net}) is net
    shipped = run_net({"net": net, "ema": ema})
    assert set(shipped) == set(net) and all(torch.equal(shipped[k], other[k]) for k in net)
    # --init from such a run starts from the average too; a light checkpoint stays as it is.
    w = init_weights({"modules": {"net": net, "ema": ema}, "step": 9}, "run/ckpt.pt")
    assert all(torch.equal(w[k], other[k].float()) for k in net)
    assert ema_weights({"net": net}) is None and run_net(None) is None


@pytest.mark.parametrize("decay", [0.0, 1.0, -0.5, 1.5, float("nan")])
def test_a_decay_outside_the_open_interval_is_refused_by_value(decay):
    with pytest.raises(SystemExit, match=rf"--ema {decay}: the decay must be in \(0, 1\)"):
        make_ema(small_net(), decay)


def test_batchnorm_statistics_are_recomputed_as_the_average_over_the_batches():
    from volcap_train.runs import recompute_bn

    net = small_net()
    net[1].running_mean.fill_(7.0)  # statistics that do not belong to these weights
    w = net[0].weight.detach().clone()
    torch.manual_seed(1)
    batches = [torch.randn(4, 2, 6, 6) * 3 + 1 for _ in range(5)]
    assert recompute_bn(net, iter(batches)) == 1
    with torch.no_grad():
        conv = torch.cat([net[0](x) for x in batches])
    want = conv.double().mean((0, 2, 3))
    assert torch.allclose(net[1].running_mean.double(), want, atol=1e-5)
    assert torch.equal(net[0].weight, w)
    # A net without BatchNorm has nothing to recompute and runs no batch.
    plain = nn.Sequential(nn.Conv2d(2, 3, 3))
    untouched = iter(batches)
    assert recompute_bn(plain, untouched) == 0 and len(list(untouched)) == len(batches)
