"""The golden vectors' files (`models/golden/NAME.safetensors.gz`): safetensors, gzipped.

Each holds the golden person's image and mask (mostly background) beside a few hundred query
values, so gzip takes a file from ~0.3 MB to ~0.04: twenty of them were 5.6 MB of the tracked
tree, which the device tool's 64 MiB carries with the packed binary
(tests/test_tree_size.py). Written byte-stable (no name and no time in the gzip header), so an
export that computes the same vectors writes the same bytes. The engine's tests read them with
flate2 (service/engine/tests/common, tools/volcap/tests/fourier_geometry.rs)."""
from __future__ import annotations

import gzip
import json
from pathlib import Path

from safetensors import SafetensorError
from safetensors.numpy import load, save

SUFFIX = ".safetensors.gz"


def golden_path(folder: Path, name: str) -> Path:
    """`folder/NAME.safetensors.gz`."""
    return Path(folder) / f"{name}{SUFFIX}"


def save_golden(tensors: dict, path: Path, metadata: dict | None = None) -> None:
    data = save(tensors, metadata=metadata)
    with open(path, "wb") as f, gzip.GzipFile(filename="", mode="wb", fileobj=f, compresslevel=9, mtime=0) as g:
        g.write(data)


def read_golden(path: Path) -> tuple[dict, dict]:
    """(tensors, metadata) of a golden file; a file that is not one is refused naming it."""
    try:
        raw = gzip.decompress(Path(path).read_bytes())
        n = int.from_bytes(raw[:8], "little")
        meta = json.loads(raw[8 : 8 + n]).get("__metadata__") or {}
        return load(raw), meta
    except (OSError, EOFError, ValueError, SafetensorError) as e:
        raise ValueError(f"{path}: not a gzipped safetensors golden file ({e})") from e


def load_golden(path: Path) -> dict:
    return read_golden(path)[0]
