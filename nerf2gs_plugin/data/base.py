"""What both parsers share: a raw frame, mask discovery, and frames -> DataparserOutputs."""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.normalize import NormalizeOptions, compute_transform
from nerf2gs_plugin.data.undistort import Intrinsics, SplitCache, output_intrinsics, process_depth, process_image, process_mask
from nerf2gs_plugin.errors import DataError

MASK_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass
class RawFrame:
    """One image as the data file describes it (original frame, possibly distorted)."""

    image: Path
    c2w: Tensor  # [3, 4] OpenGL camera-to-world, original data frame
    intr: Intrinsics
    masks: dict[str, Optional[Path]] = field(default_factory=dict)
    depth: Optional[Path] = None
    depth_png_scale: float = 1e-3


def find_folder_mask(root: Path, kind: str, image: Path) -> Optional[Path]:
    """``masks/<kind>/<image stem>.png`` (or another image extension) when it exists."""
    folder = root / "masks" / kind
    if not folder.is_dir():
        return None
    for ext in MASK_EXTS:
        p = folder / f"{image.stem}{ext}"
        if p.is_file():
            return p
    return None


def check_split(name: str, frames: list[RawFrame], available: list[str], path: Path) -> None:
    if name not in available:
        raise DataError(f"unknown split '{name}' (this dataset has: {', '.join(available)})", path)
    if not frames:
        raise DataError(f"split '{name}' is empty", path)


def build_outputs(
    split: str,
    frames: list[RawFrame],
    train_frames: list[RawFrame],
    root: Path,
    options: NormalizeOptions,
    downscale: float,
    declared_up: Optional[Tensor] = None,
    metres_per_unit: float = 1.0,
    points_xyz: Optional[np.ndarray] = None,
    points_rgb: Optional[np.ndarray] = None,
    cache_dir: Optional[Path] = None,
) -> DataparserOutputs:
    """Normalise (from the train frames), undistort/downscale through the cache (under ``cache_dir``
    when given, see :class:`~nerf2gs_plugin.data.undistort.SplitCache`), and package."""
    if not (math.isfinite(downscale) and downscale > 0):  # nan compares false with everything
        raise DataError(f"downscale must be a positive finite number, got {downscale}", root)
    pts = torch.from_numpy(np.asarray(points_xyz, dtype=np.float32)) if points_xyz is not None else None
    tf = compute_transform(torch.stack([f.c2w for f in train_frames]), options, declared_up, metres_per_unit, pts)
    needs_cache = downscale != 1.0 or any(f.intr.distorted for f in frames) or any(
        f.depth is not None and f.depth.suffix.lower() not in (".npy", ".npz") for f in frames
    )
    cache = SplitCache(root, cache_dir) if needs_cache else None

    images: list[Path] = []
    masks: dict[str, list[Optional[Path]]] = {k: [] for k in MASK_KINDS if any(f.masks.get(k) for f in frames)}
    depths: list[Optional[Path]] = []
    intrs: list[Intrinsics] = []
    for f in frames:
        img = process_image(cache, f.image, f.intr, downscale) if cache else _existing(f.image, "image")
        images.append(img)
        intrs.append(output_intrinsics(f.intr, downscale))
        for kind in masks:
            m = f.masks.get(kind)
            if m is not None:
                m = process_mask(cache, m, f.intr, downscale, f.image) if cache else _existing(m, "mask")
            masks[kind].append(m)
        d = f.depth
        if d is not None:
            d = process_depth(cache, d, f.intr, downscale, f.image, f.depth_png_scale) if cache else _existing(d, "depth")
        depths.append(d)

    c2w = tf.apply_poses(torch.stack([f.c2w for f in frames]).float())
    cams = Cameras(
        camera_to_worlds=c2w,
        fx=torch.tensor([i.fx for i in intrs]),
        fy=torch.tensor([i.fy for i in intrs]),
        cx=torch.tensor([i.cx for i in intrs]),
        cy=torch.tensor([i.cy for i in intrs]),
        width=torch.tensor([i.width for i in intrs]),
        height=torch.tensor([i.height for i in intrs]),
    )
    return DataparserOutputs(
        image_filenames=images,
        cameras=cams,
        mask_filenames=masks,
        depth_filenames=depths if any(d is not None for d in depths) else None,
        points3D_xyz=tf.apply_points(pts) if pts is not None else None,
        points3D_rgb=torch.from_numpy(np.asarray(points_rgb, dtype=np.uint8)) if points_rgb is not None else None,
        scene_box=tf.scene_box,
        dataparser_transform=tf.transform,
        dataparser_scale=tf.scale,
        metres_per_unit=tf.metres_per_unit,
        up=tf.up,
        split=split,  # the image files above are already at the requested downscale
    )


def _existing(p: Path, what: str) -> Path:
    if not p.is_file():
        raise DataError(f"{what} file does not exist", p)
    return p
