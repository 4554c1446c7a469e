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
