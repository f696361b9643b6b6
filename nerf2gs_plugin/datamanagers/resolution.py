"""Coarse to fine: a training view and its batch at ``1/d`` of their resolution (nerfstudio's splatfacto
``num_downscales`` / ``resolution_schedule``: the first steps shape the scene on small images, fast)."""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
import torch.nn.functional as F

from nerf2gs_plugin.cameras import Cameras


def downscale_at(step: int, num_downscales: int, schedule: int) -> int:
    """The factor at ``step``: ``2^num_downscales`` for the first ``schedule`` steps, halved every ``schedule`` steps."""
    if num_downscales <= 0 or schedule <= 0:
        return 1
    return 2 ** max(num_downscales - step // schedule, 0)


def _area(x: torch.Tensor, d: int, h: int, w: int) -> torch.Tensor:
    """``[H, W, C]`` -> ``[h, w, C]``: the mean of each ``d x d`` block (the rows and columns past ``h*d``, ``w*d`` dropped)."""
    blocks = x[: h * d, : w * d].float().permute(2, 0, 1)[None]
    return F.avg_pool2d(blocks, d)[0].permute(1, 2, 0)


def downscaled(camera: Cameras, batch: dict[str, Any], d: int) -> tuple[Cameras, dict[str, Any]]:
    """One view (``camera``, one camera) and its ``batch`` at ``1/d``: every ``[H, W, C]`` tensor of the view's size
    averaged over ``d x d`` blocks (a boolean mask: where most of the block is set), the intrinsics scaled by
    ``1/d`` (pixel ``i`` of the small image covers pixels ``i*d .. i*d + d - 1``); anything else as it is."""
    if d == 1:
        return camera, batch
    big_h, big_w = int(camera.height[0]), int(camera.width[0])
    h, w = big_h // d, big_w // d
    small = dataclasses.replace(camera.scaled(1.0 / d), width=torch.full_like(camera.width, w),
                                height=torch.full_like(camera.height, h))
    out: dict[str, Any] = {}
    for key, value in batch.items():
        if isinstance(value, torch.Tensor) and value.ndim == 3 and tuple(value.shape[:2]) == (big_h, big_w):
            mean = _area(value, d, h, w)
            value = mean > 0.5 if value.dtype == torch.bool else mean.to(value.dtype)
        out[key] = value
    return small, out
