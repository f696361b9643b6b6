"""Small loss helpers shared by methods (image-quality metrics live in eval/metrics.py)."""

from __future__ import annotations

import torch
from torch import Tensor


def psnr_from_mse(mse: Tensor) -> Tensor:
    return -10.0 * torch.log10(mse.clamp_min(1e-10))


def masked_mean(values: Tensor, weight: Tensor) -> Tensor:
    """Weighted mean; ``weight`` broadcasts to ``values``; zero total weight gives zero."""
    w = weight.expand_as(values).to(values.dtype)
    return (values * w).sum() / w.sum().clamp_min(1e-8)
