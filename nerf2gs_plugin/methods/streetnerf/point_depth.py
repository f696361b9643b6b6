"""Sparse-point depth supervision: which training pixels see which SfM point, and how far away.

Not in the StreetNeRF paper. Street cameras see the upper facades only at grazing angles, so the
photometric loss alone leaves them thin and fuzzy, and from above the ray then passes over a
half-built facade onto ground the NeRF invented behind it. The dataset's sparse points (COLMAP's, or
the synthetic street's) pin the facades where they are, the way DS-NeRF (Deng et al., CVPR 2022) and
nerfstudio's depth-nerfacto use SfM depth; the points also seed Splatfacto, so this gives the
reference the same geometry the baseline starts from.

Which pixels see which point: ``methods/point_visibility.py`` (shared with Splatfacto's depth loss).
"""

from __future__ import annotations

from torch import Tensor


def line_of_sight_loss(weights: Tensor, t_mid: Tensor, accumulation: Tensor, t_star: Tensor) -> Tensor:
    """Per-ray ``sum_i w_i min(|t_i - t*| / t*, 1) + (1 - A)`` ``[R]`` for target distances ``t_star [R, 1]``:
    mass away from the target costs its relative distance (at most 1), missing mass costs 1
    (Urban Radiance Fields' line-of-sight idea in a bounded form)."""
    rel = ((t_mid - t_star).abs() / t_star).clamp(max=1.0)
    return (weights * rel).sum(-1) + (1.0 - accumulation.reshape(-1))
