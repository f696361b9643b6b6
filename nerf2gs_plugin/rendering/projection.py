"""World -> camera -> pixels for 3D Gaussians: EWA projection of the covariances (differentiable).

Conventions (as gsplat): view matrices are world-to-camera in OpenCV axes (x right, y down,
z forward); pixel centres sit at ``(i + 0.5, j + 0.5)``; quaternions are ``wxyz``. The 2D
covariance gets ``eps2d = 0.3`` px^2 added (the low-pass filter of 3DGS); ``compensation`` is
``sqrt(det(cov) / det(cov + eps2d I))``, by which ``rasterize_mode="antialiased"`` scales the
opacities (Mip-Splatting's 2D filter, gsplat's antialiased mode).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from nerf2gs_plugin.utils.quaternions import quat_to_rotmat

EPS2D = 0.3


def covariance_3d(quats: Tensor, scales: Tensor) -> Tensor:
    """World covariances ``R S S^T R^T`` ``[N, 3, 3]`` from quats ``[N, 4]`` and scales ``[N, 3]``."""
    m = quat_to_rotmat(quats, normalize=False) * scales[..., None, :]
    return m @ m.transpose(-1, -2)


def world_to_camera(means: Tensor, viewmats: Tensor) -> Tensor:
    """Points ``[N, 3]`` into each camera's frame: ``[C, N, 3]``."""
    r, t = viewmats[:, :3, :3], viewmats[:, :3, 3]
    return torch.einsum("cij,nj->cni", r, means) + t[:, None, :]


def camera_centers(viewmats: Tensor) -> Tensor:
    """Camera centres in world ``[C, 3]`` from world-to-camera matrices ``[C, 4, 4]``."""
    r, t = viewmats[:, :3, :3], viewmats[:, :3, 3]
    return -torch.einsum("cji,cj->ci", r, t)


@dataclass
class Projected:
    """Per camera and Gaussian screen-space quantities (C cameras, N Gaussians)."""

    means2d: Tensor  # [C, N, 2] pixel coordinates of the projected means (differentiable)
    conics: Tensor  # [C, N, 3] inverse 2D covariance (a, b, c): sigma = 0.5(a dx^2 + c dy^2) + b dx dy
    depths: Tensor  # [C, N] camera-space z (differentiable)
    radii: Tensor  # [C, N] int32, 3-sigma pixel radius; 0 = culled (near/far, degenerate, off-screen)
    compensations: Tensor  # [C, N] sqrt(det cov / det(cov + eps2d)), the antialiasing opacity factor
    cov2d: Tensor  # [C, N, 2, 2] 2D covariance including the eps2d low-pass (differentiable)


def project_gaussians(
    means: Tensor, quats: Tensor, scales: Tensor, viewmats: Tensor, Ks: Tensor, width: int, height: int,
    near_plane: float = 0.01, far_plane: float = 1e10, eps2d: float = EPS2D, covars: Tensor | None = None,
) -> Projected:
    """EWA-project Gaussians ``means [N,3]``, ``quats [N,4]``, ``scales [N,3]`` into cameras
    ``viewmats [C,4,4]``, ``Ks [C,3,3]`` of size ``width x height``.

    The perspective Jacobian is evaluated at the mean with x/z and y/z clamped to 1.3x the field of
    view (as 3DGS/gsplat) so Gaussians near the image border do not blow up. Culled Gaussians
    (behind the near plane, beyond the far plane, degenerate 2D covariance, or whose 3-sigma box
    misses the image) get radius 0.
    """
    pts = world_to_camera(means, viewmats)  # [C, N, 3]
    r = viewmats[:, :3, :3]
    if covars is None:  # cov_cam = M M^T with M = R_v R_q S  [C, N, 3, 3]
        m = torch.einsum("cij,njk->cnik", r, quat_to_rotmat(quats, normalize=False) * scales[..., None, :])
    else:  # given (possibly singular) world covariances [N, 3, 3]
        cov_c = torch.einsum("cij,njk,clk->cnil", r, covars, r)

    fx, fy = Ks[:, 0, 0, None], Ks[:, 1, 1, None]  # [C, 1]
    cx, cy = Ks[:, 0, 2, None], Ks[:, 1, 2, None]
    x, y, z = pts.unbind(-1)
    in_depth = (z > near_plane) & (z < far_plane)
    zs = torch.where(in_depth, z, torch.ones_like(z))  # keep culled ones finite (no NaN grads)
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_xp, lim_xn = (width - cx) / fx + 0.3 * tan_fovx, cx / fx + 0.3 * tan_fovx
    lim_yp, lim_yn = (height - cy) / fy + 0.3 * tan_fovy, cy / fy + 0.3 * tan_fovy
    tx = zs * torch.minimum(lim_xp, torch.maximum(-lim_xn, x / zs))
    ty = zs * torch.minimum(lim_yp, torch.maximum(-lim_yn, y / zs))
    # rows of J M with the perspective Jacobian J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]]
    iz = 1.0 / zs
    if covars is None:
        m0, m1, m2 = m.unbind(-2)
        u = (fx * iz)[..., None] * m0 - (fx * tx * iz * iz)[..., None] * m2  # [C, N, 3]
        v = (fy * iz)[..., None] * m1 - (fy * ty * iz * iz)[..., None] * m2
        cxx, cxy, cyy = (u * u).sum(-1), (u * v).sum(-1), (v * v).sum(-1)
    else:
        zero = torch.zeros_like(zs)
        j0 = torch.stack([fx * iz, zero, -fx * tx * iz * iz], -1)  # [C, N, 3]
        j1 = torch.stack([zero, fy * iz, -fy * ty * iz * iz], -1)
        cj0, cj1 = (cov_c @ j0[..., None])[..., 0], (cov_c @ j1[..., None])[..., 0]
        cxx, cxy, cyy = (j0 * cj0).sum(-1), (j0 * cj1).sum(-1), (j1 * cj1).sum(-1)
    cov2d = torch.stack([cxx, cxy, cxy, cyy], -1).reshape(*zs.shape, 2, 2)

    a, b, c = cov2d[..., 0, 0], cov2d[..., 0, 1], cov2d[..., 1, 1]
    det_orig = a * c - b * b
    a, c = a + eps2d, c + eps2d
    det = a * c - b * b
    valid = in_depth & (det > 0)
    det_s = torch.where(valid, det, torch.ones_like(det))
    comp = torch.sqrt(torch.clamp_min(det_orig / det_s, 0.0))
    conics = torch.stack([c / det_s, -b / det_s, a / det_s], dim=-1)
    means2d = torch.stack([fx * x / zs + cx, fy * y / zs + cy], dim=-1)
    cov2d_f = torch.stack([a, b, b, c], dim=-1).reshape(*a.shape, 2, 2)

    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam = mid + torch.sqrt(torch.clamp_min(mid * mid - det, 0.01))
        radius = torch.ceil(3.0 * torch.sqrt(lam))
        mx, my = means2d[..., 0], means2d[..., 1]
        on_screen = (mx + radius > 0) & (mx - radius < width) & (my + radius > 0) & (my - radius < height)
        keep = valid & on_screen & torch.isfinite(radius)
        radii = torch.where(keep, radius, torch.zeros_like(radius)).to(torch.int32)
    return Projected(means2d, conics, z, radii, comp, cov2d_f)
