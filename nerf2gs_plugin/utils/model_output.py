"""Checks of what an external model returns (segmenter, enhancer, reference render) before it is
written or trained on: a NaN model must stop the command with one line naming it, not write black
images at exit 0."""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Union

import torch
from torch import Tensor

from nerf2gs_plugin.errors import ModelOutputError

# Share of values allowed outside the declared range widened by a quarter of its width on each
# side: models overshoot a little (clamped after), a wrong range convention (0..255) misses by far.
OUT_OF_RANGE_SHARE = 0.05


def check_finite(t: Tensor, model: Union[str, Path], what: str = "output") -> Tensor:
    """``t`` itself; a ``ModelOutputError`` naming ``model`` when it holds NaN/inf."""
    if t.is_floating_point() or t.is_complex():
        bad = int((~torch.isfinite(t)).sum())
        if bad:
            raise ModelOutputError(f"{what} holds {bad} non-finite value(s) (NaN/inf) of {t.numel()}; nothing was written from it", model)
    return t


def check_range(t: Tensor, lo: float, hi: float, model: Union[str, Path], what: str = "output") -> Tensor:
    """``t`` itself, finite and (but for a few overshooting values) within ``[lo, hi]``."""
    check_finite(t, model, what)
    if t.numel():
        tol = 0.25 * (hi - lo)
        outside = float(((t < lo - tol) | (t > hi + tol)).float().mean())
        if outside > OUT_OF_RANGE_SHARE:
            raise ModelOutputError(f"{what} spans [{float(t.min()):.4g}, {float(t.max()):.4g}], "
                                   f"{outside:.0%} of it outside the declared range {lo:g}..{hi:g}", model)
    return t


def check_shape(t: Tensor, allowed: Sequence[Sequence[Optional[int]]], model: Union[str, Path], what: str = "output") -> Tensor:
    """``t`` itself when its shape matches one of ``allowed`` (``None``: any size on that axis)."""
    for shape in allowed:
        if t.dim() == len(shape) and all(s is None or s == n for s, n in zip(shape, t.shape)):
            return t
    want = " or ".join("[" + ", ".join("*" if s is None else str(s) for s in shape) + "]" for shape in allowed)
    raise ModelOutputError(f"{what} has shape {list(t.shape)}, expected {want}", model)
