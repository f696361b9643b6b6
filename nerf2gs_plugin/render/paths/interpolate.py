"""``--path interpolate``: a smooth path through the training cameras, in capture order: positions
on a Catmull-Rom spline (it passes through every camera, with continuous velocity), orientations
slerped between neighbours; ``--interpolation-steps`` frames per transition, so frame ``k * steps``
is training camera ``k`` exactly."""

from __future__ import annotations

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.render.paths.registry import PathOptions, register_path
from nerf2gs_plugin.render.scene import PathContext
from nerf2gs_plugin.utils.quaternions import quat_to_rotmat, rotmat_to_quat


def catmull_rom(points: Tensor, seg: Tensor, t: Tensor) -> Tensor:
    """Points on the uniform Catmull-Rom spline through ``points [K, 3]``: segment ``seg`` (long
    ``[M]``, from point ``seg`` to ``seg + 1``) at ``t [M]`` in [0, 1]; the ends repeat."""
    k = len(points)
    p0, p1 = points[(seg - 1).clamp(0, k - 1)], points[seg]
    p2, p3 = points[(seg + 1).clamp(0, k - 1)], points[(seg + 2).clamp(0, k - 1)]
    t = t[:, None]
    return 0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2 + (3 * p1 - p0 - 3 * p2 + p3) * t**3)


def slerp(q0: Tensor, q1: Tensor, t: Tensor) -> Tensor:
    """Spherical interpolation of unit quaternions ``[M, 4]`` at ``t [M]`` (the short way round)."""
    dot = (q0 * q1).sum(-1, keepdim=True)
    q1 = torch.where(dot < 0, -q1, q1)
    dot = dot.abs().clamp(max=1.0)
    theta = torch.acos(dot)
    s = torch.sin(theta)
    t = t[:, None]
    near = s < 1e-6  # (almost) the same rotation: linear is exact enough and avoids 0 / 0
    w0 = torch.where(near, 1 - t, torch.sin((1 - t) * theta) / s.clamp_min(1e-12))
    w1 = torch.where(near, t, torch.sin(t * theta) / s.clamp_min(1e-12))
    return torch.nn.functional.normalize(w0 * q0 + w1 * q1, dim=-1)


@register_path("interpolate")
def interpolate(ctx: PathContext, opts: PathOptions) -> Cameras:
    cams = ctx.train
    k, steps = len(cams), max(int(opts.interpolation_steps), 1)
    if k < 2:
        return cams
    u = torch.arange((k - 1) * steps + 1, dtype=torch.float32) / steps
    seg = u.floor().long().clamp(max=k - 2)
    t = u - seg
    c2w = cams.camera_to_worlds
    pos = catmull_rom(c2w[:, :, 3], seg, t)
    q = rotmat_to_quat(c2w[:, :, :3])
    R = quat_to_rotmat(slerp(q[seg], q[seg + 1], t))
    nearest = torch.where(t < 0.5, seg, seg + 1)  # intrinsics of the nearer training camera
    return cams[nearest].with_poses(torch.cat([R, pos[:, :, None]], dim=-1))
