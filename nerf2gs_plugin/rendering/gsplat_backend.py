"""The ``gsplat`` backend: :func:`gsplat.rasterization` (3DGS) and ``rasterization_2dgs`` on CUDA,
outputs mapped to our conventions.

Only imported when CUDA is available and gsplat imports (see :mod:`.backend`), so a CPU machine
never touches gsplat's CUDA code. Differences papered over here: newer gsplat
returns per-axis radii ``[C, N, 2]`` (reduced to ``[C, N]`` by max; the original is kept as
``radii_xy``), and gsplat has no median depth for 3DGS, so ``return_median`` runs our torch
compositor (no gradients) for that one output.
"""

from __future__ import annotations

from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.rendering.rasterization import rasterize_gaussians


def rasterize_gsplat(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, viewmats: Tensor, Ks: Tensor,
    width: int, height: int, near_plane: float, far_plane: float, sh_degree: Optional[int],
    backgrounds: Optional[Tensor], render_mode: str, rasterize_mode: str, tile_size: int, return_median: bool,
) -> tuple[Tensor, Tensor, dict[str, Any]]:
    """Same contract as :func:`~nerf2gs_plugin.rendering.rasterization.rasterize_gaussians`."""
    from gsplat import rasterization  # noqa: PLC0415

    render, alpha, meta = rasterization(
        means, quats, scales, opacities, colors, viewmats, Ks, width, height,
        near_plane=near_plane, far_plane=far_plane, sh_degree=sh_degree, packed=False, tile_size=tile_size,
        backgrounds=backgrounds, render_mode=render_mode, rasterize_mode=rasterize_mode,
    )
    out = dict(meta)
    radii = meta["radii"]
    if radii.dim() == 3:
        out["radii_xy"] = radii
        radii = radii.amax(-1)
    out["radii"] = radii.to(torch.int32)
    out.update(width=width, height=height, tile_size=tile_size, n_cameras=viewmats.shape[0], backend="gsplat")
    if return_median:
        with torch.no_grad():
            _, _, m = rasterize_gaussians(
                means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane=near_plane,
                far_plane=far_plane, sh_degree=sh_degree, render_mode="D", rasterize_mode=rasterize_mode,
                backend="torch", tile_size=tile_size, return_median=True,
            )
        out["median_depth"] = m["median_depth"]
    return render, alpha, out


def rasterize_surfels_gsplat(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                      viewmats: Tensor, Ks: Tensor, width: int, height: int, near_plane: float, far_plane: float,
                      sh_degree: Optional[int], backgrounds: Optional[Tensor], render_mode: str,
                      tile_size: int, densify_signal: str = "lowpass") -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, dict[str, Any]]:
    """2DGS by ``gsplat.rasterization_2dgs``, normals mapped from world to camera frame (same contract as
    :func:`~nerf2gs_plugin.rendering.surfels.rasterize_surfels`; gsplat keeps its own densification signal)."""
    import gsplat  # noqa: PLC0415 - only reached with CUDA tensors

    C = viewmats.shape[0]
    if backgrounds is not None and backgrounds.dim() == 1:
        backgrounds = backgrounds[None].expand(C, -1)
    render, alpha, normals, surf, distort, median, meta = gsplat.rasterization_2dgs(
        means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane=near_plane,
        far_plane=far_plane, sh_degree=sh_degree, backgrounds=backgrounds, render_mode=render_mode,
        tile_size=tile_size, distloss="D" in render_mode)
    rot = viewmats[:, :3, :3]
    normals = torch.einsum("cij,chwj->chwi", rot, normals)
    if surf is None:
        surf = torch.zeros_like(normals)
    else:
        surf = torch.einsum("cij,chwj->chwi", rot, surf.reshape(C, height, width, 3))
    radii = meta["radii"]
    if radii.dim() == 3:  # newer gsplat: per-axis radii
        radii = radii.max(-1).values
    meta = {**meta, "radii": radii, "backend": "gsplat"}
    return render, alpha, normals, surf, distort, median, meta
