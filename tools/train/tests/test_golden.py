"""volcap_train.golden: the golden files are gzipped safetensors, byte-stable, and every one
committed reads back (the engine's tests read the same files with flate2)."""
from pathlib import Path

import numpy as np
import pytest

from volcap_train.golden import SUFFIX, golden_path, load_golden, read_golden, save_golden

MODELS = Path(__file__).resolve().parents[3] / "models"


def test_a_golden_file_round_trips_and_is_the_same_bytes_each_time(tmp_path):
    t = {"occ": np.linspace(0, 1, 256, dtype=np.float32), "image_u8": np.zeros((256, 256, 3), np.uint8), "ix": np.arange(7, dtype=np.int32)}
    a, b = golden_path(tmp_path, "a"), golden_path(tmp_path, "b")
    assert a.name == "a" + SUFFIX
    save_golden(t, a, metadata={"source": "test"})
    save_golden(t, b, metadata={"source": "test"})
    assert a.read_bytes() == b.read_bytes()  # no name, no time in the gzip header
    back, meta = read_golden(a)
    assert meta == {"source": "test"}
    for k, v in t.items():
        assert back[k].dtype == v.dtype and np.array_equal(back[k], v)
    # the mostly-empty image is what gzip takes away
    assert a.stat().st_size < 0.2 * (256 * 256 * 3)


def test_a_file_that_is_not_a_golden_one_is_refused_naming_it(tmp_path):
    bad = tmp_path / ("x" + SUFFIX)
    bad.write_bytes(b"not gzip at all")
    with pytest.raises(ValueError, match="x.safetensors.gz"):
        load_golden(bad)
    # gzip whose content is not safetensors: a header that claims more than there is
    import gzip

    bad.write_bytes(gzip.compress((10**6).to_bytes(8, "little") + b"{}"))
    with pytest.raises(ValueError, match="x.safetensors.gz"):
        load_golden(bad)


def test_every_committed_golden_file_reads():
    files = sorted((MODELS / "golden").glob("*" + SUFFIX)) + sorted((MODELS / "test").glob("*" + SUFFIX))
    assert len(files) >= 10
    assert not list((MODELS / "golden").glob("*.safetensors")), "an uncompressed golden file is left"
    for f in files:
        t = load_golden(f)
        assert "image_u8" in t and t["image_u8"].dtype == np.uint8, f
