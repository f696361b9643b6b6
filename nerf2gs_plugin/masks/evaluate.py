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
from nerf2gs_plugin.masks.maskless import MASK_KEYS, strip_frame_keys
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


Pinhole = tuple[float, float, float, float]  # fx, fy, cx, cy (pixels)


def resample_mask(mask: Tensor, src: Pinhole, dst: Pinhole, dst_hw: tuple[int, int]) -> Tensor:
    """A mask seen by pinhole ``src`` resampled (nearest) onto the pixel grid of pinhole ``dst`` of
    size ``dst_hw``, the same camera pose: an undistorted frame has its own focal and size, and a
    plain resize would shift pixels by the difference of the principal points and the focal ratio.
    Pixels of ``dst`` outside ``src``'s image are False."""
    import torch.nn.functional as F

    h, w = dst_hw
    sh, sw = mask.shape
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64) + 0.5, torch.arange(w, dtype=torch.float64) + 0.5, indexing="ij")
    us = (u - dst[2]) / dst[0] * src[0] + src[2]  # src pixel coordinates of each dst pixel centre
    vs = (v - dst[3]) / dst[1] * src[1] + src[3]
    grid = torch.stack([2 * us / sw - 1, 2 * vs / sh - 1], dim=-1).float()[None]
    out = F.grid_sample(mask.float()[None, None], grid, mode="nearest", padding_mode="zeros", align_corners=False)
    return out[0, 0] > 0.5


def paired_mask_iou(pairs: list[tuple]) -> Optional[float]:
    """Pooled IoU over ``(estimated file, ground-truth file)`` pairs (pixel counts summed, so small
    images do not dominate). A pair may carry ``(est pinhole, gt pinhole)`` as a third item: the
    estimate is then resampled onto the GT's pixel grid (:func:`resample_mask`); without it an
    estimate of another size is resized (nearest). None without pairs."""
    import torch.nn.functional as F

    from nerf2gs_plugin.data.images import load_mask

    if not pairs:
        return None
    inter = union = 0
    for pair in pairs:
        pred_file, gt_file = pair[0], pair[1]
        if not Path(pred_file).is_file():
            raise DataError("no estimated mask", pred_file)
        pred, gt = load_mask(pred_file), load_mask(gt_file)
        if len(pair) > 2 and pair[2] is not None:
            pred = resample_mask(pred, pair[2][0], pair[2][1], tuple(gt.shape))
        elif pred.shape != gt.shape:
            pred = F.interpolate(pred.float()[None, None], size=tuple(gt.shape), mode="nearest")[0, 0] > 0.5
        i, u = iou_counts(pred, gt)
        inter, union = inter + i, union + u
    return 1.0 if union == 0 else inter / union


def dataset_mask_iou(pred_root: Path, gt_root: Path, names: Optional[list[str]] = None,
                     kinds: tuple[str, ...] = MASK_KINDS) -> dict[str, Optional[float]]:
    """Pooled IoU per kind (:func:`paired_mask_iou`): ``pred_root/masks/<kind>/<name>.png`` vs the
    same under ``gt_root``. ``names`` (stems) defaults to every GT mask of the kind; a kind with no
    GT masks is None."""
    out: dict[str, Optional[float]] = {}
    for kind in kinds:
        gt_dir = Path(gt_root) / "masks" / kind
        stems = names if names is not None else sorted(p.stem for p in gt_dir.glob("*.png"))
        out[kind] = paired_mask_iou([(Path(pred_root) / "masks" / kind / f"{s}.png", gt_dir / f"{s}.png") for s in stems])
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
