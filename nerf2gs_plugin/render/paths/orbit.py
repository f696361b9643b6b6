"""``--path orbit``: one turn around the scene centre (the mean of the capture's cameras), ``--height``
metres above it, looking at the centre."""

from __future__ import annotations

import math

import torch

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.render.paths.registry import PathOptions, register_path
from nerf2gs_plugin.render.scene import PathContext


def ground_basis(up: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Two unit vectors spanning the ground plane of normal ``up``."""
    helper = torch.tensor([1.0, 0.0, 0.0]) if abs(float(up[0])) < 0.9 else torch.tensor([0.0, 1.0, 0.0])
    a = torch.nn.functional.normalize(torch.cross(up, helper.to(up), dim=0), dim=0)
    return a, torch.cross(up, a, dim=0)


@register_path("orbit")
def orbit(ctx: PathContext, opts: PathOptions) -> Cameras:
    up = ctx.up
    centres = ctx.train.centers
    centre = centres.mean(0)
    flat = (centres - centre) - ((centres - centre) @ up)[:, None] * up
    radius = ctx.metres(opts.radius) if opts.radius is not None else float(flat.norm(dim=-1).max().clamp_min(1e-3))
    a, b = ground_basis(up)
    n = max(int(opts.frames), 1)
    ang = torch.arange(n, dtype=torch.float32) * (2 * math.pi / n)
    eye = centre + radius * (torch.cos(ang)[:, None] * a + torch.sin(ang)[:, None] * b) + ctx.metres(opts.height) * up
    c2w = look_at(eye, centre.expand(n, 3), up)
    first = ctx.train[0]
    return Cameras(c2w, fx=first.fx, fy=first.fy, cx=first.cx, cy=first.cy, width=first.width, height=first.height)
