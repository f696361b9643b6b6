"""The learned background as Gaussians: a far shell of flat, opaque splats coloured by the
background model, so a PLY shows in any 3DGS viewer what our renders show where the scene's
Gaussians leave transmittance (the sky), instead of holes.

The shell is a Fibonacci sphere of ``n`` discs tangent to a sphere of radius ``radius`` around
``centre``; each disc's colour is the background evaluated in the direction of its centre. Our
background is a function of the view direction only, which the shell reproduces up to the
parallax ``|camera - centre| / radius`` (radians) and the disc spacing.
"""

from __future__ import annotations

import math
from typing import Optional

import torch
from torch import Tensor

from nerf2gs_plugin.methods.gaussian_utils import logit
from nerf2gs_plugin.utils.quaternions import rotmat_to_quat
from nerf2gs_plugin.utils.sh import num_sh_bases, rgb_to_sh, sh_basis


def fibonacci_sphere(n: int) -> Tensor:
    """``n`` nearly evenly spread unit vectors ``[n, 3]``."""
    i = torch.arange(n, dtype=torch.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    r = torch.sqrt((1.0 - z * z).clamp_min(0.0))
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], -1).float()


def background_colors(background: torch.nn.Module, dirs: Tensor) -> Optional[Tensor]:
    """Colour ``[n, 3]`` the background model shows at eval time in world directions ``dirs``;
    None when it has no colour to show (``black``, or ``random``, which is black at eval)."""
    mode = getattr(background, "mode", None)
    if mode == "sky":
        coeffs = background.coeffs.detach().float().cpu()
        return torch.sigmoid(sh_basis(background.sh_degree, dirs) @ coeffs)
    if mode == "learned":
        return torch.sigmoid(background.color.detach().float().cpu()).expand(dirs.shape[0], 3)
    if mode == "white":
        return torch.ones(dirs.shape[0], 3)
    return None


def _tangent_frames(normals: Tensor) -> Tensor:
    """Rotations ``[n, 3, 3]`` whose third column is ``normals`` (the disc's thin axis)."""
    helper = torch.where(normals[:, 2:3].abs() < 0.9, torch.tensor([0.0, 0.0, 1.0]), torch.tensor([1.0, 0.0, 0.0]))
    u = torch.nn.functional.normalize(torch.cross(helper, normals, dim=-1), dim=-1)
    v = torch.cross(normals, u, dim=-1)
    return torch.stack([u, v, normals], dim=-1)


def sky_shell_gaussians(
    background: torch.nn.Module, centre: Tensor, radius: float, n: int = 10000, sh_rest: int = 0,
    overlap: float = 1.2, opacity: float = 0.995,
) -> Optional[dict[str, Tensor]]:
    """The shell as :func:`write_gaussian_ply` quantities (``features_rest`` zero, ``sh_rest``
    coefficients per channel, to match the scene's layout); None when the background is black.

    ``overlap`` is the discs' standard deviation in units of their spacing: at 1.2 every direction
    lies within about half a standard deviation of three discs, so the shell's accumulation is ~1."""
    dirs = fibonacci_sphere(n)
    colors = background_colors(background, dirs)
    if colors is None:
        return None
    spacing = radius * math.sqrt(4.0 * math.pi / n)
    sigma = overlap * spacing
    log_scales = torch.log(torch.tensor([sigma, sigma, 1e-3 * sigma])).expand(n, 3).clone()
    return {
        "means": centre.float().cpu()[None] + radius * dirs,
        "log_scales": log_scales,
        "quats": rotmat_to_quat(_tangent_frames(dirs)),
        "opacity_logits": torch.full((n,), float(logit(opacity))),
        "features_dc": rgb_to_sh(colors.clamp(0.0, 1.0)),
        "features_rest": torch.zeros(n, sh_rest, 3),
    }


def concat_gaussians(a: dict[str, Tensor], b: dict[str, Tensor]) -> dict[str, Tensor]:
    """Two Gaussian sets in the PLY layout -> one (``b``'s SH rest padded or cut to ``a``'s)."""
    out = {}
    for key, va in a.items():
        vb = b[key].to(va)
        if key == "features_rest" and vb.shape[1] != va.shape[1]:
            vb = torch.zeros(vb.shape[0], va.shape[1], 3, dtype=va.dtype, device=va.device)
        out[key] = torch.cat([va, vb], dim=0)
    return out


def sh_degree_of(features_rest: Tensor) -> int:
    """SH degree of ``[N, K-1, 3]`` rest coefficients."""
    k = features_rest.shape[1] + 1
    degree = int(round(math.sqrt(k))) - 1
    if num_sh_bases(degree) != k:
        raise ValueError(f"{k} SH coefficients is no complete degree")
    return degree
