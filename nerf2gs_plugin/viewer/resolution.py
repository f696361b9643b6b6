"""Adaptive render resolution: interactive while the camera moves, full detail when it rests.

The cost of a frame is modelled as proportional to its pixel count (an exponential moving average
of measured seconds per pixel). While the camera moves, each frame gets the largest scale that
fits the frame budget (``1 / target_fps``), so a slow last frame lowers the next one's resolution.
When the camera rests the scale climbs to full resolution: in one step when a full frame is
cheap, else doubling per frame (progressive refinement for slow NeRF methods).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional


@dataclass
class AdaptiveResolution:
    max_side: int = 640
    """Longest side of a full-resolution frame (the browser canvas is capped to this)."""
    target_fps: float = 10.0
    """Frame budget while the camera moves."""
    min_side: int = 32
    """Shortest side never goes below this (or the full frame's, if smaller)."""
    smoothing: float = 0.5
    """Weight of the newest measurement in the seconds-per-pixel average."""
    initial_scale: float = 0.25
    """Scale of the very first moving frame, before anything was measured."""
    sec_per_pixel: Optional[float] = field(default=None)

    @property
    def budget(self) -> float:
        return 1.0 / self.target_fps

    def full_size(self, canvas_w: int, canvas_h: int) -> tuple[int, int]:
        """Full-resolution frame for a canvas: its aspect, long side at most ``max_side``."""
        canvas_w, canvas_h = max(int(canvas_w), 1), max(int(canvas_h), 1)
        s = min(1.0, self.max_side / max(canvas_w, canvas_h))
        return max(1, round(canvas_w * s)), max(1, round(canvas_h * s))

    def record(self, width: int, height: int, seconds: float) -> None:
        """Feed the measured time of a rendered frame."""
        rate = max(seconds, 1e-6) / max(width * height, 1)
        if self.sec_per_pixel is None:
            self.sec_per_pixel = rate
        else:
            self.sec_per_pixel = self.smoothing * rate + (1.0 - self.smoothing) * self.sec_per_pixel

    def predicted_seconds(self, width: int, height: int) -> Optional[float]:
        return None if self.sec_per_pixel is None else self.sec_per_pixel * width * height

    def _min_scale(self, full_w: int, full_h: int) -> float:
        return min(1.0, self.min_side / max(min(full_w, full_h), 1))

    def moving_scale(self, full_w: int, full_h: int) -> float:
        """Largest scale whose predicted frame time fits the budget."""
        lo = self._min_scale(full_w, full_h)
        if self.sec_per_pixel is None:
            return max(lo, min(1.0, self.initial_scale))
        full_time = self.sec_per_pixel * full_w * full_h
        return max(lo, min(1.0, math.sqrt(self.budget / max(full_time, 1e-12))))

    def resting_scale(self, full_w: int, full_h: int, last_scale: Optional[float]) -> float:
        """Next scale once the camera rests: full when affordable, else double the last one
        (starting from the moving scale), so a slow model refines progressively."""
        if self.sec_per_pixel is None or self.sec_per_pixel * full_w * full_h <= 4.0 * self.budget:
            return 1.0
        base = last_scale if last_scale is not None else self.moving_scale(full_w, full_h)
        scale = max(base, self._min_scale(full_w, full_h)) * 2.0
        return 1.0 if scale >= 0.7 else scale  # no near-full intermediate step

    @staticmethod
    def frame_size(full_w: int, full_h: int, scale: float) -> tuple[int, int]:
        """Pixel size of a frame at ``scale`` of the full one (aspect kept, at least 1x1)."""
        return max(1, round(full_w * scale)), max(1, round(full_h * scale))
