"""`train --init`: a light checkpoint and a run's full checkpoint give the same weights;
anything else is refused with the file named."""
import pytest
import torch

from volcap_train.runs import init_weights


def test_light_and_full_checkpoints_give_the_same_weights():
    net = {"a.weight": torch.randn(3, 2, dtype=torch.float16), "a.bias": torch.randn(3)}
    light = {"net": net, "step": 8000}
    full = {"modules": {"net": net}, "opt": {"state": {}}, "step": 8000}
    a, b = init_weights(light, "light.pt"), init_weights(full, "ckpt.pt")
    assert a.keys() == net.keys() == b.keys()
    for k in net:
        assert a[k].dtype == torch.float32
        assert torch.equal(a[k], b[k])
        assert torch.equal(a[k], net[k].float())


@pytest.mark.parametrize("bad", [{}, {"modules": {}}, {"modules": None}, {"net": [1, 2]}, [1, 2], None])
def test_other_files_are_refused_naming_the_file(bad):
    with pytest.raises(SystemExit, match="somewhere/odd.pt"):
        init_weights(bad, "somewhere/odd.pt")


def test_a_runs_light_checkpoint_resumes_its_weights(tmp_path):
    from volcap_train.light import from_run

    net = {"a.weight": torch.randn(3, 2), "a.bias": torch.randn(3)}
    run = tmp_path / "run"
    run.mkdir()
    torch.save({"modules": {"net": net}, "opt": {"state": {"big": torch.zeros(1000)}}, "step": 1234}, run / "ckpt.pt")
    out = tmp_path / "checkpoints" / "wip.pt"
    assert from_run(run, out, "fourier-small") == 1234
    light = torch.load(out, weights_only=False)
    assert light["step"] == 1234 and light["variant"] == "fourier-small" and "opt" not in light
    w = init_weights(light, out)
    assert all(torch.equal(w[k], net[k]) for k in net)


def test_a_folder_without_a_checkpoint_is_refused_by_name(tmp_path):
    from volcap_train.light import from_run

    with pytest.raises(SystemExit, match="empty: no ckpt.pt"):
        from_run(tmp_path / "empty", tmp_path / "x.pt", "fourier-small")


def test_a_half_light_checkpoint_is_half_the_bytes_and_resumes_within_float16s_rounding(tmp_path):
    from volcap_train.light import from_run

    torch.manual_seed(3)
    net = {
        "conv.weight": torch.randn(64, 32, 3, 3) * 0.05,
        "bn.running_var": torch.rand(64) + 0.5,
        "bn.num_batches_tracked": torch.tensor(5334),
        # float16 cannot hold these: beyond its range, and a value it would flush to zero
        "odd.big": torch.tensor([1e6, 1.0]),
        "odd.tiny": torch.tensor([1e-9, 1.0]),
    }
    run = tmp_path / "run"
    run.mkdir()
    torch.save({"modules": {"net": net}, "step": 5334}, run / "ckpt.pt")
    full, half = tmp_path / "f32.pt", tmp_path / "f16.pt"
    from_run(run, full, "fourier-medium")
    from_run(run, half, "fourier-medium", half=True)
    assert half.stat().st_size < 0.6 * full.stat().st_size
    light = torch.load(half, weights_only=False)
    assert light["dtype"] == "float16" and light["step"] == 5334
    assert light["net"]["conv.weight"].dtype == torch.float16
    assert light["net"]["odd.big"].dtype == torch.float32 and light["net"]["odd.tiny"].dtype == torch.float32
    w = init_weights(light, half)
    assert all(w[k].dtype == torch.float32 for k in net if net[k].is_floating_point())
    assert w["bn.num_batches_tracked"].dtype == torch.int64 and int(w["bn.num_batches_tracked"]) == 5334
    for k in ("conv.weight", "bn.running_var"):
        ref = net[k].double()
        err = (w[k].double() - ref).abs()
        # float16's rounding: half a unit in the last place, 2^-11 of the value; below its
        # smallest normal (2^-14) the subnormals' fixed step, 2^-24
        bound = torch.maximum(ref.abs() * 2.0**-11, torch.full_like(ref, 2.0**-25))
        assert err.max() > 0 and bool((err <= bound).all()), k
    assert torch.equal(w["odd.big"], net["odd.big"]) and torch.equal(w["odd.tiny"], net["odd.tiny"])
