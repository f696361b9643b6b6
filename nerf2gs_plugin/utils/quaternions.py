"""Quaternion maths (``wxyz``), the one copy the rasterizers and the methods share."""

from __future__ import annotations

import math
from typing import Optional

import torch
from torch import Tensor


def normalize_quats(q: Tensor) -> Tensor:
    return torch.nn.functional.normalize(q, dim=-1)


def quat_to_rotmat(q: Tensor, normalize: bool = True) -> Tensor:
    """``[..., 4]`` wxyz -> rotation matrices ``[..., 3, 3]``. ``normalize=False`` when the caller
    already holds unit quaternions (the rasterizers: their gradients then skip the normalisation)."""
    w, x, y, z = (normalize_quats(q) if normalize else q).unbind(-1)
    r = torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1)
    return r.reshape(*q.shape[:-1], 3, 3)


def random_quats(n: int, generator: Optional[torch.Generator] = None) -> Tensor:
    """Uniformly distributed unit quaternions ``[n, 4]`` (wxyz), Shoemake's method."""
    u, v, w = torch.rand(3, n, generator=generator)
    a, b = torch.sqrt(1 - u), torch.sqrt(u)
    return torch.stack([a * torch.sin(2 * math.pi * v), a * torch.cos(2 * math.pi * v),
                        b * torch.sin(2 * math.pi * w), b * torch.cos(2 * math.pi * w)], dim=-1)


def rotmat_to_quat(R: Tensor) -> Tensor:
    """Rotation matrices ``[..., 3, 3]`` -> unit quaternions ``[..., 4]`` wxyz (w >= 0)."""
    m = R
    t = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack([
        torch.stack([1 + t, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        torch.stack([m[..., 2, 1] - m[..., 1, 2], 1 + 2 * m[..., 0, 0] - t, m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
        torch.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 + 2 * m[..., 1, 1] - t, m[..., 1, 2] + m[..., 2, 1]], -1),
        torch.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1], 1 + 2 * m[..., 2, 2] - t], -1),
    ], dim=-2)  # [..., 4, 4]; row i is 4*q*q_i, best conditioned where q_i is largest
    diag = torch.stack([1 + t, 1 + 2 * m[..., 0, 0] - t, 1 + 2 * m[..., 1, 1] - t, 1 + 2 * m[..., 2, 2] - t], -1)
    best = diag.argmax(-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = normalize_quats(q)
    return torch.where(q[..., :1] < 0, -q, q)
