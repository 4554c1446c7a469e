"""Fetch MediaPipe's selfie segmentation from its PyPI wheel and install it as `models/seg.onnx`.

    python -m volcap_train.mediapipe_seg --out ../../models [--wheel PATH] [--data DS]

Provenance, pinned: the `mediapipe` 0.10.21 wheel for CPython 3.11 / manylinux_2_28 x86_64
(Apache-2.0, Google), sha256 below, bundles `selfie_segmentation.tflite` (the "general"
256x256 model; sha256 below). Newer wheels no longer ship it. The wheel is fetched by
`pip download` from PyPI (the only network this needs) unless `--wheel` names a copy; both
hashes are checked before anything is written. The TFLite graph is converted by
`tflite_onnx.py` (NCHW, fp16 weights widened to f32) and saved with the `volcap.*` metadata
the engine checks. Input `image` [1, 3, 256, 256] RGB in [0, 1]; output `mask` [1, 1, 256,
256], the person probability: the contract of our own segmentation network, so the engine
and the daemon take it unchanged.

The golden vectors (`models/golden/seg.safetensors.gz`, checked by the engine's tests) come from
MediaPipe's own runtime when the `mediapipe` package is importable (install the same wheel in
a side environment: it pins protobuf 4, which the training environment's onnx does not
accept), otherwise from onnxruntime on the converted graph; the file says which. The
conversion itself was checked against MediaPipe's runtime: max |difference| 4.3e-5 on
scikit-image's astronaut and camera images (docs/seg/README.md).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

WHEEL = "mediapipe-0.10.21-cp311-cp311-manylinux_2_28_x86_64.whl"
WHEEL_SHA256 = "05dc4a9e593655a79558d05d6227d31018c2537a4bd3362b51e230cf22aecfe3"
MEMBER = "mediapipe/modules/selfie_segmentation/selfie_segmentation.tflite"
TFLITE_SHA256 = "9ee168ec7c8f2a16c56fe8e1cfbc514974cbbb7e434051b455635f1bd1462f5c"
LICENSE_MEMBER = "mediapipe-0.10.21.dist-info/LICENSE"
RUN = "mediapipe-selfie-segmentation-0.10.21"


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def fetch_wheel(dest: Path) -> Path:
    """pip download the pinned wheel (no dependencies) into dest."""
    dest.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "pip", "download", "mediapipe==0.10.21", "--no-deps", "--only-binary=:all:",
           "--python-version", "3.11", "--platform", "manylinux_2_28_x86_64", "-d", str(dest)]
    subprocess.run(cmd, check=True)
    return dest / WHEEL


def extract(wheel: Path, tmp: Path) -> tuple[Path, str]:
    got = sha256(wheel)
    if got != WHEEL_SHA256:
        raise SystemExit(f"{wheel}: sha256 {got}, expected {WHEEL_SHA256} (not the pinned mediapipe 0.10.21 wheel)")
    with zipfile.ZipFile(wheel) as z:
        z.extract(MEMBER, tmp)
        licence = z.read(LICENSE_MEMBER).decode()
    tfl = tmp / MEMBER
    got = sha256(tfl)
    if got != TFLITE_SHA256:
        raise SystemExit(f"{wheel}!{MEMBER}: sha256 {got}, expected {TFLITE_SHA256}")
    return tfl, licence


def with_meta(m, meta: dict):
    del m.metadata_props[:]
    for k, v in meta.items():
        p = m.metadata_props.add()
        p.key, p.value = f"volcap.{k}", str(v)
    return m


def write_card(out: Path, m) -> None:
    """models.json entry and seg.md for the installed segmentation."""
    from onnx import numpy_helper

    params = sum(int(np.prod(numpy_helper.to_array(t).shape)) for t in m.graph.initializer)
    index = out / "models.json"
    idx = json.loads(index.read_text()) if index.exists() else {}
    idx["seg"] = {"files": ["seg.onnx"], "params": params, "source": RUN, "license": "Apache-2.0"}
    index.write_text(json.dumps(idx, indent=2, sort_keys=True))
    (out / "seg.md").write_text(f"""# Model card: seg

File: `seg.onnx`: MediaPipe's selfie segmentation ("general", 256x256), Google, Apache-2.0
(`LICENSE-mediapipe`), converted from TFLite by `python -m volcap_train.mediapipe_seg --out models`.
Not trained here: a third-party dependency, pinned like a crate.

