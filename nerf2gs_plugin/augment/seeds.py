"""Initial points for the target where only the additional views see the scene.

A splatting target grows new primitives only by cloning and splitting those it has: where the capture's
sparse points leave a surface uncovered (the road seen from above, which street-level SfM barely
triangulates), the views from above find nothing to densify, and a view-direction background learns the
ground's colour instead, so the target stays transparent there. The reference rendered a depth with each
additional view: lifted to world points, they say where those surfaces are. The points are thinned on a
voxel grid (one point, the mean of the pixels in it, per voxel that holds no sparse point), the grid as fine
as the count allows, so they fill the gaps the sparse points leave and no more.
"""

from __future__ import annotations

from typing import Any, Optional, Sequence

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.augment.confidence import inside_box, lift
from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.utils.voxels import unique_cells

MIN_SEED_BASE = 1000
"""The count of points ``--augment.seed-points`` multiplies when the capture has fewer sparse points."""
PIXEL_STRIDE = 2
"""Every this many pixels of a view of the input views' size (in each direction) are lifted: the grid thins
them far more anyway. A view rendered smaller (``--augment.view-downscale``) is lifted more densely, so that
the grid finds as many points on the same surfaces."""


def lifted_points(cameras: Cameras, depths: Sequence[Tensor], images: Sequence[Tensor], depth_along: str,
                  scene_box: Optional[Tensor] = None, stride: int = PIXEL_STRIDE) -> tuple[Tensor, Tensor]:
    """World points ``[P, 3]`` and colours ``[P, 3]`` (0-1) of every ``stride``-th pixel of each view
    (``depths`` ``[H, W, 1]``, ``images`` ``[H, W, 3]``), inside ``scene_box`` ``[2, 3]`` (what lies beyond it,
    the far background, is no place for a primitive)."""
    pts, cols = [], []
    for i in range(len(cameras)):
        d, img = depths[i].float(), images[i].float()
        h, w = d.shape[:2]
        keep = torch.zeros(h, w, dtype=torch.bool)
        keep[::stride, ::stride] = True
        keep &= torch.isfinite(d[..., 0]) & (d[..., 0] > 0)
        p = lift(d, cameras[i].to("cpu"), depth_along).float()[keep.reshape(-1)]
        pts.append(p)
        cols.append(img.reshape(-1, 3)[keep.reshape(-1)])
    xyz, rgb = torch.cat(pts), torch.cat(cols)
    inside = inside_box(xyz, scene_box)
    return xyz[inside], rgb[inside]


def thin_on_grid(xyz: Tensor, rgb: Tensor, occupied: Optional[Tensor], size: float) -> tuple[Tensor, Tensor]:
    """One point per voxel of edge ``size`` that holds lifted points and none of ``occupied`` ``[Q, 3]``: the
    mean position and colour of its points."""
    if len(xyz) == 0:
        return xyz, rgb
    both = xyz if occupied is None or len(occupied) == 0 else torch.cat([xyz, occupied.to(xyz)])
    cells = torch.floor((both - both.min(0).values) / size).long()
    _, inverse = unique_cells(cells)
    n_cells = int(inverse.max()) + 1
    taken = torch.zeros(n_cells, dtype=torch.bool)
    taken[inverse[len(xyz):]] = True
    ids = inverse[: len(xyz)]
    count = torch.zeros(n_cells).index_add_(0, ids, torch.ones(len(xyz)))
    mean_xyz = torch.zeros(n_cells, 3).index_add_(0, ids, xyz) / count.clamp_min(1)[:, None]
    mean_rgb = torch.zeros(n_cells, 3).index_add_(0, ids, rgb) / count.clamp_min(1)[:, None]
    new = (count > 0) & ~taken
    return mean_xyz[new], mean_rgb[new]


def seed_points(xyz: Tensor, rgb: Tensor, occupied: Optional[Tensor], max_points: int) -> tuple[Tensor, Tensor]:
    """At most ``max_points`` points from the lifted ``xyz``/``rgb``, on the finest voxel grid (edges doubling
    from 1/1024 of the points' extent) that leaves no more than that many voxels free of ``occupied``."""
    if max_points <= 0 or len(xyz) == 0:
        return xyz[:0], rgb[:0]
    size = float((xyz.max(0).values - xyz.min(0).values).max()) / 1024 or 1e-3
    while True:
        out = thin_on_grid(xyz, rgb, occupied, size)
        if len(out[0]) <= max_points:
            return out
        size *= 2.0


def views_seed_points(manifest: Any, extra: Any, depth_along: str, train_data: Any, ratio: float,
                      per_family: bool = False, view_downscale: int = 1) -> Optional[tuple[Tensor, Tensor]]:
    """:func:`seed_points` of a cache entry's additional views (``manifest``: their depths beside the raw
    renders; ``extra``: the ImageSet the target trains on), at most ``ratio`` x the dataset's sparse points
    (at least :data:`MIN_SEED_BASE`); None when the entry has no depths (a reference that renders none).
    ``per_family``: each family's views in turn on their own grid and budget, clear of the points before.
    ``view_downscale``: the views' size is 1/this of the input views' (see :data:`PIXEL_STRIDE`)."""
    depth_files = [manifest.extra_png(j, raw=True).with_name(f"{j:05d}_depth.npy") for j in range(manifest.num_extra)]
    if not depth_files or not all(f.is_file() for f in depth_files):
        return None
    images = [extra.image(j).cpu() for j in range(len(extra))]
    depths = [torch.from_numpy(np.load(f).astype(np.float32)).reshape(*img.shape[:2], 1) for f, img in zip(depth_files, images)]
    sparse = train_data.points3D_xyz.float().cpu() if train_data.points3D_xyz is not None else None
    budget = int(round(ratio * max(len(sparse) if sparse is not None else 0, MIN_SEED_BASE)))
    families = manifest.extra_families if per_family and manifest.extra_families else ["all"] * len(images)
    cams = extra.cameras.to("cpu")
    out_xyz, out_rgb, occupied = [], [], sparse
    for family in dict.fromkeys(families):
        ids = [j for j, f in enumerate(families) if f == family]
        xyz, rgb = lifted_points(cams[torch.tensor(ids)] if len(ids) < len(images) else cams, [depths[j] for j in ids],
                                 [images[j] for j in ids], depth_along, train_data.scene_box,
                                 max(1, PIXEL_STRIDE // max(int(view_downscale), 1)))
        pts, cols = seed_points(xyz, rgb, occupied, budget)
        out_xyz.append(pts)
        out_rgb.append(cols)
        occupied = pts if occupied is None else torch.cat([occupied, pts])
    return torch.cat(out_xyz), torch.cat(out_rgb)
