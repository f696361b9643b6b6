"""Reject a ground plane that is not one: tilted far from the cameras' own up.

``data.ground.fit_ground_plane`` gates its RANSAC hypotheses at 30 deg from the cameras' up, but its
least-squares refit and its scale-free inlier threshold (a fraction of the camera height above the
plane: larger for planes far below, or steep) can drift onto a sloped roof line or the foot of the
walls. On the castle-P30 courtyard (30 walking photos) it returned a plane 39 deg off the true up and
a metric scale 7.6x too small. People hold cameras roughly level, so a plane whose normal is further
than ``max_tilt_deg`` from the cameras' mean up is not trusted: the caller falls back (the cameras'
up, and ``--metres-per-unit`` for the scale).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

MAX_TILT_DEG = 30.0


def tilt_deg(normal: np.ndarray, cam_up: np.ndarray) -> float:
    """Angle between a plane normal and the cameras' mean up, degrees."""
    n = np.asarray(normal, dtype=np.float64)
    u = np.asarray(cam_up, dtype=np.float64)
    c = float(n @ u / (np.linalg.norm(n) * np.linalg.norm(u) + 1e-12))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def credible(plane, cam_up: np.ndarray, max_tilt_deg: float = MAX_TILT_DEG) -> Optional[str]:
    """None when ``plane`` is credible, else the one-line reason it is not."""
    if plane is None:
        return "no ground plane found below the cameras"
    t = tilt_deg(plane.normal, cam_up)
    if t > max_tilt_deg:
        return f"the ground plane found is tilted {t:.0f} deg from the cameras' up (more than {max_tilt_deg:.0f})"
    return None
