"""One render output as an 8-bit colour image: what the viewer shows and ns2gs-render writes."""

from __future__ import annotations

import functools

import numpy as np
import torch
from torch import Tensor


@functools.lru_cache(maxsize=1)
def _turbo_lut() -> np.ndarray:
    import matplotlib

    return (matplotlib.colormaps["turbo"](np.linspace(0.0, 1.0, 256))[:, :3] * 255 + 0.5).astype(np.uint8)


def to_uint8(img: Tensor) -> np.ndarray:
    return (img.detach().float().clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)


def colorize(outputs: dict[str, Tensor], mode: str) -> np.ndarray:
    """One render output as a ``uint8 [H, W, 3]`` image: depth through the turbo colour map
    (2-98 percentile range of covered pixels), accumulation in grey, normals as ``(n + 1) / 2``."""
    if mode not in outputs:
        raise KeyError(f"render mode '{mode}' not in the outputs ({', '.join(outputs)})")
    acc = outputs.get("accumulation")
    covered = (acc[..., 0] > 0.5) if acc is not None else None
    if mode == "rgb":
        return to_uint8(outputs["rgb"][..., :3])
    if mode == "accumulation":
        return to_uint8(outputs["accumulation"][..., :1].expand(*outputs["accumulation"].shape[:2], 3))
    if mode == "normals":
        n = outputs["normals"][..., :3].float()
        img = (n * 0.5 + 0.5).clamp(0, 1)
        if covered is not None:
            img = torch.where(covered[..., None], img, torch.zeros_like(img))
        return to_uint8(img)
    d = outputs["depth"][..., 0].detach().float().cpu()
    valid = torch.isfinite(d) & (d > 0)
    if covered is not None:
        valid &= covered.cpu()
    if not bool(valid.any()):
        return np.zeros((*d.shape, 3), np.uint8)
    vals = d[valid]
    if vals.numel() > 100_000:
        vals = vals[torch.randperm(vals.numel(), generator=torch.Generator().manual_seed(0))[:100_000]]
    lo, hi = torch.quantile(vals, torch.tensor([0.02, 0.98])).tolist()
    t = ((d - lo) / max(hi - lo, 1e-8)).clamp(0, 1)
    idx = (t * 255).round().long().numpy()
    img = _turbo_lut()[idx]
    img[~valid.numpy()] = 0
    return img
