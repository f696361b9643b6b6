"""Small loss helpers shared by methods (PSNR and SSIM live in :mod:`nerf2gs_plugin.utils.image_metrics`)."""

from __future__ import annotations

from torch import Tensor


def masked_mean(values: Tensor, weight: Tensor) -> Tensor:
    """Weighted mean; ``weight`` broadcasts to ``values``; zero total weight gives zero."""
    w = weight.expand_as(values).to(values.dtype)
    return (values * w).sum() / w.sum().clamp_min(1e-8)
