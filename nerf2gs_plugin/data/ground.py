"""Metric scale and up for captures without them: the ground plane under the cameras.

Why: SfM gives poses in arbitrary units and axes, yet ``--augment.delta-h`` is metres and "down"
must mean the road. A car-mounted (or hand-held) camera moves at a roughly known height over a
roughly planar road, so: fit a plane by RANSAC to the sparse points below the cameras, take its
normal (pointing to the cameras) as up, and metres-per-unit = camera height / the median camera
height above the plane.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from nerf2gs_plugin.errors import DataError


@dataclass
class GroundPlane:
    normal: np.ndarray  # [3] unit, pointing from the ground to the cameras (= up)
    offset: float  # plane: normal . x + offset = 0
    inliers: int
    candidates: int
    median_camera_height: float  # in data units

    def height(self, x: np.ndarray) -> np.ndarray:
        """Signed height of points ``[N, 3]`` above the plane."""
        return np.asarray(x, dtype=np.float64) @ self.normal + self.offset

    def to_json(self) -> dict:
        return {"normal": [float(v) for v in self.normal], "offset": float(self.offset), "inliers": self.inliers,
                "candidates": self.candidates, "median_camera_height": float(self.median_camera_height)}


def _plane_from_3(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normals ``[T, 3]`` (unnormalised, may be ~0 for degenerate triples) and a point per trial."""
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 0]


def fit_ground_plane(points: np.ndarray, cam_centres: np.ndarray, cam_up: Optional[np.ndarray] = None,
                     iterations: int = 500, inlier_frac: float = 0.01, max_tilt_deg: float = 45.0,
                     min_inliers: int = 30, seed: int = 0) -> Optional[GroundPlane]:
    """RANSAC plane over points below the cameras; ``None`` when no credible plane exists.

    ``cam_up`` (the cameras' mean up axis in data units) selects the candidate points (below the
    median camera along it) and rejects planes tilted more than ``max_tilt_deg`` from it (walls).
    The inlier threshold is ``inlier_frac`` of the camera trajectory's extent (plus 1% of the point
    spread so a static capture still has a scale to work with).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cams = np.asarray(cam_centres, dtype=np.float64).reshape(-1, 3)
    if len(cams) == 0 or len(pts) < min_inliers:
        return None
    up = np.asarray(cam_up, dtype=np.float64) if cam_up is not None else np.array([0.0, 0.0, 1.0])
    up = up / (np.linalg.norm(up) + 1e-12)
    cam_h = cams @ up
    cand = pts[pts @ up < np.median(cam_h)]
    if len(cand) < min_inliers:
        return None
    lo, hi = np.percentile(pts, [5, 95], axis=0)
    extent = float(np.linalg.norm(cams.max(0) - cams.min(0)))
    thresh = inlier_frac * extent + 0.01 * float(np.linalg.norm(hi - lo))
    rng = np.random.default_rng(seed)
    tri = cand[rng.integers(0, len(cand), size=(iterations, 3))]
    n, p0 = _plane_from_3(tri)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n = n[ok] / norm[ok, None]
    p0 = p0[ok]
    n = n * np.sign(n @ up)[:, None]  # point toward the cameras' up
    n[np.sign(n @ up) == 0] = up
    ok = n @ up > np.cos(np.radians(max_tilt_deg))
    if not ok.any():
        return None
    n, p0 = n[ok], p0[ok]
    d = -(n * p0).sum(1)
    # Count inliers per hypothesis in chunks (no loop over points).
    counts = np.zeros(len(n), dtype=np.int64)
    for s in range(0, len(n), 64):
        counts[s:s + 64] = (np.abs(cand @ n[s:s + 64].T + d[s:s + 64]) < thresh).sum(0)
    best = int(counts.argmax())
    inl = cand[np.abs(cand @ n[best] + d[best]) < thresh]
    if len(inl) < min_inliers:
        return None
    # Least-squares refit on the inliers (smallest singular vector), oriented up.
    c = inl.mean(0)
    normal = np.linalg.svd(inl - c, full_matrices=False)[2][-1]
    normal = normal if normal @ up > 0 else -normal
    offset = float(-normal @ c)
    heights = cams @ normal + offset
    med = float(np.median(heights))
    if not med > 0:
        return None
    return GroundPlane(normal, offset, int(len(inl)), int(len(cand)), med)


@dataclass
class MetricScale:
    metres_per_unit: float
    up: np.ndarray  # [3] in data units
    source: str  # "camera-height" | "override"
    plane: Optional[GroundPlane] = None


def estimate_metric_scale(points: np.ndarray, cam_centres: np.ndarray, cam_up: np.ndarray, camera_height: float = 1.5,
                          metres_per_unit: Optional[float] = None, where: str = "sparse points") -> MetricScale:
    """Up and metres-per-unit from the ground plane (``metres_per_unit`` overrides the scale; the
    plane still gives up when found). No plane and no override: a DataError naming the flags."""
    plane = fit_ground_plane(points, cam_centres, cam_up)
    if metres_per_unit is not None:
        if not metres_per_unit > 0:
            raise DataError(f"--metres-per-unit must be positive, got {metres_per_unit}", where)
        up = plane.normal if plane is not None else np.asarray(cam_up, dtype=np.float64) / np.linalg.norm(cam_up)
        return MetricScale(float(metres_per_unit), up, "override", plane)
    if plane is None:
        raise DataError("no ground plane found below the cameras to set the metric scale: pass --metres-per-unit "
                        "(metres per data unit) instead", where)
    if not camera_height > 0:
        raise DataError(f"--camera-height must be positive, got {camera_height}", where)
    return MetricScale(float(camera_height / plane.median_camera_height), plane.normal, "camera-height", plane)
