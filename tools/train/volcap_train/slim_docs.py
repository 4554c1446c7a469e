"""Keep the committed reports small: the working tree travels to a lent GPU machine whole, and
the device tool takes at most 64 MiB with what a call carries (the packed `volcap`, ~12 MiB).

  python -m volcap_train.slim_docs PATH... [--pack-json [--md DIR...]] [--dry-run]

- Every PNG under the PATHs becomes a 256-colour palette PNG: the palette by median cut, the
  pixels Floyd-Steinberg dithered onto it (plots keep their colours exactly, renders and photos
  lose no visible detail); an image with transparency keeps its alpha through an octree
  palette. A file is rewritten only when that saves at least `--min-gain` of its bytes, so a
  second pass changes nothing.
- With `--pack-json`, every `eval.json` under the PATHs becomes `eval.json.xz` (reports of
  `volcap eval` kept for `compare_evals`, which reads either), and a Markdown link to a packed
  file (in the .md files under the PATHs, or under each `--md DIR`) is pointed at the `.xz`.

Prints each PATH's bytes before and after. Run it on new report folders before committing them
(docs/eval/hands.md says which folders are kept packed).
"""
from __future__ import annotations

import argparse
import io
import lzma
import re
from pathlib import Path

from PIL import Image

LINK = re.compile(r"\]\(([^)\s]*eval\.json)\)")


def palette_png(data: bytes) -> bytes:
    """The image as a palette PNG (see the module's text)."""
    im = Image.open(io.BytesIO(data))
    im.load()
    if im.mode == "P":
        return data
    if im.mode in ("RGBA", "LA") and im.getchannel("A").getextrema()[0] < 255:
        q = im.convert("RGBA").quantize(256, method=Image.Quantize.FASTOCTREE)
    else:
        rgb = im.convert("RGB")
        pal = rgb.quantize(256, method=Image.Quantize.MEDIANCUT)
        q = rgb.quantize(palette=pal, dither=Image.Dither.FLOYDSTEINBERG)
    out = io.BytesIO()
    q.save(out, "PNG", optimize=True)
    return out.getvalue()


def slim_png(path: Path, min_gain: float, dry: bool) -> tuple[int, int]:
    """(bytes before, bytes after) of one PNG, rewritten when it pays."""
    data = path.read_bytes()
    try:
        small = palette_png(data)
    except (OSError, ValueError) as e:  # PIL's UnidentifiedImageError is an OSError
        raise SystemExit(f"{path}: not a PNG that can be read ({e})") from e
    if len(small) > len(data) * (1.0 - min_gain):
        return len(data), len(data)
    if not dry:
        path.write_bytes(small)
    return len(data), len(small)


def pack_json(path: Path, dry: bool) -> tuple[int, int]:
    """(bytes before, bytes after) of one eval.json packed into eval.json.xz beside it."""
    data = path.read_bytes()
    packed = lzma.compress(data, preset=9 | lzma.PRESET_EXTREME)
    if not dry:
        path.with_name(path.name + ".xz").write_bytes(packed)
        path.unlink()
    return len(data), len(packed)


def relink(md: Path, dry: bool) -> int:
    """Points links to packed eval.json files at their .xz; the number of links changed."""
    text = md.read_text()
    changed = 0

    def sub(m: re.Match) -> str:
        nonlocal changed
        target = m.group(1)
        local = (md.parent / target)
        if "://" in target or local.exists() or not local.with_name(local.name + ".xz").exists():
            return m.group(0)
        changed += 1
        return f"]({target}.xz)"

    new = LINK.sub(sub, text)
    if changed and not dry:
        md.write_text(new)
    return changed


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="+", type=Path)
    ap.add_argument("--pack-json", action="store_true", help="pack every eval.json into eval.json.xz")
    ap.add_argument("--md", nargs="+", type=Path, default=None, help="folders whose .md links to packed files are fixed (default: the PATHs)")
    ap.add_argument("--min-gain", type=float, default=0.1, help="rewrite a PNG only when this share of its bytes is saved")
    ap.add_argument("--dry-run", action="store_true")
    a = ap.parse_args(argv)
    for root in a.paths:
        if not root.exists():
            raise SystemExit(f"{root}: no such file or folder")
        files = [root] if root.is_file() else sorted(root.rglob("*"))
        before = after = 0
        for f in files:
            if f.suffix == ".png":
                b, s = slim_png(f, a.min_gain, a.dry_run)
            elif a.pack_json and f.name == "eval.json":
                b, s = pack_json(f, a.dry_run)
            else:
                continue
            before, after = before + b, after + s
        print(f"{root}: {before / 2**20:.2f} -> {after / 2**20:.2f} MiB{' (dry run)' if a.dry_run else ''}")
    if a.pack_json:
        links = 0
        for d in a.md or a.paths:
            for md in [d] if d.is_file() else sorted(d.rglob("*.md")):
                if md.suffix == ".md":
                    links += relink(md, a.dry_run)
        print(f"{links} links pointed at packed reports")


if __name__ == "__main__":
    main()
