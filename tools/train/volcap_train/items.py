"""The Fourier head's training items: per image the engine's crop, the cropped RGB and mask,
the ground-truth coefficient maps and labelled points (`fourier_items`), cached beside a
dataset's shards (`fourier_cached`, optionally on the product's segmentation masks), several
datasets' training images joined as one (`fourier_union`), and the upper-body variant cut by
the frame's lower edge (`fourier_upper_cached`, its masks the true ones cut or the product's of the
cut images, `cut_masks`)."""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from tqdm import tqdm

from . import crop as C
from . import fourier as FO
from .data import Split


COEFF_SIZE = 128


def cut_row(mask: torch.Tensor, keep: float) -> int | None:
    """The last image row kept when only the top `keep` of the person's height stays in the
    frame (a person close to the camera, cut by the frame's lower edge: a webcam's upper body);
    None when the mask is empty."""
    rows = torch.nonzero(mask.amax(-1) > 0.5)[:, 0]
    if len(rows) == 0:
        return None
    top, bottom = int(rows.min()), int(rows.max())
    return top + max(1, int(round(keep * (bottom - top))))


def truncate_below(img: torch.Tensor, row: int) -> torch.Tensor:
    """[C, H, W] with every row after `row` set to 0 (what the crop reads beyond the frame)."""
    out = img.clone()
    out[..., row + 1 :, :] = 0
    return out


def fourier_items(split: Split, k: int, points: int = 4096, keep=None, masks: torch.Tensor | None = None):
    """Per image: the GT-mask crop (engine rule), the cropped RGB and mask (u8), the ground-truth
    coefficient maps [2K+1, 128, 128] (f16) on the crop's map grid, and labelled points in crop
    NDC. The coefficient maps are computed on the input pixel grid (intervals scaled by the
    crop, fourier.py) and resampled through the crop (bilinear, zeros outside): linear in the
    coefficients, so a map pixel holds the mean occupancy function of its neighbourhood.

    `keep` (image index -> fraction, or None): the upper-body variant. Only the top fraction
    of the person stays in the frame; everything below the cut row is zero in the image, the
    mask, the target series and the point labels (the field is what the image shows, a bust),
    and the crop is taken from the cut mask, as the engine would on such a frame.

    `masks` (u8 [B, 1, H, W], seg_masks.predicted_masks): the engine's segmentation instead of
    the ground-truth mask for the crop and the encoder's mask channel (the targets stay the
    ground truth's); images where it finds no person are left out, as the engine reports none."""
    if not split.ray_offsets:
        raise ValueError(f"{split.files[0]}: shards have no ray_offsets/ray_z (regenerate with `volcap sim dataset`)")
    rgb, mask, coeff, pts, occ, keep_idx = [], [], [], [], [], []
    size = split.image.shape[-1]
    for i in tqdm(range(len(split)), desc=f"fourier targets K={k}{' (cut)' if keep else ''}", unit="img"):
        m = split.mask01(i)
        image = split.rgb01(i)
        row = cut_row(m[0], keep(i)) if keep is not None else None
        if masks is not None:
            m = masks[i].float() / 255.0
        if row is not None:
            m, image = truncate_below(m, row), truncate_below(image, row)
        p = C.crop_params(m[0])
        if p is None:
            continue
        s, tx, ty = p
        rgb.append((C.apply_crop(image, p) * 255).round().to(torch.uint8))
        mask.append((C.apply_crop(m, p) * 255).round().to(torch.uint8))
        full = FO.ray_coeff_maps(split.ray_offsets[i], split.ray_z[i], size, s, k)
        if row is not None:
            full = truncate_below(full, row)
        theta = torch.tensor([[[s, 0.0, tx], [0.0, s, ty]]], dtype=torch.float32)
        grid = F.affine_grid(theta, (1, 1, COEFF_SIZE, COEFF_SIZE), align_corners=True)
        coeff.append(F.grid_sample(full[None], grid, mode="bilinear", padding_mode="zeros", align_corners=True)[0].half())
        # Shards store the inside points first, then the outside ones: take both halves so
        # that the point term is balanced (the first `points` alone would be all inside,
        # which pushes the series outward).
        n_all, half = split.points.shape[1], points // 2
        sel = torch.cat([torch.arange(half), torch.arange(n_all - (points - half), n_all)])
        o = split.occ[i][sel]
        if row is not None:
            # Input NDC y of pixel row r is -1 + 2 r / (S - 1) (crop.py): below the cut is empty.
            o = torch.where(split.points[i][sel][:, 1] > -1 + 2 * (row + 0.5) / (size - 1), torch.zeros_like(o), o)
        pts.append(C.to_crop(split.points[i][sel], p))
        occ.append(o)
        keep_idx.append(i)
    return {"rgb": torch.stack(rgb), "mask": torch.stack(mask), "coeff": torch.stack(coeff), "points": torch.stack(pts), "occ": torch.stack(occ), "keep": torch.tensor(keep_idx), "k": k}


def fourier_cache_path(root: Path, split: str, k: int, seg: Path | None = None, passes: int = 1) -> Path:
    """Where `fourier_cached` keeps a split's items."""
    if seg is None:
        return root / f"fourier-{split}-k{k}-v2.pt"
    from .seg_masks import model_tag, passes_tag

    return root / f"fourier-{split}-k{k}-seg-{model_tag(seg)}{passes_tag(passes)}-v1.pt"


