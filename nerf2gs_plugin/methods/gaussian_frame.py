"""Gaussians from the normalised training frame back to the dataset's own frame and scale.

The dataparser maps the data frame to the normalised one by ``x_n = s (R x + t)``
(``dataparser_transforms.json``: ``transform = [R | t]``, ``scale = s``). The inverse moves the
means, rotates the Gaussians' orientations, rescales them, and rotates the view-dependent
colour: each SH band ``l`` is rotated by the matrix ``D_l`` with ``Y_l(R d) = D_l Y_l(d)``,
solved by least squares on sample directions (exact: every band is closed under rotation).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from nerf2gs_plugin.utils.quaternions import normalize_quats, quat_to_rotmat, rotmat_to_quat
from nerf2gs_plugin.utils.sh import sh_basis


def sh_rotation_matrices(R: Tensor, degree: int) -> list[Tensor]:
    """Per band ``l = 1..degree``, ``D_l [2l+1, 2l+1]`` with ``Y_l(R d) = D_l Y_l(d)``."""
    if degree == 0:
        return []
    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(512, 3, generator=g, dtype=torch.float64), dim=-1)
    Rd = d @ R.double().T
    B, BR = sh_basis(degree, d), sh_basis(degree, Rd)
    out = []
    for l in range(1, degree + 1):
        sl = slice(l * l, (l + 1) * (l + 1))
        # B_l(d) @ D_l^T = B_l(R d)
        out.append(torch.linalg.lstsq(B[:, sl], BR[:, sl]).solution.T)
    return out


def rotate_sh_rest(features_rest: Tensor, R: Tensor) -> Tensor:
    """Rest coefficients ``[N, K-1, 3]`` of a colour seen along ``d`` in frame A -> those of the
    same colour with directions expressed in frame B, where ``d_A = R d_B``."""
    k = features_rest.shape[1] + 1
    degree = int(round(math.sqrt(k))) - 1
    out = features_rest.clone()
    for l, D in enumerate(sh_rotation_matrices(R, degree), start=1):
        sl = slice(l * l - 1, (l + 1) * (l + 1) - 1)  # rest excludes the DC term
        out[:, sl] = torch.einsum("kj,nkc->njc", D.to(features_rest), features_rest[:, sl])
    return out


def to_data_frame(g: dict[str, Tensor], transform: Tensor, scale: float) -> dict[str, Tensor]:
    """Gaussians (the PLY quantities) in the normalised frame -> the dataset's original frame."""
    R, t = transform[:, :3].to(g["means"]), transform[:, 3].to(g["means"])
    out = dict(g)
    out["means"] = (g["means"] / scale - t) @ R  # R^T (x/s - t), row vectors
    out["log_scales"] = g["log_scales"] - math.log(scale)
    out["quats"] = rotmat_to_quat(R.T @ quat_to_rotmat(normalize_quats(g["quats"])))
    if g.get("features_rest") is not None and g["features_rest"].shape[1] > 0:
        # colour(d_n) with d_n = R d_data
        out["features_rest"] = rotate_sh_rest(g["features_rest"], R)
    return out


def camera_to_data_frame(c2w: Tensor, transform: Tensor, scale: float) -> Tensor:
    """``[N, 3, 4]`` camera-to-world in the normalised frame -> the dataset's frame."""
    R, t = transform[:, :3].to(c2w), transform[:, 3].to(c2w)
    rot = R.T @ c2w[:, :, :3]
    pos = (c2w[:, :, 3] / scale - t) @ R
    return torch.cat([rot, pos[:, :, None]], dim=-1)
