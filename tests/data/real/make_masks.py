"""Rasterize the hand-drawn person polygons of masks.json into NAME.mask.png (0 / 255).

    python make_masks.py        (needs Pillow; run from this folder)
"""

import json
from pathlib import Path

from PIL import Image, ImageDraw

here = Path(__file__).parent
spec = json.loads((here / "masks.json").read_text())
for name, poly in spec["masks"].items():
    src = next(p for p in (here / f"{name}.jpg", here / f"{name}.png") if p.exists())
    size = Image.open(src).size
    m = Image.new("L", size, 0)
    ImageDraw.Draw(m).polygon([tuple(p) for p in poly], fill=255)
    m.save(here / f"{name}.mask.png")
