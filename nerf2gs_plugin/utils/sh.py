"""Real spherical harmonics in the 3DGS/gsplat sign convention: the one basis that the rasterizers'
torch path, the splatting methods' sky and StreetNeRF's direction encoding all use.

Coefficients are ``[..., K, 3]`` with ``K = (degree + 1) ** 2`` and the DC term first; a DC
coefficient stores ``(rgb - 0.5) / SH_C0`` (the rasterizer adds 0.5 back).
"""

from __future__ import annotations

import functools
import math

import torch
from torch import Tensor

SH_C0 = 0.28209479177387814


def num_sh_bases(degree: int) -> int:
    return (degree + 1) ** 2


def rgb_to_sh(rgb: Tensor) -> Tensor:
    """Colour in [0, 1] -> DC coefficient (the rasterizer adds 0.5 back after evaluating SH)."""
    return (rgb - 0.5) / SH_C0


def sh_to_rgb(sh: Tensor) -> Tensor:
    return sh * SH_C0 + 0.5


def sh_basis(degree: int, dirs: Tensor) -> Tensor:
    """Real SH basis of unit directions ``[..., 3]`` up to ``degree`` (0-4) -> ``[..., (degree+1)^2]``."""
    if not 0 <= degree <= 4:
        raise ValueError("spherical-harmonics degree must be in 0..4")
    x, y, z = dirs.unbind(-1)
    out = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-0.48860251190291987 * y, 0.48860251190291987 * z, -0.48860251190291987 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [
            1.0925484305920792 * xy,
            -1.0925484305920792 * yz,
            0.94617469575755997 * zz - 0.31539156525251999,
            -1.0925484305920792 * xz,
            0.54627421529603959 * (xx - yy),
        ]
    if degree >= 3:
        out += [
            0.59004358992664352 * y * (-3.0 * xx + yy),
            2.8906114426405538 * xy * z,
            0.45704579946446572 * y * (1.0 - 5.0 * zz),
            0.3731763325901154 * z * (5.0 * zz - 3.0),
            0.45704579946446572 * x * (1.0 - 5.0 * zz),
            1.4453057213202769 * z * (xx - yy),
            0.59004358992664352 * x * (-xx + 3.0 * yy),
        ]
    if degree >= 4:
        out += [
            2.5033429417967046 * xy * (xx - yy),
            1.7701307697799304 * yz * (-3.0 * xx + yy),
            0.94617469575756008 * xy * (7.0 * zz - 1.0),
            0.66904654355728921 * yz * (7.0 * zz - 3.0),
            0.10578554691520431 * (35.0 * zz * zz - 30.0 * zz + 3.0),
            0.66904654355728921 * xz * (7.0 * zz - 3.0),
            0.47308734787878004 * (xx - yy) * (7.0 * zz - 1.0),
            1.7701307697799304 * xz * (xx - 3.0 * yy),
            0.62583573544917614 * (xx * (xx - 3.0 * yy) - yy * (3.0 * xx - yy)),
        ]
    return torch.stack(out, dim=-1)


def _sphere_points(n: int) -> Tensor:
    """``n`` well-spread unit directions ``[n, 3]`` (float64, a Fibonacci sphere)."""
    i = torch.arange(n, dtype=torch.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    r = torch.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], dim=-1)


def sh_rotation(degree: int, rotation: Tensor) -> Tensor:
    """``[K, K]`` (K = (degree+1)^2, float64) with ``sh_basis(degree, d @ rotation.T) == sh_basis(degree, d) @ D``
    for every unit ``d``: a rotation of the directions is a linear map of their SH basis (each band onto
    itself). Solved by least squares on fixed directions, exact to float64 rounding."""
    dirs, solve = _sphere_solve(degree)
    rot = rotation.detach().to("cpu", torch.float64)
    return solve @ sh_basis(degree, dirs @ rot.T)


@functools.lru_cache(maxsize=None)
def _sphere_solve(degree: int) -> tuple[Tensor, Tensor]:
    """The fixed directions of :func:`sh_rotation` and the least-squares solve of their basis (its
    pseudo-inverse), made once per degree: each call then costs one basis of the turned directions."""
    dirs = _sphere_points(4 * num_sh_bases(degree))
    return dirs, torch.linalg.pinv(sh_basis(degree, dirs))
