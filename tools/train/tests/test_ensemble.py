"""ensemble: N Fourier nets as one ONNX file whose coefficients are the mean of theirs."""
import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from volcap_train import ensemble
from volcap_train.export import export
from volcap_train.nets import make_fourier


def test_the_files_output_is_the_mean_of_the_nets_and_keeps_the_metadata(tmp_path):
    nets = []
    for seed in (0, 1, 2):
        torch.manual_seed(seed)
        n = make_fourier("fourier-small").eval()
        torch.save({"net": n.state_dict(), "step": 1, "variant": "fourier-small"}, tmp_path / f"n{seed}.pt")
        nets.append(n)
    like = tmp_path / "like.onnx"
    export(nets[0], (torch.rand(1, 4, 64, 64),), ["image"], ["coeff"], like, {"input_size": 64, "iso_level": 0.55}, False)
    out = tmp_path / "ens.onnx"
    ensemble.main([str(out), *(str(tmp_path / f"n{s}.pt") for s in (0, 1, 2)), "--variant", "fourier-small", "--like", str(like)])
    x = torch.rand(1, 4, 64, 64, generator=torch.Generator().manual_seed(5))
    got = ort.InferenceSession(str(out)).run(None, {"image": x.numpy()})[0]
    with torch.no_grad():
        ref = torch.stack([n(x).double() for n in nets]).mean(0).numpy()
    assert np.abs(got - ref).max() < 1e-4 * max(1.0, np.abs(ref).max())
    assert np.abs(got - nets[0](x).detach().numpy()).max() > 1e-3  # not one net's
    meta = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert meta["volcap.iso_level"] == "0.55" and meta["volcap.run"].startswith("ensemble of 3")
    with pytest.raises(SystemExit, match="at least two"):
        ensemble.main([str(out), str(tmp_path / "n0.pt"), "--variant", "fourier-small", "--like", str(like)])
