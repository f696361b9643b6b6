"""Tile binning: which projected Gaussians touch which screen tile, front to back (vectorised torch).

Every (camera, Gaussian) pair with a non-zero radius is listed in each tile that its
``alpha >= 1/255`` ellipse (capped at 3 sigma) can reach; each tile's list is sorted by depth (stable: ties keep pair order, as in the C++ binning).
The result is a CSR layout shared by every compositing backend:
``tile_offsets [C*TY*TX + 1]`` (int64) and ``flat_ids [M]`` (int64 indices into the flattened
``C*N`` pairs), where tile ``t = (c * TY + ty) * TX + tx``.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor


def tile_grid(width: int, height: int, tile_size: int) -> tuple[int, int]:
    """Number of tiles ``(TX, TY)`` covering a ``width x height`` image."""
    return math.ceil(width / tile_size), math.ceil(height / tile_size)


@torch.no_grad()
def bin_gaussians(
    means2d: Tensor, cov2d: Tensor, opacities: Tensor, depths: Tensor, radii: Tensor,
    width: int, height: int, tile_size: int,
) -> tuple[Tensor, Tensor]:
    """CSR per-tile depth-sorted lists for ``C`` cameras and ``N`` Gaussians.

    Args:
        means2d: ``[C, N, 2]`` pixel coordinates.
        cov2d: ``[C, N, 2, 2]`` 2D covariances (with the low-pass term).
        opacities: ``[C, N]`` opacities as composited (after antialiasing compensation).
        depths: ``[C, N]`` camera-space z (sort key).
        radii: ``[C, N]`` int, 0 for culled pairs.
    Returns:
        ``tile_offsets [C*TY*TX + 1]`` and ``flat_ids [M]`` (both int64).
    """
    n_cams, n = depths.shape
    tx_n, ty_n = tile_grid(width, height, tile_size)
    dev = means2d.device
    # half-extents of the ellipse sigma <= s with s = min(ln(255 o), 4.5) (alpha < 1/255 beyond)
    s = torch.log((opacities * 255.0).clamp_min(1.0)).clamp_max(4.5)
    ex = torch.sqrt((2.0 * s * cov2d[..., 0, 0]).clamp_min(0.0))
    ey = torch.sqrt((2.0 * s * cov2d[..., 1, 1]).clamp_min(0.0))
    vis = (radii > 0) & (s > 0)
    mx, my = means2d[..., 0], means2d[..., 1]
    x0 = torch.floor((mx - ex) / tile_size).clamp(0, tx_n)
    x1 = (torch.floor((mx + ex) / tile_size) + 1).clamp(0, tx_n)
    y0 = torch.floor((my - ey) / tile_size).clamp(0, ty_n)
    y1 = (torch.floor((my + ey) / tile_size) + 1).clamp(0, ty_n)
    w = (x1 - x0).long()
    counts = torch.where(vis, w * (y1 - y0).long(), torch.zeros_like(w)).reshape(-1)  # [C*N]
    n_tiles = n_cams * tx_n * ty_n
    total = int(counts.sum())
    if total == 0:
        return torch.zeros(n_tiles + 1, dtype=torch.long, device=dev), torch.zeros(0, dtype=torch.long, device=dev)
    pair = torch.repeat_interleave(torch.arange(n_cams * n, device=dev), counts)  # [M]
    start = torch.cumsum(counts, 0) - counts
    j = torch.arange(total, device=dev) - start[pair]
    wf, x0f, y0f = w.reshape(-1)[pair], x0.reshape(-1).long()[pair], y0.reshape(-1).long()[pair]
    tx = x0f + j % wf
    ty = y0f + torch.div(j, wf, rounding_mode="floor")
    cam = torch.div(pair, n, rounding_mode="floor")
    tile = (cam * ty_n + ty) * tx_n + tx
    rank = torch.empty(n_cams * n, dtype=torch.long, device=dev)
    rank[torch.argsort(depths.reshape(-1), stable=True)] = torch.arange(n_cams * n, device=dev)
    key = tile * (n_cams * n) + rank[pair]
    order = torch.argsort(key)
    flat_ids = pair[order]
    per_tile = torch.bincount(tile, minlength=n_tiles)
    offsets = torch.zeros(n_tiles + 1, dtype=torch.long, device=dev)
    offsets[1:] = torch.cumsum(per_tile, 0)
    return offsets, flat_ids
