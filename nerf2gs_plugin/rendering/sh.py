"""Spherical-harmonics colour evaluation in the 3DGS convention (shared by 3DGS and 2DGS).

Coefficients are ``[..., K, 3]`` with ``K >= (degree + 1) ** 2`` and the DC term first; only the
first ``(degree + 1) ** 2`` are used, so a model can raise its degree during training without
reshaping. As in gsplat/nerfstudio the result is ``sum_k Y_k(d) c_k + 0.5`` clamped at 0 (the DC
term stores ``(rgb - 0.5) / C0``).
"""

from __future__ import annotations

import torch
from torch import Tensor

from nerf2gs_plugin.utils.sh import sh_basis


def eval_sh(degree: int, coeffs: Tensor, dirs: Tensor) -> Tensor:
    """Colour from SH coefficients ``coeffs [..., K, 3]`` seen along ``dirs [..., 3]`` -> ``[..., 3]``.

    ``dirs`` need not be unit length (normalised here); leading dims broadcast (e.g. coeffs
    ``[N, K, 3]`` with dirs ``[C, N, 3]`` gives ``[C, N, 3]``).
    """
    nb = (degree + 1) ** 2
    if coeffs.shape[-2] < nb:
        raise ValueError(f"SH degree {degree} needs {nb} coefficients, got {coeffs.shape[-2]}")
    d = torch.nn.functional.normalize(dirs, dim=-1)
    basis = sh_basis(degree, d.reshape(-1, 3)).reshape(*d.shape[:-1], nb)  # [..., nb]
    rgb = (basis[..., :, None] * coeffs[..., :nb, :]).sum(-2)
    return torch.clamp_min(rgb + 0.5, 0.0)
