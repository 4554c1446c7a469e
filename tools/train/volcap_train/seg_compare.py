"""Compare person segmentation candidates: real photos with hand masks, simulator renders, time.

    python -m volcap_train.seg_compare --real ../../tests/data/real --data /work/data/ds2 \
        --model ours=PATH --model mediapipe=../../models/seg.onnx --out ../../docs/seg

Every candidate is an ONNX file with the engine's segmentation contract (`image` [1, 3, 256,
256] RGB in [0, 1] -> `mask` [1, 1, 256, 256] person probability). Inputs are letterboxed to
256x256 exactly as the engine does (aspect kept, black bars); the prediction (> 0.5) is
compared with the reference mask at 256x256:

* real: each `NAME.{jpg,png}` in --real with its hand-drawn `NAME.mask.png` (person = 255);
* sim: the held-out split of a `volcap sim dataset` folder, as rendered, and composited over
  the training's procedural backgrounds with photometric extremes (seed 1234, the seg
  trainer's validation protocol);
* ms: median of 20 runs with onnxruntime on one thread (the engine's own time, tract, is in
  `volcap eval`'s "seg ms" column).

Writes OUT/compare.md and OUT/compare.json, and OUT/real.png: each real photo, its reference
mask and every candidate's mask side by side.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from tqdm import tqdm

SIZE = 256


def letterbox(img: Image.Image, resample=Image.BILINEAR) -> np.ndarray:
    """The engine's letterbox (preprocess.rs): aspect kept, centred, black bars."""
    w, h = img.size
    scale = min(SIZE / w, SIZE / h)
    fw, fh = max(1, min(SIZE, round(w * scale))), max(1, min(SIZE, round(h * scale)))
    out = Image.new(img.mode, (SIZE, SIZE))
    out.paste(img.resize((fw, fh), resample), ((SIZE - fw) // 2, (SIZE - fh) // 2))
    return np.asarray(out)


def iou(pred: np.ndarray, ref: np.ndarray) -> float:
    union = (pred | ref).sum()
    return float((pred & ref).sum() / union) if union else 1.0


def real_set(folder: Path):
    out = []
    for m in sorted(folder.glob("*.mask.png")):
        stem = m.name[: -len(".mask.png")]
        src = next((p for p in (folder / f"{stem}.jpg", folder / f"{stem}.png") if p.exists()), None)
        if src is None:
            raise SystemExit(f"{m}: no {stem}.jpg or {stem}.png beside it")
        img = Image.open(src).convert("RGB")
        mask = Image.open(m).convert("L")
        if mask.size != img.size:
            raise SystemExit(f"{m}: size {mask.size} differs from {src} {img.size}")
        x = letterbox(img).astype(np.float32) / 255.0
        ref = letterbox(mask, Image.NEAREST) > 127
        out.append((stem, x, ref))
    return out


def sim_set(data: Path, n: int):
    from .data import Split, backgrounds, photometric

    va = Split(data, "val")
    idx = torch.arange(0, len(va), max(1, len(va) // n))[:n]
    rgb = torch.stack([va.rgb01(int(i)) for i in idx])
    m = torch.stack([va.mask01(int(i)) for i in idx])
    g = torch.Generator().manual_seed(1234)
    comp = photometric(rgb * m + backgrounds(len(idx), rgb.shape[-1], g) * (1 - m), g)
    ref = (m[:, 0] > 0.5).numpy()
    return rgb.numpy(), comp.numpy(), ref


def main(argv=None):
    ap = argparse.ArgumentParser(prog="volcap_train.seg_compare", description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", action="append", required=True, help="NAME=PATH of an ONNX segmentation model (repeat)")
    ap.add_argument("--real", type=Path, required=True, help="folder of real photos NAME.jpg/png with NAME.mask.png")
    ap.add_argument("--data", type=Path, default=None, help="a `volcap sim dataset` folder (its val split)")
    ap.add_argument("--sim-images", type=int, default=96)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    from .seg_masks import session

    real = real_set(args.real)
    sim = sim_set(args.data, args.sim_images) if args.data else None
    rows, masks = [], {}
    for spec in tqdm(args.model, desc="candidates", unit="model"):
        name, _, path = spec.partition("=")
        if not path:
            raise SystemExit(f"--model {spec}: expected NAME=PATH")
        sess = session(path)

        def run(x: np.ndarray) -> np.ndarray:
            return sess.run(None, {"image": np.ascontiguousarray(x[None].transpose(0, 3, 1, 2) if x.shape[-1] == 3 else x[None], dtype=np.float32)})[0][0, 0]

        row = {"model": name, "file": path, "bytes": Path(path).stat().st_size, "real": {}}
        for stem, x, ref in real:
            p = run(x)
            if not np.isfinite(p).all():
                raise SystemExit(f"{path}: non-finite mask on {stem}")
            masks[(name, stem)] = p > 0.5
            row["real"][stem] = iou(p > 0.5, ref)
        row["real_mean"] = float(np.mean(list(row["real"].values())))
        if sim is not None:
            rgb, comp, ref = sim
            row["sim_rendered"] = float(np.mean([iou(run(rgb[i]) > 0.5, ref[i]) for i in range(len(ref))]))
            row["sim_composited"] = float(np.mean([iou(run(comp[i]) > 0.5, ref[i]) for i in range(len(ref))]))
        x = real[0][1]
        run(x)
        ts = []
        for _ in range(20):
            t = time.perf_counter()
            run(x)
            ts.append((time.perf_counter() - t) * 1e3)
        row["ms_ort_1thread"] = float(np.median(ts))
        rows.append(row)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "compare.json").write_text(json.dumps(rows, indent=1))
    stems = [s for s, _, _ in real]
    head = "| model | " + " | ".join(f"real {s}" for s in stems) + " | real mean | sim rendered | sim composited | ms (ort, 1 thread) | bytes |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        sim_cols = f"{r['sim_rendered']:.3f} | {r['sim_composited']:.3f}" if "sim_rendered" in r else "- | -"
        lines.append(f"| {r['model']} | " + " | ".join(f"{r['real'][s]:.3f}" for s in stems) + f" | {r['real_mean']:.3f} | {sim_cols} | {r['ms_ort_1thread']:.1f} | {r['bytes']} |")
    (args.out / "compare.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    # Sheet: photo, reference, then each candidate.
    names = [r["model"] for r in rows]
    sheet = Image.new("RGB", (SIZE * (2 + len(names)), SIZE * len(real)), (255, 255, 255))
    for j, (stem, x, ref) in enumerate(real):
        tiles = [(x * 255).astype(np.uint8), np.repeat(ref[..., None] * 255, 3, -1).astype(np.uint8)]
        tiles += [np.repeat(masks[(n, stem)][..., None] * 255, 3, -1).astype(np.uint8) for n in names]
        for i, t in enumerate(tiles):
            sheet.paste(Image.fromarray(t), (i * SIZE, j * SIZE))
    sheet.save(args.out / "real.png")


if __name__ == "__main__":
    main()
