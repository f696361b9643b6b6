"""``--path birds-eye``: the views from above that the run's augmentation trained on (read back from
its reference's cache manifest), else a fly-over ``--height`` metres above the capture's cameras,
pitched ``--pitch`` degrees below the horizon."""

from __future__ import annotations

from nerf2gs_plugin.cameras import Cameras, birds_eye_poses_absolute
from nerf2gs_plugin.render.paths.registry import PathOptions, register_path
from nerf2gs_plugin.render.scene import PathContext


def fly_over(ctx: PathContext, height_m: float, pitch_deg: float) -> Cameras:
    """Every training camera raised ``height_m`` along the ground's up and pitched down (no roll)."""
    return ctx.train.with_poses(birds_eye_poses_absolute(ctx.train.camera_to_worlds, ctx.up, ctx.metres(height_m), pitch_deg))


@register_path("birds-eye")
def birds_eye(ctx: PathContext, opts: PathOptions) -> Cameras:
    if ctx.augment_views is not None and len(ctx.augment_views) and not opts.fly_over:
        return ctx.augment_views
    return fly_over(ctx, opts.height, opts.pitch)
