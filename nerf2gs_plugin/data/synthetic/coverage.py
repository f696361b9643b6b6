"""What an eval view sees that no training view saw: the paper's problem, measured exactly.

For each ground pixel (road or sidewalk) of an eval view we take its surface point and its viewing
direction, and ask every training camera whether it saw that point (inside its image, in front,
and not hidden: the training depth map at the projection agrees with the point's depth, so a car
or a pole in front counts as not seen) and from within ``angle_deg`` of the eval view's direction.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from nerf2gs_plugin.data.synthetic.raycast import Pinhole


def ground_coverage(
    points: Tensor,
    eye: Tensor,
    train_c2w: Tensor,
    train_depth: Tensor,
    intr: Pinhole,
    angle_deg: float = 15.0,
) -> tuple[int, int, int]:
    """Ground points ``[M, 3]`` seen from ``eye [3]`` -> ``(M, unseen_at_similar_angle, unseen_at_all)``.

    ``train_c2w [J, 3, 4]`` OpenGL, ``train_depth [J, H, W]`` z-depth in metres (0 = sky)."""
    M = points.shape[0]
    if M == 0:
        return 0, 0, 0
    view = torch.nn.functional.normalize(points - eye, dim=-1)  # [M, 3]
    R = train_c2w[:, :, :3]  # [J, 3, 3] columns: right, up, back
    C = train_c2w[:, :, 3]
    rel = points[None] - C[:, None]  # [J, M, 3]
    cam = torch.einsum("jmk,jkc->jmc", rel, R)  # camera coordinates (OpenGL)
    z = -cam[..., 2]
    zs = z.clamp(min=1e-3)
    u = intr.fx * cam[..., 0] / zs + intr.cx
    v = intr.cy - intr.fy * cam[..., 1] / zs
    inside = (z > 0.1) & (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
    ui = u.clamp(0, intr.width - 1).long()
    vi = v.clamp(0, intr.height - 1).long()
    J = train_c2w.shape[0]
    d = train_depth.reshape(J, -1).gather(1, vi * intr.width + ui)  # [J, M]
    # nearest-pixel depth at grazing angles varies fast across a pixel: a generous relative tolerance
    visible = inside & (d > 0) & ((z - d).abs() < 0.25 + 0.06 * z)
    cos_sim = (torch.nn.functional.normalize(rel, dim=-1) * view[None]).sum(-1)
    similar = visible & (cos_sim >= math.cos(math.radians(angle_deg)))
    return M, int((~similar.any(0)).sum()), int((~visible.any(0)).sum())
