"""Where the bird's-eye (additional) views are: one value in the user's units (metres, degrees),
turned into world units in one place, when it makes the cameras. The augmentation renders at them,
the cache manifest records them with their poses, and the viewer and the export read those back."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras, raise_and_pitch
from nerf2gs_plugin.errors import ConfigError


class WorldFrame(Protocol):
    """What the geometry needs of a dataset (``DataparserOutputs`` is one)."""

    up: Tensor

    def metres_to_world(self, metres: float) -> float: ...


@dataclass(frozen=True)
class ViewGeometry:
    """The ``--augment.*`` fields that place the additional views (compared as a whole)."""

    delta_h: float
    """Height above the input view, metres."""
    theta_pitch: float
    """Pitch down, degrees (below the ground plane's horizon, or added to the input's tilt: ``pitch_mode``)."""
    every_n: int = 1
    pitch_mode: str = "absolute"
    delta_h_spread: float = 0.0
    """Each view's height drawn in delta-h +- this, metres (0: all at delta-h)."""
    theta_pitch_spread: float = 0.0
    """Each view's pitch drawn in theta-pitch +- this, degrees."""

    def __post_init__(self) -> None:  # one type per field, so that equality is the fields' equality
        for name, kind in (("delta_h", float), ("theta_pitch", float), ("every_n", int), ("pitch_mode", str),
                           ("delta_h_spread", float), ("theta_pitch_spread", float)):
            object.__setattr__(self, name, kind(getattr(self, name)))

    @classmethod
    def of(cls, augment: Any) -> ViewGeometry:
        """The geometry of an ``AugmentConfig`` (``every_n`` below 1 means every view)."""
        return cls(augment.delta_h, augment.theta_pitch, max(int(augment.every_n), 1), augment.pitch_mode,
                   augment.delta_h_spread, augment.theta_pitch_spread)

    @classmethod
    def recorded(cls, config: dict[str, Any]) -> ViewGeometry:
        """The geometry a cache manifest's plain config recorded; an entry written before an option
        existed has that option's old behaviour (relative pitch, no spreads)."""
        return cls(config.get("delta_h", -1), config.get("theta_pitch", -1), config.get("every_n", 1),
                   config.get("pitch_mode", "relative"), config.get("delta_h_spread", 0.0),
                   config.get("theta_pitch_spread", 0.0))

    def sources(self, train: Cameras) -> Cameras:
        """The input cameras the views are raised from (every ``every_n``-th)."""
        return train[torch.arange(0, len(train), max(self.every_n, 1))]

    def cameras(self, train: Cameras, world: WorldFrame) -> Cameras:
        """The additional-view cameras: input intrinsics, raised and pitched poses (with spreads: each
        view's height and pitch drawn uniformly around delta-h / theta-pitch, the same draws on every
        call). The one place where the heights become world units."""
        sub = self.sources(train)
        if self.pitch_mode not in ("absolute", "relative"):
            raise ConfigError(f"--augment.pitch-mode must be absolute or relative, got {self.pitch_mode!r}")
        delta_h_world, spread_world = world.metres_to_world(self.delta_h), world.metres_to_world(self.delta_h_spread)
        if spread_world < 0 or not 0 <= self.theta_pitch_spread < 90:
            raise ConfigError(f"spreads must be >= 0 (pitch < 90 deg), got {spread_world}, {self.theta_pitch_spread}",
                              "--augment.delta-h-spread / --augment.theta-pitch-spread")
        dh: float | Tensor = delta_h_world
        pitch: float | Tensor = self.theta_pitch
        if spread_world > 0 or self.theta_pitch_spread > 0:
            u = torch.rand(2, len(sub), generator=torch.Generator().manual_seed(0), dtype=torch.float64) * 2 - 1
            dh = (delta_h_world + spread_world * u[0]).clamp_min(0.0)
            pitch = (self.theta_pitch + self.theta_pitch_spread * u[1]).clamp(0.0, 89.0)
        return sub.with_poses(raise_and_pitch(sub.camera_to_worlds, world.up, dh, pitch, self.pitch_mode))
