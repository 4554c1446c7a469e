"""train fourier --amp bf16 / --compile (training_forward): the float32 path untouched, the
bfloat16 forward's outputs back in float32 and close to float32's, its gradients pointing
the same way, and the one combination that gives non-finite gradients refused up front."""
from pathlib import Path

import pytest
import torch

from volcap_train import train
from volcap_train.nets import make_fourier
from volcap_train.runs import init_weights

REPO = Path(__file__).resolve().parents[3]
CKPT = REPO / "models" / "checkpoints" / "shape-fourier-small.pt"


def net_and_input(seed=0):
    torch.manual_seed(seed)
    net = make_fourier("fourier-small")
    net.load_state_dict(init_weights(torch.load(CKPT, weights_only=False, map_location="cpu"), CKPT))
    g = torch.Generator().manual_seed(seed)
    # A person-like input: a masked blob of image in [-1, 1] and its mask.
    mask = torch.zeros(2, 1, 64, 64)
    mask[:, :, 8:56, 20:44] = 1.0
    rgb = torch.rand(2, 3, 64, 64, generator=g) * 2 - 1
    return net, torch.cat([rgb * mask, mask], 1)


def forward_and_grads(fwd, net, x):
    (coeff,) = fwd(x)
    net.zero_grad()
    # A loss like the training's dense term, in float32 on the float32 outputs.
    (coeff - 0.1).square().mean().backward()
    grads = torch.cat([p.grad.flatten() for p in net.parameters()])
    return coeff, grads


def test_off_is_the_float32_forward_itself():
    fn = lambda x: (x,)  # noqa: E731
    assert train.training_forward(fn, [], "off", False) is fn


def test_bf16_outputs_are_float32_close_to_it_and_the_gradients_agree():
    net, x = net_and_input()
    ref, g_ref = forward_and_grads(lambda t: (net(t),), net, x)
    net2, _ = net_and_input()
    fwd = train.training_forward(lambda t: (net2(t),), [net2], "bf16", False)
    out, g = forward_and_grads(fwd, net2, x)
    assert out.dtype == torch.float32 and torch.isfinite(out).all() and torch.isfinite(g).all()
    # bfloat16 keeps 8 bits of mantissa: the coefficients within a few per cent of the
    # maps' scale, the gradient's direction nearly float32's.
    scale = ref.abs().max().item()
    assert (out - ref).abs().max().item() < 0.05 * scale, ((out - ref).abs().max().item(), scale)
    cos = torch.nn.functional.cosine_similarity(g.double(), g_ref.double(), dim=0).item()
    assert cos > 0.98, cos
    # The weights went to channels-last order, their values unchanged.
    w = net2.e0[0].weight
    assert w.is_contiguous(memory_format=torch.channels_last)
    assert torch.equal(w, net.e0[0].weight)


def test_compile_with_bf16_is_refused_before_any_data_is_read(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        train.main(["fourier", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "run"), "--amp", "bf16", "--compile"])
    assert e.value.code == 2
    assert "--compile with --amp bf16" in capsys.readouterr().err
    with pytest.raises(ValueError, match="compile"):
        train.training_forward(lambda x: (x,), [], "bf16", True)
