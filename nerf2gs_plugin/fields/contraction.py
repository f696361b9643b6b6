"""Unbounded scene contraction (mip-NeRF 360, Barron et al. 2022, Eq. 10) in the L-inf norm.

Positions are first expressed in the scene box's frame (the box maps to [-1, 1]^3), then
``contract(x) = x`` inside the box and ``(2 - 1/|x|) x/|x|`` outside, with ``|x|`` the L-inf norm
(as nerfacto does for grids: the contracted space is the full cube [-2, 2]^3, so no hash-grid
cell is wasted). Far facades and the horizon land in the outer shell; the grids then see
``(contract(x) + 2) / 4`` in [0, 1]^3.
"""

from __future__ import annotations

import torch
from torch import Tensor


def to_box_frame(x: Tensor, scene_box: Tensor) -> Tensor:
    """World ``[...,3]`` -> the frame where ``scene_box [2,3]`` is [-1,1]^3."""
    lo, hi = scene_box[0].to(x), scene_box[1].to(x)
    return (x - (lo + hi) / 2) / ((hi - lo) / 2)


def contract(x: Tensor) -> Tensor:
    """``x [...,3]`` (box frame) -> contracted ``[...,3]`` in [-2, 2]^3 (L-inf norm)."""
    n = x.abs().amax(-1, keepdim=True).clamp_min(1e-9)
    return torch.where(n <= 1.0, x, (2.0 - 1.0 / n) * (x / n))


def contraction_scale(x: Tensor) -> Tensor:
    """Isotropic local scale of :func:`contract` at ``x [...,3]``: ``|det J|^(1/3)`` ``[...]``.

    Outside the box the radial derivative is ``1/|x|^2`` and the two tangential ones
    ``(2 - 1/|x|)/|x|``; a sample's radius shrinks by their geometric mean (Zip-NeRF's
    isotropic approximation of the contracted Gaussian)."""
    n = x.abs().amax(-1).clamp_min(1e-9)
    inside = n <= 1.0
    # the formula only for points outside: inside, at |x| = 0.5, its cube root has an infinite slope,
    # and a NaN gradient of the unused branch would reach positions that require grad (camera optimizer)
    n_out = torch.where(inside, torch.ones_like(n), n)
    outside = (1.0 / n_out**2 * ((2.0 - 1.0 / n_out) / n_out) ** 2) ** (1.0 / 3.0)
    return torch.where(inside, torch.ones_like(n), outside)


def to_grid_unit(xc: Tensor) -> Tensor:
    """Contracted ``[-2,2]^3`` -> ``[0,1]^3`` (the hash grid's domain)."""
    return (xc + 2.0) / 4.0


@torch.no_grad()
def render_grid_coords(x: Tensor, scene_box: Tensor) -> tuple[Tensor, Tensor]:
    """``to_grid_unit(contract(to_box_frame(x)))`` and ``contraction_scale(to_box_frame(x))`` for renders
    (no gradient): the norm is taken once and the arithmetic runs in place, the same maths to float rounding."""
    lo, hi = scene_box[0].to(x), scene_box[1].to(x)
    xb = (x - (lo + hi) / 2).div_((hi - lo) / 2)
    n = xb.abs().amax(-1, keepdim=True).clamp_min_(1e-9)
    inside = n <= 1.0
    inv = torch.where(inside, torch.ones_like(n), n).reciprocal_()  # 1/|x| outside, 1 inside
    k = (2.0 - inv).mul_(inv)  # outside: (2 - 1/|x|)/|x|, the factor of x
    xg = torch.where(inside, xb, xb * k).add_(2.0).div_(4.0)
    # outside: (1/|x|^2 * ((2 - 1/|x|)/|x|)^2)^(1/3); inside 1
    scale = inv.square_().mul_(k.square_()).pow_(1.0 / 3.0).masked_fill_(inside, 1.0)
    return xg, scale.reshape(x.shape[:-1])
