"""The product's segmentation: provenance pinned in the committed file, the converter's padding rule."""

from pathlib import Path

import onnx
import pytest

from volcap_train import mediapipe_seg as MS
from volcap_train.tflite_onnx import _same_pads

MODELS = Path(__file__).resolve().parents[3] / "models"


def test_same_padding_puts_the_odd_pixel_after():
    # TensorFlow's SAME: out = ceil(in / stride), the extra pixel of an odd total at the end.
    assert _same_pads((256, 256), (3, 3), (2, 2)) == [0, 0, 1, 1]
    assert _same_pads((128, 128), (3, 3), (1, 1)) == [1, 1, 1, 1]
    assert _same_pads((16, 16), (5, 5), (2, 2)) == [1, 1, 2, 2]
    assert _same_pads((8, 8), (1, 1), (1, 1)) == [0, 0, 0, 0]


@pytest.mark.skipif(not (MODELS / "seg.onnx").exists(), reason="no committed seg.onnx")
def test_committed_segmentation_names_its_pinned_source_and_licence():
    m = onnx.load(str(MODELS / "seg.onnx"), load_external_data=False)
    meta = {p.key: p.value for p in m.metadata_props}
    assert meta["volcap.kind"] == "seg"
    assert meta["volcap.license"] == "Apache-2.0"
    assert MS.WHEEL_SHA256 in meta["volcap.source"] and MS.TFLITE_SHA256 in meta["volcap.source"]
    assert "Apache License" in (MODELS / "LICENSE-mediapipe").read_text()
    shape = [d.dim_value for d in m.graph.input[0].type.tensor_type.shape.dim]
    assert shape == [1, 3, 256, 256]


def test_a_wheel_with_another_hash_is_refused(tmp_path):
    fake = tmp_path / MS.WHEEL
    fake.write_bytes(b"not the wheel")
    with pytest.raises(SystemExit, match="sha256"):
        MS.extract(fake, tmp_path)