| | |
|---|---|
| source | PyPI `{WHEEL}` (sha256 `{WHEEL_SHA256}`), member `{MEMBER}` (sha256 `{TFLITE_SHA256}`) |
| licence | Apache-2.0 (the wheel's LICENSE, copied to `models/LICENSE-mediapipe`) |
| parameters | {params:,} |
| contract | `image` [1,3,256,256] RGB in [0,1] (letterboxed frame) -> `mask` [1,1,256,256] person probability |
| conversion | `tools/train/volcap_train/tflite_onnx.py`: NCHW, fp16 weights widened to f32; max abs difference to MediaPipe's own runtime 4.3e-5 (astronaut, camera) |
| golden | `golden/seg.safetensors.gz`, from MediaPipe's runtime, checked against tract by `cargo test` |
| int8 | none: its statically quantized form lost 0.33 mask IoU on the astronaut photo and was slower in tract; `@int8` models use this f32 file |

**Why this one.** Measured against our own sim-trained U-Net (`seg-sim.onnx`) by
`python -m volcap_train.seg_compare` (docs/seg/compare.md): on real photographs with hand-drawn masks it
holds (mean mask IoU 0.81 against 0.37); on the simulator's renders as the appliance sees them 0.89 against
0.57; on renders composited over the trainer's procedural backgrounds with photometric extremes 0.79 against
0.86. In the engine (tract, one core) 15 ms per frame with letterbox and person regions.

**Trained on** real selfie and video-call imagery (Google's model card: "MediaPipe Selfie Segmentation",
people within about 2 m of the camera); full bodies further away are segmented but are outside its stated
use, so keep watching mask IoU on the appliance's own scenes (`volcap eval` reports it per image).
""")


def reference_mask(image_u8: np.ndarray, onnx_path: Path) -> tuple[np.ndarray, str]:
    """Person probability [256, 256] of a 256x256 RGB8 image: MediaPipe's runtime if present and
    the file holds MediaPipe's own weights (its `volcap.run` is the conversion's), else ONNX
    Runtime on the file (a `seg_tune`d file: MediaPipe's runtime knows only the original). The
    metadata is read through the same ONNX Runtime session (not the onnx package, which may not
    import beside mediapipe's protobuf 4)."""
    import onnxruntime as ort

    sess = ort.InferenceSession(str(onnx_path))
    run = sess.get_modelmeta().custom_metadata_map.get("volcap.run", "")
    if run == RUN:
        try:
            import mediapipe as mp  # noqa: F401

            with mp.solutions.selfie_segmentation.SelfieSegmentation(model_selection=0) as s:
                return np.asarray(s.process(image_u8).segmentation_mask, np.float32), "mediapipe 0.10.21 runtime (TFLite)"
        except ImportError:
            pass
    x = (image_u8.astype(np.float32) / 255.0).transpose(2, 0, 1)[None]
    return sess.run(None, {"image": x})[0][0, 0], f"onnxruntime on {onnx_path.name} ({run})"


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.mediapipe_seg", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="models folder (writes seg.onnx, seg.md, LICENSE-mediapipe, golden/seg.safetensors.gz, the models.json entry)")
    ap.add_argument("--wheel", type=Path, default=None, help="a local copy of the pinned wheel (default: pip download it)")
    ap.add_argument("--golden-only", action="store_true", help="only rewrite golden/seg.safetensors.gz from the installed seg.onnx")
    args = ap.parse_args(argv)
    from .golden import golden_path, load_golden, save_golden

    out = args.out
    golden = golden_path(out / "golden", "seg")
    path = out / "seg.onnx"
    if not args.golden_only:
        import onnx  # not needed for --golden-only, which may run beside mediapipe's protobuf 4

        from .tflite_onnx import convert

        with tempfile.TemporaryDirectory() as td:
            tmp = Path(td)
            wheel = args.wheel or fetch_wheel(tmp / "wheel")
            tfl, licence = extract(wheel, tmp)
            m = convert(str(tfl))
        meta = {"kind": "seg", "input_size": 256, "precision": "f32", "run": RUN, "source": f"PyPI {WHEEL} sha256:{WHEEL_SHA256} {MEMBER} sha256:{TFLITE_SHA256}", "license": "Apache-2.0"}
        onnx.save(with_meta(m, meta), str(path))
        (out / "LICENSE-mediapipe").write_text(licence)
        write_card(out, m)
        print(f"wrote {path} ({path.stat().st_size} bytes), seg.md, LICENSE-mediapipe")
    if not golden.exists():
        raise SystemExit(f"{golden}: missing (it holds the golden image; export the trained models first)")
    g = load_golden(golden)
    prob, source = reference_mask(g["image_u8"], path)
    gen = np.random.default_rng(7)
    iy = gen.integers(0, 256, 512).astype(np.int32)
    ix = gen.integers(0, 256, 512).astype(np.int32)
    keep = {k: v for k, v in g.items() if k not in ("iy", "ix", "mask_prob")}
    save_golden({**keep, "iy": iy, "ix": ix, "mask_prob": prob[iy, ix].astype(np.float32)}, golden, metadata={"source": source})
    print(json.dumps({"golden": str(golden), "source": source}))


if __name__ == "__main__":
    main()
