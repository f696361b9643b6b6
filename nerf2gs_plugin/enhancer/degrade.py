"""Synthetic degradations that look like NeRF novel-view artifacts, for training pairs
(degraded, ground truth) made from the training images themselves: blur, downsample-upsample,
noise, smeared streaks (stretched texture, like floaters and under-constrained ground),
dark/foggy holes, colour shifts. Vectorised over pixels; the loop runs over batch samples."""

from __future__ import annotations

import math
from typing import Sequence

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

KINDS = ("blur", "resample", "noise", "smear", "holes", "color")


def _u(gen: torch.Generator, lo: float, hi: float) -> float:
    return lo + (hi - lo) * float(torch.rand((), generator=gen))


def _ri(gen: torch.Generator, lo: int, hi: int) -> int:
    """Integer in [lo, hi] inclusive."""
    return int(torch.randint(lo, max(hi, lo) + 1, (), generator=gen))


def gaussian_blur(x: Tensor, sigma: float) -> Tensor:
    """Gaussian blur of ``[B, C, H, W]`` (radius 3 sigma, mirrored border without repeating the edge).
    OpenCV's, as exact as a torch convolution and many times faster on the CPU (docs/libraries.md)."""
    if sigma <= 0:
        return x
    r = max(1, int(math.ceil(3 * sigma)))
    r = min(r, x.shape[-1] - 1, x.shape[-2] - 1)
    if r < 1:
        return x
    hwc = x.detach().cpu().permute(0, 2, 3, 1).numpy()
    out = np.stack([cv2.GaussianBlur(im, (2 * r + 1, 2 * r + 1), sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT_101)
                    .reshape(im.shape) for im in hwc])
    return torch.from_numpy(out).permute(0, 3, 1, 2).to(x)


def _resample(y: Tensor, f: float) -> Tensor:
    h, w = y.shape[-2:]
    small = F.interpolate(y, size=(max(2, round(h / f)), max(2, round(w / f))), mode="bilinear", align_corners=False, antialias=True)
    return F.interpolate(small, size=(h, w), mode="bilinear", align_corners=False)


def _rect(gen: torch.Generator, h: int, w: int, lo: float, hi: float) -> tuple[int, int, int, int]:
    rh, rw = max(2, int(h * _u(gen, lo, hi))), max(2, int(w * _u(gen, lo, hi)))
    y0, x0 = _ri(gen, 0, h - rh), _ri(gen, 0, w - rw)
    return y0, x0, rh, rw


def _smear(y: Tensor, gen: torch.Generator) -> Tensor:
    """A patch whose content is one row (or column) stretched across it, blended in."""
    h, w = y.shape[-2:]
    y0, x0, rh, rw = _rect(gen, h, w, 0.2, 0.5)
    patch = y[..., y0 : y0 + rh, x0 : x0 + rw]
    if float(torch.rand((), generator=gen)) < 0.5:
        r = _ri(gen, 0, rh - 1)
        streak = patch[..., r : r + 1, :].expand_as(patch)
    else:
        c = _ri(gen, 0, rw - 1)
        streak = patch[..., :, c : c + 1].expand_as(patch)
    a = _u(gen, 0.5, 1.0)
    ramp_y = torch.minimum(torch.arange(rh) + 1, rh - torch.arange(rh)).float() / max(rh / 4, 1)
    ramp_x = torch.minimum(torch.arange(rw) + 1, rw - torch.arange(rw)).float() / max(rw / 4, 1)
    alpha = (a * ramp_y.clamp(max=1)[:, None] * ramp_x.clamp(max=1)[None, :]).to(y)
    y = y.clone()
    y[..., y0 : y0 + rh, x0 : x0 + rw] = patch * (1 - alpha) + streak * alpha
    return y


def _hole(y: Tensor, gen: torch.Generator) -> Tensor:
    """A dark hole (as Gaussian splats leave on the road) or a foggy blob (NeRF floater)."""
    h, w = y.shape[-2:]
    y0, x0, rh, rw = _rect(gen, h, w, 0.1, 0.35)
    y = y.clone()
    region = y[..., y0 : y0 + rh, x0 : x0 + rw]
    if float(torch.rand((), generator=gen)) < 0.5:
        fill = torch.full_like(region, _u(gen, 0.0, 0.12))
    else:
        fill = gaussian_blur(region, max(rh, rw) / 3).mean((-2, -1), keepdim=True).expand_as(region) * 0.5 + 0.5 * _u(gen, 0.4, 0.9)
    a = _u(gen, 0.6, 1.0)
    y[..., y0 : y0 + rh, x0 : x0 + rw] = region * (1 - a) + fill * a
    return y


def _apply(kind: str, y: Tensor, gen: torch.Generator, strength: float) -> Tensor:
    if kind == "blur":
        return gaussian_blur(y, _u(gen, 0.6, 2.0) * strength)
    if kind == "resample":
        return _resample(y, 1 + _u(gen, 0.5, 2.5) * strength)
    if kind == "smear":
        return _smear(y, gen)
    if kind == "holes":
        return _hole(y, gen)
    if kind == "color":
        gain = 1 + torch.empty(1, 3, 1, 1).uniform_(-0.08, 0.08, generator=gen) * strength
        bias = torch.empty(1, 3, 1, 1).uniform_(-0.03, 0.03, generator=gen) * strength
        return y * gain.to(y) + bias.to(y)
    sigma = _u(gen, 0.01, 0.05) * strength  # noise
    return y + sigma * torch.randn(y.shape, generator=gen).to(y)


# Probability of each kind in a mix; a sample that draws none gets one kind at random, so every
# degraded image differs from its ground truth (a clean one would score an infinite PSNR).
PROBS = {"blur": 0.5, "resample": 0.35, "smear": 0.35, "holes": 0.25, "color": 0.35, "noise": 0.5}


def degrade(x: Tensor, gen: torch.Generator, kinds: Sequence[str] = KINDS, strength: float = 1.0) -> Tensor:
    """A random mix of ``kinds`` (at least one) applied to each image of ``x`` ``[B, 3, H, W]`` (0..1)."""
    unknown = set(kinds) - set(KINDS)
    if unknown:
        raise ValueError(f"unknown degradations {sorted(unknown)}; known: {', '.join(KINDS)}")
    order = [k for k in ("blur", "resample", "smear", "holes", "color", "noise") if k in kinds]
    out = []
    for b in range(x.shape[0]):  # over samples only; each op is vectorised over pixels
        chosen = [k for k in order if float(torch.rand((), generator=gen)) < PROBS[k]]
        if not chosen:
            chosen = [order[int(torch.randint(len(order), (), generator=gen))]]
        y = x[b : b + 1]
        for k in chosen:
            y = _apply(k, y, gen, strength)
        out.append(y)
    return torch.cat(out).clamp(0, 1)
