"""Estimated masks against ground truth: IoU per kind, and a dataset copy with its masks hidden.

Why: ``ns2gs-data masks`` estimates sky / ground / transient masks for real captures; the
synthetic street has exact ones, so estimating them on a copy without ``masks/`` (and without the
per-frame mask and depth keys) and comparing measures each kind. ``ns2gs-bench real`` reuses
:func:`mask_iou` and :func:`dataset_mask_iou`.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Optional, Union

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.data.masks.maskless import MASK_KEYS, strip_frame_keys
from nerf2gs_plugin.errors import DataError

ArrayLike = Union[Tensor, np.ndarray]
_HIDDEN_KEYS = MASK_KEYS + ("depth_file_path",)


def iou_counts(pred: ArrayLike, gt: ArrayLike) -> tuple[int, int]:
    """(intersection, union) pixel counts of two bool masks of the same shape."""
    p = torch.as_tensor(np.asarray(pred) if not isinstance(pred, Tensor) else pred).bool()
    g = torch.as_tensor(np.asarray(gt) if not isinstance(gt, Tensor) else gt).bool()
    if p.shape != g.shape:
        raise ValueError(f"mask shapes differ: {tuple(p.shape)} vs {tuple(g.shape)}")
    return int((p & g).sum()), int((p | g).sum())


def mask_iou(pred: ArrayLike, gt: ArrayLike) -> float:
    """Intersection over union of two bool masks; 1.0 when both are empty (nothing to find, nothing found)."""
    inter, union = iou_counts(pred, gt)
    return 1.0 if union == 0 else inter / union


def dataset_mask_iou(pred_root: Path, gt_root: Path, names: Optional[list[str]] = None,
                     kinds: tuple[str, ...] = MASK_KINDS) -> dict[str, Optional[float]]:
    """Pooled IoU per kind over images: ``pred_root/masks/<kind>/<name>.png`` vs the same under
    ``gt_root`` (pixel counts summed over all images, so small images do not dominate). ``names``
    (stems) defaults to every GT mask of the kind; a kind with no GT masks is None."""
    from nerf2gs_plugin.data.images import load_mask

    out: dict[str, Optional[float]] = {}
    for kind in kinds:
        gt_dir = Path(gt_root) / "masks" / kind
        stems = names if names is not None else sorted(p.stem for p in gt_dir.glob("*.png"))
        if not stems:
            out[kind] = None
            continue
        inter = union = 0
        for s in stems:
            pred_file = Path(pred_root) / "masks" / kind / f"{s}.png"
            if not pred_file.is_file():
                raise DataError(f"no estimated {kind} mask for {s}", pred_file)
            i, u = iou_counts(load_mask(pred_file), load_mask(gt_dir / f"{s}.png"))
            inter, union = inter + i, union + u
        out[kind] = 1.0 if union == 0 else inter / union
    return out


def hide_ground_truth(src: Path, dst: Path) -> Path:
    """A copy of the nerfstudio dataset ``src`` at ``dst`` as a real capture would arrive: images,
    points and poses, but no ``masks/``, no depth, and no per-frame mask/depth keys."""
    src, dst = Path(src), Path(dst)
    meta_path = src / "transforms.json"
    if not meta_path.is_file():
        raise DataError("hide_ground_truth needs a transforms.json dataset", src)
    meta = json.loads(meta_path.read_text())
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for item in src.iterdir():
        if item.name in ("masks", "depth", "transforms.json") or item.name.startswith("."):
            continue
        (shutil.copytree if item.is_dir() else shutil.copy2)(item, dst / item.name)

    atomic_write_text(dst / "transforms.json", json.dumps(strip_frame_keys(meta, _HIDDEN_KEYS), indent=1))
    return dst
