"""slim_docs: palette PNGs that keep the picture, eval.json packed and still read, links fixed."""
import json

import numpy as np
import pytest
from PIL import Image

from volcap_train import compare_evals as ce
from volcap_train import slim_docs


def test_a_plot_keeps_its_colours_exactly_and_a_render_stays_close(tmp_path):
    rng = np.random.default_rng(0)
    # A plot: a few flat colours (axes, grid, two series) on white.
    plot = np.full((240, 320, 3), 255, np.uint8)
    plot[::20] = (200, 200, 200)
    plot[100:110, 40:300] = (220, 20, 60)
    plot[150:160, 40:300] = (60, 180, 75)
    plot[:, 30:32] = 0
    # A render: smooth shading of many colours plus sensor noise.
    y, x = np.mgrid[0:240, 0:320]
    render = np.stack([x * 0.7 + 20, y * 0.9 + 10, (x + y) * 0.4], -1) + rng.normal(0, 6, (240, 320, 3))
    render = np.clip(render, 0, 255).astype(np.uint8)
    for name, arr in [("plot", plot), ("render", render)]:
        p = tmp_path / f"{name}.png"
        Image.fromarray(arr).save(p)
        before = p.stat().st_size
        b, a = slim_docs.slim_png(p, 0.0, False)
        assert b == before and a == p.stat().st_size
        got = np.asarray(Image.open(p).convert("RGB")).astype(np.float64)
        assert got.shape == arr.shape
        err = np.abs(got - arr)
        if name == "plot":
            assert err.max() == 0, err.max()
        else:
            assert a < before
            # Dithered onto 256 colours: every pixel near, the local mean nearer still.
            assert err.mean() < 8.0, err.mean()
            blur = lambda v: v.reshape(60, 4, 80, 4, 3).mean((1, 3))
            assert np.abs(blur(got) - blur(arr.astype(np.float64))).mean() < 3.0
        # A second pass leaves the file as it is.
        data = p.read_bytes()
        slim_docs.slim_png(p, 0.1, False)
        assert p.read_bytes() == data


def test_transparency_survives(tmp_path):
    arr = np.zeros((32, 32, 4), np.uint8)
    arr[8:24, 8:24] = (10, 200, 30, 255)
    p = tmp_path / "a.png"
    Image.fromarray(arr, "RGBA").save(p)
    p.write_bytes(slim_docs.palette_png(p.read_bytes()))
    got = np.asarray(Image.open(p).convert("RGBA"))
    assert (got[..., 3] == arr[..., 3]).all()
    assert (got[8:24, 8:24, :3] == (10, 200, 30)).all()


def test_packed_reports_are_read_by_compare_evals_and_links_follow(tmp_path):
    run = tmp_path / "docs" / "sec" / "run"
    run.mkdir(parents=True)
    rows = [{"subject": "s1", "pose": 0, "yaw_deg": 0.0, "model": "m", "status": "ok", "chamfer_cm": 2.0,
             "p2s_cm": 1.0, "iou": 0.7, "part_cm": [1, 1, 1, 9.5, 1, 1]}]
    (run / "eval.json").write_text(json.dumps({"images": rows, "models": []}, indent=2))
    plain = ce.load_rows(run, None)
    md = tmp_path / "docs" / "notes.md"
    md.write_text("see [the report](sec/run/eval.json) and [a missing one](sec/other/eval.json)\n")
    slim_docs.main([str(tmp_path / "docs" / "sec"), "--pack-json", "--md", str(tmp_path / "docs")])
    assert not (run / "eval.json").exists() and (run / "eval.json.xz").exists()
    assert ce.load_rows(run, None) == plain
    assert ce.load_rows(run / "eval.json.xz", None) == plain
    assert md.read_text() == "see [the report](sec/run/eval.json.xz) and [a missing one](sec/other/eval.json)\n"


def test_a_file_that_is_no_png_is_named_in_the_error(tmp_path):
    p = tmp_path / "broken.png"
    p.write_bytes(b"not a png at all")
    with pytest.raises(SystemExit, match="broken.png: not a PNG"):
        slim_docs.main([str(tmp_path)])
    assert p.read_bytes() == b"not a png at all"
