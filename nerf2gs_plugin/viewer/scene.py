"""What the viewer draws besides the render: output colouring, camera frustums and thumbnails,
and the bird's-eye additional views of an augmented run (read from the augment cache manifest)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.render.colorize import colorize, to_uint8  # noqa: F401  (colorize: the viewer's modes)
from nerf2gs_plugin.utils.resize import area_resize

# Colour code of the paper's Fig. 1: red input views, green additional views; eval views as in its
# dataset figure (yellow bird's-eye evaluation views).
INPUT_VIEW_COLOR = (220, 50, 40)
EXTRA_VIEW_COLOR = (40, 175, 70)
EVAL_COLORS = {"street": (60, 130, 235), "bev_1": (235, 200, 30), "bev_2": (245, 140, 20)}
OTHER_EVAL_COLOR = (150, 150, 160)
RENDER_MODES = ("rgb", "depth", "accumulation", "normals")


def available_modes(outputs: dict[str, Tensor]) -> list[str]:
    """The render modes a method's ``render_camera`` output supports, in menu order."""
    return [m for m in RENDER_MODES if m in outputs]


def thumbnail(image: Tensor, max_side: int) -> np.ndarray:
    """``[H, W, 3]`` float image -> ``uint8`` with its long side at most ``max_side`` (area filter)."""
    h, w = image.shape[:2]
    s = min(1.0, max_side / max(h, w))
    if s < 1.0:
        size = (max(1, round(h * s)), max(1, round(w * s)))
        image = area_resize(image, size)
    return to_uint8(image)


def frustum_scale(centers: Tensor) -> float:
    """A frustum size that neither hides nor clutters: a third of the median nearest-neighbour
    spacing of the cameras, between 1% and 5% of their extent."""
    c = centers.detach().float().cpu()
    if len(c) < 2:
        return 0.1
    d = torch.cdist(c, c)
    d.fill_diagonal_(float("inf"))
    nn = d.min(dim=1).values
    extent = float((c.max(0).values - c.min(0).values).norm())
    return max(min(float(nn[torch.isfinite(nn)].median()) / 3.0, 0.05 * extent), 0.01 * extent, 1e-3)


@dataclass
class ExtraViews:
    """The additional views of an augmented run (every view family's)."""

    cameras: Cameras
    thumbnails: list[Optional[np.ndarray]]
    source: str  # the manifest they were read from, or how they were computed


def find_extra_views(config, train_data, train_cameras: Cameras, thumb_side: int = 96) -> Optional[ExtraViews]:
    """The additional views a run was trained with (``None`` for a run without ``--augment-from``).

    Read from the reference run's augment cache (:func:`find_cached_extra_views`, the one manifest
    reader): the poses the manifest saved, with the rendered views as thumbnails. When the cache is
    gone (it lives under the reference run, which may be moved or cleaned), the views are made again
    from the run's config by the one geometry the augmentation uses.
    """
    from nerf2gs_plugin.augment.cache import load_png
    from nerf2gs_plugin.augment.datamanager import find_cached_extra_views
    from nerf2gs_plugin.augment.views import additional_views
    from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint, resolve_checkpoint
    from nerf2gs_plugin.errors import UserError

    aug = config.augment
    if config.augment_from is None or not aug.extra_views:
        return None
    made = additional_views(train_cameras, train_data, aug)  # every family's cameras, as the augmentation makes them
    if made is None:
        return None
    sub = made.cameras
    try:
        ref_dir, _ = resolve_checkpoint(Path(config.augment_from))
    except UserError:
        ref_dir = None
    manifest = (find_cached_extra_views(ref_dir, dataset_fingerprint(train_data.image_filenames), aug, len(sub))
                if ref_dir is not None else None)
    if manifest is not None:
        thumbs: list[Optional[np.ndarray]] = []
        for j in range(manifest.num_extra):
            png = manifest.extra_png(j)
            thumbs.append(thumbnail(load_png(png), thumb_side) if png.is_file() else None)
        return ExtraViews(sub[torch.tensor(manifest.extra_indices, dtype=torch.long)].with_poses(manifest.extra_poses().to(sub.device)),
                          thumbs, str(manifest.path))
    return ExtraViews(sub, [None] * len(sub), "recomputed from the run's --augment config (no cache manifest found)")
