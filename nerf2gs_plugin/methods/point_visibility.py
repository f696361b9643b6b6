"""Which training pixels see which sparse (SfM) point, and how far away: the targets of a sparse-point
depth loss (StreetNeRF's ``point_depth``, Splatfacto's ``depth_loss_weight``).

A ``.ply`` has no tracks, so visibility is estimated from the points themselves: a point counts as
seen by a camera when it projects inside the image and is within ``tolerance`` of the nearest point
in its ``cell`` x ``cell`` pixel block (a coarse point z-buffer; occluders without points are missed,
which a bounded loss tolerates).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras, RayBundle


@dataclass
class PointRays:
    """One row per (camera, visible point): the pixel to cast and the point's distance along it."""

    rays: RayBundle  # [N] rays through the pixel centres (camera_indices says whose)
    coords: Tensor  # [N, 2] long pixel (u, v)
    t_star: Tensor  # [N] distance from the camera centre to the point along the pixel's unit ray

    @property
    def camera_indices(self) -> Tensor:
        return self.rays.camera_indices

    def __len__(self) -> int:
        return int(self.t_star.shape[0])


@torch.no_grad()
def visible_point_rays(cameras: Cameras, points: Tensor, cell: int = 8, tolerance: float = 0.1,
                       min_depth: float = 1e-3) -> PointRays:
    """Every (camera, point) pair where ``points [P, 3]`` (normalised world) is visible; see the module doc."""
    bundles, uvs, ts = [], [], []
    points = points.float().to(cameras.device)
    for i in range(len(cameras)):  # one vectorised projection per camera
        uv, z = cameras.project(points, i)
        w, h = int(cameras.width[i]), int(cameras.height[i])
        u, v = uv[:, 0].floor().long(), uv[:, 1].floor().long()
        inside = (z > min_depth) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        if not bool(inside.any()):
            continue
        idx = inside.nonzero().squeeze(1)
        u, v, z = u[idx], v[idx], z[idx]
        ncols = (w + cell - 1) // cell
        block = (v // cell) * ncols + (u // cell)
        nearest = torch.full(((h + cell - 1) // cell * ncols,), float("inf"), device=z.device)
        nearest = nearest.scatter_reduce(0, block, z, reduce="amin")
        keep = z <= nearest[block] * (1.0 + tolerance)
        idx, u, v = idx[keep], u[keep], v[keep]
        coords = torch.stack([u, v], dim=-1)
        rays = cameras.generate_rays(torch.full((len(idx),), i, dtype=torch.long, device=z.device), coords)
        t = ((points[idx] - rays.origins) * rays.directions).sum(-1)
        bundles.append(rays)
        uvs.append(coords)
        ts.append(t)
    if not bundles:
        empty = torch.zeros(0, 3, device=points.device)
        return PointRays(RayBundle(empty, empty, torch.zeros(0, 1, device=points.device), torch.zeros(0, dtype=torch.long, device=points.device)),
                         torch.zeros(0, 2, dtype=torch.long), torch.zeros(0))
    rays = RayBundle(*(torch.cat([getattr(b, k) for b in bundles]) for k in ("origins", "directions", "pixel_radius", "camera_indices")))
    return PointRays(rays, torch.cat(uvs), torch.cat(ts))