def fourier_cached(root: Path, split: str, k: int, seg: Path | None = None, passes: int = 1):
    """`fourier_items` of a split, cached beside the shards; with `seg` (an ONNX segmentation
    model) the crops and mask channels come from its masks (seg_masks.predicted_masks, with
    `passes` segmentation passes: the engine's `segment_passes`)."""
    cache = fourier_cache_path(root, split, k, seg, passes)
    if cache.exists():
        return torch.load(cache)
    data = Split(root, split)
    masks = None
    if seg is not None:
        from .seg_masks import predicted_masks

        masks = predicted_masks(root, data, split, seg, passes)
    out = fourier_items(data, k, masks=masks)
    torch.save(out, cache)
    return out


def fourier_union(roots: list[Path], split: str, k: int, seg: Path | None = None, passes: int = 1):
    """`fourier_cached` of the same split of several datasets as one set of items, in the order
    given. Each dataset's cache is built (or read) on its own and memory-mapped, then copied
    into tensors sized for the union, so the peak is the union plus one dataset's pages, not
    two copies of everything (two 32-pose datasets hold ~10 GB of items). `keep` indexes the
    concatenated images."""
    if len(roots) == 1:
        return fourier_cached(roots[0], split, k, seg, passes)
    parts = []
    for r in roots:
        fourier_cached(r, split, k, seg, passes)  # builds the cache if missing
        parts.append(torch.load(fourier_cache_path(r, split, k, seg, passes), mmap=True))
    out = {"k": k}
    for name, v in parts[0].items():
        if not torch.is_tensor(v):
            continue
        shapes = {tuple(p[name].shape[1:]) for p in parts}
        if len(shapes) != 1:
            raise ValueError(f"{name}: the datasets {', '.join(map(str, roots))} disagree on its shape per item ({sorted(shapes)})")
        t = torch.empty((sum(len(p[name]) for p in parts), *v.shape[1:]), dtype=v.dtype)
        at, offset = 0, 0
        for p in parts:
            t[at : at + len(p[name])] = p[name] + offset if name == "keep" else p[name]
            at += len(p[name])
            offset += len(p["rgb"])
        out[name] = t
    return out


UPPER_KEEP = (0.3, 0.75)


def upper_keep(i: int) -> float:
    """The kept fraction of image `i` of the upper-body variant: drawn in UPPER_KEEP, seeded by
    the index, so a cache and the masks made for it agree."""
    lo, hi = UPPER_KEEP
    return lo + (hi - lo) * float(torch.rand(1, generator=torch.Generator().manual_seed(1000 + i)))


def cut_images(split, keep) -> torch.Tensor:
    """[B, 3, H, W] in [0, 1]: each image of `split` as the upper-body variant shows it, every
    row below the cut (`cut_row` of its true mask at `keep(i)`) set to 0; an image without a
    person unchanged."""
    out = []
    for i in range(len(split)):
        image = split.rgb01(i)
        row = cut_row(split.mask01(i)[0], keep(i))
        out.append(truncate_below(image, row) if row is not None else image)
    return torch.stack(out)


def cut_masks(split, keep, segmenter) -> torch.Tensor:
    """u8 [B, 1, H, W]: the product's masks of the cut images (`cut_images`), as the engine
    segments a frame whose lower edge cuts the person. `segmenter`: [B, 3, H, W] in [0, 1] ->
    [B, H, W] soft masks of the most prominent person (`seg_masks.product_masks`)."""
    from .seg_masks import as_u8

    return as_u8(segmenter(cut_images(split, keep)))


def fourier_upper_cached(root: Path, split: str, k: int, every: int = 2, seg: Path | None = None, passes: int = 1):
    """The upper-body variant (fourier_items `keep`) of every `every`-th image of a split, the
    kept fraction drawn per image in UPPER_KEEP (`upper_keep`), cached. With `seg` (an ONNX
    segmentation model) the crops and mask channels come from its masks of the cut images,
    `passes` passes (`cut_masks`), as the engine makes them on such a frame; without it, from
    the true masks cut (what runs (77)-(82) of the close-range model trained on)."""
    if seg is None:
        cache = root / f"fourier-{split}-k{k}-upper{every}-v1.pt"
    else:
        from .seg_masks import model_tag, passes_tag

        cache = root / f"fourier-{split}-k{k}-upper{every}-seg-{model_tag(seg)}{passes_tag(passes)}-v1.pt"
    if cache.exists():
        return torch.load(cache)
    sp = Split(root, split)
    sub = Subset(sp, list(range(0, len(sp), every)))
    masks = None
    if seg is not None:
        from .seg_masks import product_masks

        masks = cut_masks(sub, upper_keep, lambda images: product_masks(seg, images, passes))
    out = fourier_items(sub, k, keep=upper_keep, masks=masks)
    torch.save(out, cache)
    return out


class Subset:
    """Every listed image of a Split, with the accessors fourier_items reads."""

    def __init__(self, split: Split, idx: list):
        self.split, self.idx = split, idx
        self.image = split.image
        self.files = [split.files[i] for i in idx]
        self.points = split.points[idx]
        self.occ = split.occ[idx]
        self.ray_z = [split.ray_z[i] for i in idx]
        self.ray_offsets = [split.ray_offsets[i] for i in idx]

    def __len__(self):
        return len(self.idx)

    def mask01(self, i):
        return self.split.mask01(self.idx[i])

    def rgb01(self, i):
        return self.split.rgb01(self.idx[i])
