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


def file_sha1(path: Path) -> str:
    """SHA-1 of a whole file's content (a file replaced under the same name, size and time differs)."""
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


SMALL_FILE = 1 << 18  # files up to 256 KiB are hashed whole; bigger ones by size, mtime and both ends
_EDGE = 1 << 16


def cheap_file_digest(path: Path) -> bytes:
    """Content of a small file; size + mtime + first/last 64 KiB of a big one (cheap, still catches
    a rewrite). A missing file digests as ``missing``."""
    h = hashlib.sha1()
    try:
        st = path.stat()
        h.update(str(st.st_size).encode())
        with open(path, "rb") as f:
            if st.st_size <= SMALL_FILE:
                h.update(f.read())
            else:
                h.update(str(st.st_mtime_ns).encode())
                h.update(f.read(_EDGE))
                f.seek(-_EDGE, 2)
                h.update(f.read(_EDGE))
    except OSError:
        h.update(b"missing")
    return h.digest()


def files_fingerprint(files: list[Path], root: Path) -> str:
    """Fingerprint of every file a run reads (names relative to ``root``, so a moved copy of a
    dataset of small files keeps it)."""
    h = hashlib.sha1()
    root = Path(root).resolve()
    for p in sorted({Path(f).resolve() for f in files}):
        try:
            name = str(p.relative_to(root))
        except ValueError:
            name = str(p)
        h.update(name.encode() + b"\0" + cheap_file_digest(p))
    return h.hexdigest()[:16]


def file_hash(path: Path) -> str:
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]
