"""One image resize for the package's ``[H, W, C]`` float tensors (area filter: a shrink averages the pixels
it merges). Imports nothing of the package (the ground floor)."""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor


def area_resize(img: Tensor, hw: tuple[int, int]) -> Tensor:
    """``img`` ``[H, W, C]`` area-resized to ``hw`` ``(h, w)`` as float; ``img`` itself when it has that size."""
    if tuple(img.shape[:2]) == tuple(hw):
        return img
    return F.interpolate(img.permute(2, 0, 1)[None].float(), size=tuple(hw), mode="area")[0].permute(1, 2, 0)
