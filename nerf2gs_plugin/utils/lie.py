"""Small rotation maths for pose corrections: the skew matrix, the SO(3) exponential map and the
SO3xR3 correction of camera rays and poses (nerfstudio's camera-optimizer parametrisation).

A correction is a 6-vector ``[tx, ty, tz, rx, ry, rz]`` (translation first, as nerfstudio): the
camera centre moves by ``t`` (world axes) and the camera turns by ``exp([r]x)`` about its own centre
(world axes). The ray form and the pose form below are the same correction: a ray of a corrected
camera is the ray of the corrected pose, so a model that refines its training rays renders the same
pixels from :func:`correct_poses` of those cameras.
"""

from __future__ import annotations

import torch
from torch import Tensor

SMALL_ANGLE2 = 1e-6
"""Squared angle (rad^2) below which the exp map uses its Taylor series (no 0/0 and finite gradients at 0)."""


def skew(v: Tensor) -> Tensor:
    """``[..., 3]`` -> the cross-product matrices ``[..., 3, 3]`` (``skew(a) @ b == a x b``)."""
    x, y, z = v.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).reshape(*v.shape[:-1], 3, 3)


def so3_exp_map(omega: Tensor) -> Tensor:
    """Axis-angle vectors ``[..., 3]`` (direction: axis, norm: angle in radians) -> rotation
    matrices ``[..., 3, 3]`` (Rodrigues). Differentiable everywhere, including at ``omega = 0``
    (where the camera optimizer's corrections start)."""
    theta2 = (omega * omega).sum(-1)
    small = theta2 < SMALL_ANGLE2
    safe2 = torch.where(small, torch.ones_like(theta2), theta2)  # the unused branch must not be 0/0
    theta = torch.sqrt(safe2)
    a = torch.where(small, 1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0, (1.0 - torch.cos(theta)) / safe2)
    K = skew(omega)
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device).expand(K.shape)
    return eye + a[..., None, None] * K + b[..., None, None] * (K @ K)


def so3xr3_matrices(tangent: Tensor) -> Tensor:
    """SO3xR3 corrections ``[N, 6]`` (``[t, r]``) -> ``[N, 3, 4]`` ``[exp([r]x) | t]``."""
    return torch.cat([so3_exp_map(tangent[..., 3:]), tangent[..., :3, None]], dim=-1)


def correct_rays(origins: Tensor, directions: Tensor, corrections: Tensor) -> tuple[Tensor, Tensor]:
    """Rays ``[R, 3]`` of cameras moved by per-ray corrections ``[R, 3, 4]`` (:func:`so3xr3_matrices`):
    origins shift by ``t``, directions turn by ``R`` (unit length kept)."""
    o = origins + corrections[:, :, 3]
    d = torch.einsum("rij,rj->ri", corrections[:, :, :3], directions)
    return o, d


def correct_poses(camera_to_worlds: Tensor, corrections: Tensor) -> Tensor:
    """Camera-to-world poses ``[N, 3, 4]`` moved by corrections ``[N, 3, 4]``: ``[R R_c | c + t]``,
    the pose whose rays :func:`correct_rays` gives."""
    rot = corrections[:, :, :3] @ camera_to_worlds[:, :, :3]
    return torch.cat([rot, camera_to_worlds[:, :, 3:] + corrections[:, :, 3:]], dim=-1)
