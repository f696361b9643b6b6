"""Cameras, random Gaussians and the gradient comparison shared by the cpu projection ops' tests
(3DGS: test_projection_cpu.py, 2DGS surfels: test_surfels_cpu_projection.py)."""

from __future__ import annotations

import math
from typing import Sequence

import torch
from torch import Tensor


def three_cameras(dtype: torch.dtype = torch.float64) -> tuple[Tensor, Tensor]:
    """Three cameras for a 40x30 image: identity, shifted, and tilted about x and pushed forward."""
    vm = torch.eye(4, dtype=dtype).repeat(3, 1, 1)
    vm[1, 0, 3] = 0.4
    c, s = math.cos(0.3), math.sin(0.3)
    vm[2, :3, :3] = torch.tensor([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=dtype)
    vm[2, 2, 3] = 0.5
    ks = torch.tensor([[30.0, 0, 20], [0, 30, 15], [0, 0, 1]], dtype=dtype).repeat(3, 1, 1)
    return vm, ks


def random_geometry(n: int, dtype: torch.dtype, g: torch.Generator) -> tuple[Tensor, Tensor, Tensor]:
    """Means spread in front of the cameras (the first one behind all of them: culled), quaternions
    not normalised, scales in [0.05, 0.35); drawn from ``g``, which the caller goes on drawing from."""
    means = torch.randn(n, 3, generator=g, dtype=dtype) * torch.tensor([1.5, 1.0, 1.0], dtype=dtype)
    means[:, 2] += 3.0
    means[0, 2] = -1.0
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.rand(n, 3, generator=g, dtype=dtype) * 0.3 + 0.05
    return means, quats, scales


def assert_same_gradients(ours: Sequence[Tensor], ref: Sequence[Tensor], ours_leaves: Sequence[Tensor],
                          ref_leaves: Sequence[Tensor], seed: int) -> None:
    """The gradients of one random weighting of both ops' outputs agree to 1e-10 of the largest (and are not 0)."""
    g = torch.Generator().manual_seed(seed)
    weights = [torch.randn(y.shape, generator=g, dtype=y.dtype) for y in ref]
    ga = torch.autograd.grad(sum((x * w).sum() for x, w in zip(ours, weights)), ours_leaves)
    gb = torch.autograd.grad(sum((y * w).sum() for y, w in zip(ref, weights)), ref_leaves)
    for x, y in zip(ga, gb):
        assert float(y.abs().max()) > 0
        assert float((x - y).abs().max()) <= 1e-10 * float(y.abs().max())
