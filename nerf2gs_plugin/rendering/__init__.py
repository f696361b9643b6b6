"""Differentiable Gaussian rasterization: 3DGS (:func:`rasterize_gaussians`) and 2DGS surfels
(:func:`rasterize_surfels`), each with ``cpu`` (C++/OpenMP), ``torch`` (reference) and ``gsplat``
(CUDA) backends behind one entry. Imports are lazy so that importing the package is cheap.
"""

from __future__ import annotations

from typing import Any


def rasterize_gaussians(*args: Any, **kwargs: Any) -> Any:
    """See :func:`nerf2gs_plugin.rendering.rasterization.rasterize_gaussians`."""
    from nerf2gs_plugin.rendering.rasterization import rasterize_gaussians as f

    return f(*args, **kwargs)


def rasterize_surfels(*a: Any, **k: Any) -> Any:
    """See :func:`nerf2gs_plugin.rendering.surfels.rasterize_surfels` (2DGS)."""
    from nerf2gs_plugin.rendering.surfels import rasterize_surfels as f

    return f(*a, **k)


__all__ = ["rasterize_gaussians", "rasterize_surfels"]
