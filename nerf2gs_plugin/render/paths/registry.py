"""The one registry of camera-path kinds: each kind is a module that registers a function
``(PathContext, PathOptions) -> Cameras`` under its name."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.render.scene import PathContext


@dataclass
class PathOptions:
    """What the path kinds read (lengths in metres, angles in degrees)."""

    height: float = 10.0
    """birds-eye fly-over and orbit: height above the capture's cameras (the augmentation's default delta-h)."""
    pitch: float = 30.0
    """birds-eye fly-over: pitch below the horizon (the augmentation's default theta-pitch)."""
    fly_over: bool = False
    """birds-eye: the fly-over even when the run has its augmentation's own bird's-eye views."""
    interpolation_steps: int = 10
    """interpolate: frames from one training camera to the next."""
    frames: int = 90
    """orbit: frames in one turn."""
    radius: Optional[float] = None
    """orbit: radius around the scene centre (default: the capture's horizontal extent from its centre)."""
    offset: float = 3.0
    """lane-shift: metres sideways along the ground's lateral axis (positive: to the right)."""
    camera_path_file: Optional[Path] = None
    """A nerfstudio camera_path.json (its own path kind, 'camera-path')."""


PathFn = Callable[[PathContext, PathOptions], Cameras]
PATHS: dict[str, PathFn] = {}


def register_path(name: str) -> Callable[[PathFn], PathFn]:
    def add(fn: PathFn) -> PathFn:
        PATHS[name] = fn
        return fn

    return add
