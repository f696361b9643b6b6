"""``--path lane-shift --offset M``: the drive re-driven ``M`` metres sideways, along the ground
plane's lateral axis (not the camera's own x axis, which a rolled camera tilts)."""

from __future__ import annotations

from nerf2gs_plugin.cameras import Cameras, ground_lateral
from nerf2gs_plugin.render.paths.registry import PathOptions, register_path
from nerf2gs_plugin.render.scene import PathContext


@register_path("lane-shift")
def lane_shift(ctx: PathContext, opts: PathOptions) -> Cameras:
    c2w = ctx.train.camera_to_worlds.clone()
    c2w[:, :, 3] += ctx.metres(opts.offset) * ground_lateral(c2w, ctx.up)
    return ctx.train.with_poses(c2w)
