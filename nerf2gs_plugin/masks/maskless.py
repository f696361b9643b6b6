"""A dataset's masks taken away: per-frame mask keys stripped from ``transforms.json``, and a
mask-less view of a dataset folder (what the ``--segmenter auto`` reference trains on).

Why without masks: the masks are what is being estimated; a reference trained on stale or partial
masks would only reproduce them. The dataset may already hold masks (a second run with
``--overwrite``), so the reference trains on a sibling folder of symlinks to everything but
``masks/`` (and, for ``transforms.json``, a copy without the per-frame mask keys). Training images
are the same files, so the dataset fingerprint is the same.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterable

from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.utils.io import atomic_write_text

VIEW_DIRNAME = ".ns2gs_maskless"
SECOND_PASS_DIRNAME = ".ns2gs_second_pass"  # the motion route's second pass: the first pass's transient masks only
MASK_KEYS = tuple(f"{k}_mask_path" for k in MASK_KINDS)
_SKIP = {"masks", ".ns2gs_cache", VIEW_DIRNAME, SECOND_PASS_DIRNAME}


def strip_frame_keys(meta: dict, keys: Iterable[str] = MASK_KEYS) -> dict:
    """``meta`` (a transforms.json document) with ``keys`` removed from every frame, eval splits included."""
    keys = set(keys)

    def strip(fr: object) -> object:
        return {k: v for k, v in fr.items() if k not in keys} if isinstance(fr, dict) else fr

    out = dict(meta)
    out["frames"] = [strip(f) for f in meta.get("frames", [])]
    if isinstance(meta.get("eval_splits"), dict):
        out["eval_splits"] = {k: [strip(f) for f in v] if isinstance(v, list) else v for k, v in meta["eval_splits"].items()}
    return out


def strip_mask_keys(data: Path) -> None:
    """Remove the per-frame mask keys from ``DATA/transforms.json`` in place (atomically)."""
    meta_file = Path(data) / "transforms.json"
    if meta_file.is_file():
        atomic_write_text(meta_file, json.dumps(strip_frame_keys(json.loads(meta_file.read_text())), indent=1))


def maskless_view(data: Path) -> Path:
    """``DATA/.ns2gs_maskless``: the dataset without its masks (symlinks; rebuilt every call)."""
    data = Path(data).resolve()
    view = data / VIEW_DIRNAME
    view.mkdir(exist_ok=True)
    for item in data.iterdir():
        if item.name in _SKIP or item.name == "transforms.json":
            continue
        link = view / item.name
        if link.is_symlink() or link.exists():
            if link.is_symlink() and os.readlink(link) == str(item):
                continue
            link.unlink()
        link.symlink_to(item)
    meta_file = data / "transforms.json"
    if meta_file.is_file():
        atomic_write_text(view / "transforms.json", json.dumps(strip_frame_keys(json.loads(meta_file.read_text())), indent=1))
    return view
