"""The product's segmentation masks for training images: what the engine's encoder is given.

The engine (service/engine/src/model/mod.rs, `Models::prepare`) segments the 256x256
letterboxed frame with models/seg.onnx (MediaPipe), keeps the most prominent person
(`preprocess::keep_most_prominent`: the largest 8-connected region of mask > 0.5 that covers
at least MIN_PERSON_FRACTION of the frame and MIN_PERSON_RELATIVE of the largest region; the
soft values inside it are kept, everything else is 0), crops around it and feeds the soft mask
to the encoder. Training on ground-truth masks alone leaves the shape network blind to that
mask's errors (soft edges, a lost hand, a shadow taken for a leg); `predicted_masks` gives the
same mask for each dataset image (the dataset's images are 256x256, the letterbox is the
identity), cached beside the shards.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from . import crop as C

# preprocess.rs
MIN_PERSON_FRACTION = 0.002
MIN_PERSON_RELATIVE = 0.1


def runs(binary: np.ndarray) -> list[tuple[int, int, int]]:
    """The horizontal runs of True in a [H, W] bool array, row-major: (row, first, last)."""
    out = []
    for r, row in enumerate(binary):
        d = np.diff(np.concatenate(([0], row.astype(np.int8), [0])))
        out.extend((r, int(a), int(b) - 1) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))
    return out


def keep_most_prominent(mask: torch.Tensor) -> tuple[torch.Tensor, int]:
    """The engine's rule on one soft [H, W] mask: (the mask with everything outside the most
    prominent person set to 0, the number of people). Regions are 8-connected (runs of
    adjacent rows joined when they overlap or touch diagonally, union-find); ties between
    equal areas go to the region met first in row-major order, as in the engine."""
    n = mask.numel()
    rs = runs((mask > 0.5).numpy())
    parent = list(range(len(rs)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    prev, cur, row = [], [], -1
    for i, (r, a, b) in enumerate(rs):
        if r != row:
            prev, cur, row = (cur if r == row + 1 else []), [], r
        for j in prev:
            _, c, d = rs[j]
            if a <= d + 1 and c <= b + 1:
                ri, rj = find(i), find(j)
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)  # the root is the region's first run
        cur.append(i)
    area: dict[int, int] = {}
    for i, (_, a, b) in enumerate(rs):
        root = find(i)
        area[root] = area.get(root, 0) + b - a + 1
    if not area:
        return torch.zeros_like(mask), 0
    largest = max(area.values())
    floor = max(MIN_PERSON_FRACTION * n, MIN_PERSON_RELATIVE * largest)
    people = sum(1 for v in area.values() if v >= floor)
    if people == 0:
        return torch.zeros_like(mask), 0
    best = min(root for root, v in area.items() if v == largest)
    keep = torch.zeros_like(mask, dtype=torch.bool)
    for i, (r, a, b) in enumerate(rs):
        if find(i) == best:
            keep[r, a : b + 1] = True
    return torch.where(keep, mask, torch.zeros_like(mask)), people


def session(model: Path | str, threads: int = 1):
    """An onnxruntime CPU session for a segmentation model, `threads` intra-op threads, quiet."""
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.log_severity_level = 3
    return ort.InferenceSession(str(model), so, providers=["CPUExecutionProvider"])


def segment(model: Path, images: torch.Tensor, threads: int = 1) -> torch.Tensor:
    """Soft person masks [B, H, W] from RGB [B, 3, 256, 256] in [0, 1] through the ONNX
    segmentation model (`image` -> `mask`); non-finite values count as 0, as in the engine."""
    sess = session(model, threads)
    out = []
    for i in tqdm(range(len(images)), desc=f"segmenting ({model.name})", unit="img"):
        m = sess.run(None, {"image": np.ascontiguousarray(images[i : i + 1].numpy(), dtype=np.float32)})[0][0, 0]
        out.append(torch.from_numpy(np.nan_to_num(m, nan=0.0, posinf=0.0, neginf=0.0)))
    return torch.stack(out)


def paste_max(crop_mask: torch.Tensor, params, into: torch.Tensor) -> torch.Tensor:
    """The engine's `Crop::paste_max`: a [S, S] mask made on the crop `params` (crop.py) taken
    back into the [S, S] input square, each input pixel inside the crop's square the larger
    of its own value and the crop mask's bilinear value there (grid_sample,
    align_corners=True); pixels outside the square keep theirs."""
    s, tx, ty = params
    n = into.shape[-1]
    ndc = -1 + 2 * torch.arange(n, dtype=torch.float32) / (n - 1)
    ux, uy = (ndc - tx) / s, (ndc - ty) / s
    gy, gx = torch.meshgrid(uy, ux, indexing="ij")
    grid = torch.stack([gx, gy], -1)[None]
    v = F.grid_sample(crop_mask[None, None].float(), grid, mode="bilinear", padding_mode="border", align_corners=True)[0, 0]
    inside = (gx.abs() <= 1) & (gy.abs() <= 1)
    return torch.where(inside, torch.maximum(into, v), into)


def second_pass(model: Path, images: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
    """The engine's second segmentation pass (`Models::person_mask` with `segment_passes`
    2) on kept first-pass masks [B, H, W]: each person's crop segmented again, that mask
    pasted back by its larger value, the most prominent person kept again."""
    out = first.clone()
    crops, where = [], []
    for i in range(len(first)):
        p = C.crop_params(first[i])
        if p is not None:
            crops.append(C.apply_crop(images[i], p))
            where.append((i, p))
    if not crops:
        return out
    second = segment(model, torch.stack(crops))
    for (i, p), m2 in zip(where, second):
        out[i] = keep_most_prominent(paste_max(m2, p, first[i]))[0]
    return out


def model_tag(model: Path) -> str:
    """The caches' name for a segmentation model: its file's stem and the first 8 hex digits of
    its SHA-256, so that a retrained model of the same name (seg_tune's `seg.onnx`) never reads
    masks cached from another."""
    import hashlib

    if not Path(model).is_file():
        raise FileNotFoundError(f"{model}: no such segmentation model")
    return f"{Path(model).stem}-{hashlib.sha256(Path(model).read_bytes()).hexdigest()[:8]}"


def passes_tag(passes: int) -> str:
    """The caches' name part for masks made in `passes` segmentation passes ("" for one)."""
    return "-p2" if passes > 1 else ""


def as_u8(soft: torch.Tensor) -> torch.Tensor:
    """u8 [B, 1, H, W] (soft mask x 255, the caches' form) of soft masks [B, H, W]."""
    return (soft.clamp(0, 1) * 255).round().to(torch.uint8)[:, None]


def product_masks(model: Path, images: torch.Tensor, passes: int = 1) -> torch.Tensor:
    """Soft masks [B, H, W] of the most prominent person in RGB [B, 3, 256, 256] in [0, 1], as
    the engine's `Models::person_mask` makes them: segmented, the largest person kept, with
    `passes` 2 the person's crop segmented again (`second_pass`)."""
    soft = segment(model, images)
    kept = torch.stack([keep_most_prominent(m)[0] for m in soft])
    if passes > 1:
        kept = second_pass(model, images, kept)
    return kept


def predicted_masks(root: Path, split, split_name: str, model: Path, passes: int = 1) -> torch.Tensor:
    """u8 [B, 1, H, W] (soft mask x 255) of the engine's segmentation for every image of a
    dataset split, most prominent person only (all zero where none is found), with
    `passes` 2 the person's crop segmented again (`second_pass`); cached as
    ROOT/seg-{split}-{model_tag(model)}[-p2]-v1.pt."""
    cache = root / f"seg-{split_name}-{model_tag(model)}{passes_tag(passes)}-v1.pt"
    if cache.exists():
        out = torch.load(cache)
        if out.shape[0] == len(split):
            return out
    images = torch.stack([split.rgb01(i) for i in range(len(split))])
    out = as_u8(product_masks(model, images, passes))
    torch.save(out, cache)
    return out
