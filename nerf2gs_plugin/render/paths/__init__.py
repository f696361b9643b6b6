"""Camera paths, one module per kind; importing the package registers them all."""

from __future__ import annotations

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.render.paths import birds_eye, camera_path_file, interpolate, lane_shift, orbit  # noqa: F401
from nerf2gs_plugin.render.paths.registry import PATHS, PathOptions, register_path  # noqa: F401
from nerf2gs_plugin.render.scene import PathContext


def make_path(name: str, ctx: PathContext, opts: PathOptions) -> Cameras:
    """The cameras of path kind ``name``."""
    if name not in PATHS:
        raise ConfigError(f"--path {name}: unknown camera path; known: {', '.join(sorted(PATHS))}")
    cams = PATHS[name](ctx, opts)
    if len(cams) == 0:
        raise ConfigError(f"--path {name}: the path has no cameras")
    return cams
