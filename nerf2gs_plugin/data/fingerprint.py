"""Identify a dataset and a file by content, not location (used by checkpoints and caches)."""

from __future__ import annotations

import hashlib
from pathlib import Path


def dataset_fingerprint(image_filenames: list[Path]) -> str:
    """Training images' names, sizes and leading bytes: a moved copy keeps its fingerprint, a
    regenerated scene (other seed) does not."""
    h = hashlib.sha1()
    for p in image_filenames:
        p = Path(p)
        h.update(p.name.encode())
        try:
            h.update(str(p.stat().st_size).encode())
            with open(p, "rb") as f:
                h.update(f.read(4096))
        except OSError:
            h.update(b"missing")
    return h.hexdigest()[:16]


def file_hash(path: Path) -> str:
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]
