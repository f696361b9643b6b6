"""The exact optical flow between two training frames of the street (a yardstick for flow-based
motion masks): each pixel's centre ray hits a point of the static street or of a moving box at its
frame's time; the point moves with its object (boxes only translate) to the other frame's time and is
projected into that camera. Valid where the point is in front of that camera, inside its image and
seen there (the other frame's centre ray at that pixel hits the same object at the same distance).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from nerf2gs_plugin.data.synthetic.layout import Boxes, StreetLayout
from nerf2gs_plugin.data.synthetic.raycast import Pinhole, camera_rays, centre_hits

_NEAR = 0.05
_SEEN_REL, _SEEN_ABS = 0.05, 0.1  # "seen": the nearest pixel's centre ray lands up to half a pixel off (grazing road: 3% at 40 m)


@dataclass
class FrameHits:
    """One frame: camera ``c2w [3, 4]``, its moving boxes (``movers.frame_boxes``), and its centre
    rays' distance ``[H, W]`` (inf: sky) and object ids ``[H, W]`` (``raycast.centre_hits``)."""

    c2w: Tensor
    moving: Boxes
    dist: Tensor
    obj: Tensor


def trace_frame(layout: StreetLayout, c2w: Tensor, intr: Pinhole, moving: Boxes) -> FrameHits:
    """``c2w``'s centre rays over the static street plus ``moving``."""
    dist, obj = centre_hits(layout, c2w, intr, moving)
    return FrameHits(c2w.float(), moving, dist, obj)


def _shifts(layout: StreetLayout, a: FrameHits, b: FrameHits) -> Tensor:
    """``[B + S + 2, 3]`` how far each object moves from ``a``'s time to ``b``'s (indexed by object id
    + 2: sky, ground plane, boxes, crowns); only the moving boxes move."""
    n_static, n_moving, n_crowns = len(layout.static), len(a.moving), len(layout.crowns.radius)
    if len(b.moving) != n_moving:
        raise ValueError(f"frames differ in their moving boxes ({n_moving} vs {len(b.moving)})")
    shift = torch.zeros(2 + n_static + n_moving + n_crowns, 3)
    shift[2 + n_static:2 + n_static + n_moving] = (b.moving.lo + b.moving.hi - a.moving.lo - a.moving.hi) / 2
    return shift


def exact_flow(layout: StreetLayout, intr: Pinhole, a: FrameHits, b: FrameHits) -> tuple[Tensor, Tensor]:
    """The flow ``[H, W, 2]`` (pixels, x then y) from frame ``a`` to frame ``b`` (0 for the sky and
    behind ``b``; hidden points and those outside ``b`` keep theirs) and where it is valid ``[H, W]``
    (not sky, in front of ``b``, inside it and not hidden there)."""
    h, w = a.dist.shape
    ray = camera_rays(a.c2w, intr, 1)[0]
    finite = torch.isfinite(a.dist)
    p = a.c2w[:, 3] + ray * torch.where(finite, a.dist, torch.zeros_like(a.dist))[..., None]
    q = p + _shifts(layout, a, b)[a.obj + 2]
    cam = (q - b.c2w[:, 3]) @ b.c2w[:, :3]
    z = -cam[..., 2]
    zs = z.clamp(min=_NEAR)
    x, y = intr.fx * cam[..., 0] / zs + intr.cx, intr.cy - intr.fy * cam[..., 1] / zs
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float32) + 0.5, torch.arange(w, dtype=torch.float32) + 0.5, indexing="ij")
    inside = finite & (z > _NEAR) & (x >= 0) & (x < w) & (y >= 0) & (y < h)
    col, row = x.floor().long().clamp(0, w - 1), y.floor().long().clamp(0, h - 1)
    there = (q - b.c2w[:, 3]).norm(dim=-1)
    seen = (b.obj[row, col] == a.obj) & ((b.dist[row, col] - there).abs() <= _SEEN_REL * there + _SEEN_ABS)
    flow = torch.stack([x - u, y - v], dim=-1)
    return torch.where((finite & (z > _NEAR))[..., None], flow, torch.zeros_like(flow)), inside & seen
