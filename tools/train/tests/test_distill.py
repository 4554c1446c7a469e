"""--teacher: distilling a trained Fourier net's maps into the one being trained (hands.md
section 40): the teacher is checked before any data are read, frozen, and its maps are compared
with the student's in the student's frame, mirrored images included."""
from pathlib import Path

import pytest
import torch

from volcap_train import fourier as FO
from volcap_train.nets import make_fourier
from volcap_train.train import distill_loss, load_teacher, main, mirror_some, teacher_forward

REPO = Path(__file__).resolve().parents[3]
MEDIUM = REPO / "models/checkpoints/shape-fourier-medium.pt"
SMALL = REPO / "models/checkpoints/shape-fourier-small-seg2.pt"


def test_the_committed_medium_net_loads_as_a_frozen_teacher_and_reads_finite_maps():
    t = load_teacher(MEDIUM, "fourier-medium", 15)
    assert not t.training and not any(p.requires_grad for p in t.parameters())
    x = torch.rand(2, 4, 256, 256) * 2 - 1
    m = teacher_forward(t)(x)
    assert m.shape == (2, 31, 128, 128) and m.dtype == torch.float32 and torch.isfinite(m).all()
    with torch.no_grad():
        assert torch.allclose(m, t(x), atol=1e-6)
    # bfloat16 as the student's forward with --amp bf16: close to float32, not equal.
    b = teacher_forward(t, "bf16")(x)
    assert torch.isfinite(b).all() and (b - m).abs().max() < 0.1 * m.abs().max()


def test_a_bad_teacher_is_refused_naming_it(tmp_path):
    with pytest.raises(SystemExit, match="no such checkpoint"):
        load_teacher(tmp_path / "none.pt", "fourier-medium", 15)
    with pytest.raises(SystemExit, match="not a fourier-medium checkpoint"):
        load_teacher(SMALL, "fourier-medium", 15)
    with pytest.raises(SystemExit, match="not a Fourier variant"):
        load_teacher(MEDIUM, "compact", 15)
    with pytest.raises(SystemExit, match="K = 15, the student's K = 31"):
        load_teacher(MEDIUM, "fourier-medium", 31)
    torch.save({"something": 1}, tmp_path / "bad.pt")
    with pytest.raises(SystemExit, match="bad.pt"):
        load_teacher(tmp_path / "bad.pt", "fourier-medium", 15)
    # Through the command line, before any data are read (--data does not exist); a weight
    # that would not distil (or would push away from the teacher) is refused by value.
    with pytest.raises(SystemExit):
        main(["fourier", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "run"), "--teacher", str(MEDIUM), "--teacher-weight", "-1"])
    assert not (tmp_path / "run").exists()
    with pytest.raises(SystemExit, match="none.pt: no such checkpoint"):
        main(["fourier", "--data", str(tmp_path / "nodata"), "--out", str(tmp_path / "run"), "--variant", "fourier-small", "--teacher", str(tmp_path / "none.pt")])


def test_the_loss_compares_the_maps_in_the_students_frame_mirrors_included():
    gen = torch.Generator().manual_seed(3)
    student = torch.randn(4, 31, 16, 16, generator=gen)
    flips = torch.tensor([True, False, True, False])
    # The teacher saw the mirrored inputs: its maps of them are the student's mirrored.
    seen = mirror_some(student, flips)
    assert distill_loss(student, seen, flips).item() < 1e-12
    # Without mirroring them back the mirrored rows differ; unmirrored rows still agree.
    assert distill_loss(student, seen, None).item() > 0.1
    # It is the mean Parseval L2 (the truth's dense loss), f64 reference.
    other = torch.randn(4, 31, 16, 16, generator=gen)
    ref = FO.parseval_l2(student.double(), other.double(), dim=1).mean().item()
    assert abs(distill_loss(student, other).item() - ref) < 1e-5 * abs(ref)
    grad = student.clone().requires_grad_(True)
    distill_loss(grad, other).backward()
    assert torch.isfinite(grad.grad).all() and grad.grad.abs().sum() > 0


def test_a_student_equal_to_its_teacher_has_no_distillation_loss():
    net = make_fourier("fourier-small")
    net.eval()
    x = torch.rand(1, 4, 256, 256) * 2 - 1
    with torch.no_grad():
        assert distill_loss(net(x), teacher_forward(net)(x)).item() < 1e-10
