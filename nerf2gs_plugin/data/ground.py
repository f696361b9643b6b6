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


def fit_ground_plane(points: np.ndarray, cam_centres: np.ndarray, cam_up: Optional[np.ndarray] = None,
                     iterations: int = 2000, rel_thresh: float = 0.05, max_tilt_deg: float = 30.0,
                     min_inliers: int = 15, seed: int = 0) -> Optional[GroundPlane]:
    """RANSAC plane over points below the cameras; ``None`` when no credible plane exists.

    ``cam_up`` (the cameras' mean up axis in data units) selects the candidate points (below the
    median camera along it) and rejects planes tilted more than ``max_tilt_deg`` from it (walls).
    Scale-free: a point is an inlier when its distance to the plane is below ``rel_thresh`` x the
    median camera height above that plane; the best plane is refitted by least squares on its inliers.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cams = np.asarray(cam_centres, dtype=np.float64).reshape(-1, 3)
    if len(cams) == 0 or len(pts) < min_inliers:
        return None
    up = np.asarray(cam_up, dtype=np.float64) if cam_up is not None else np.array([0.0, 0.0, 1.0])
    up = up / (np.linalg.norm(up) + 1e-12)
    cand = pts[pts @ up < np.median(cams @ up)]
    if len(cand) < min_inliers:
        return None
    rng = np.random.default_rng(seed)
    tri = cand[rng.integers(0, len(cand), size=(iterations, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n, p0 = n[ok] / norm[ok, None], tri[ok, 0]
    n = n * np.where(n @ up < 0, -1.0, 1.0)[:, None]  # point toward the cameras' up
    ok = n @ up > np.cos(np.radians(max_tilt_deg))
    if not ok.any():
        return None
    n, p0 = n[ok], p0[ok]
    d = -(n * p0).sum(1)
    cam_h = np.median(cams @ n.T + d, axis=0)  # [T] median camera height above each hypothesis
    valid = cam_h > 0
    counts = np.zeros(len(n), dtype=np.int64)
    for s in range(0, len(n), 64):  # chunks of hypotheses: no loop over points
        sl = slice(s, s + 64)
        counts[sl] = (np.abs(cand @ n[sl].T + d[sl]) < rel_thresh * np.abs(cam_h[sl])).sum(0)
    counts[~valid] = 0
    if counts.max() < min_inliers:
        return None
    best = int(counts.argmax())
    normal, offset, med = n[best], float(d[best]), float(cam_h[best])
    for _ in range(3):  # least-squares refit on the inliers (smallest singular vector), oriented up
        inl = cand[np.abs(cand @ normal + offset) < rel_thresh * med]
        if len(inl) < 3:
            return None
        c = inl.mean(0)
        normal = np.linalg.svd(inl - c, full_matrices=False)[2][-1]
        normal = normal if normal @ up > 0 else -normal
        offset = float(-normal @ c)
        med = float(np.median(cams @ normal + offset))
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


def scale_from_frames(train_c2w, points_xyz, camera_height: float, where) -> tuple[float, "np.ndarray"]:
    """Metres-per-unit and up for a parsed dataset (``--pipeline.datamanager.camera-height``):
    train cameras ``[N, 3, 4]`` OpenGL (their y axis is up) and the sparse points, original frame."""
    c2w = np.asarray(train_c2w, dtype=np.float64)
    if points_xyz is None or len(points_xyz) == 0:
        raise DataError("--camera-height needs sparse points (a COLMAP model or ply_file_path) to find the ground; "
                        "pass --metres-per-unit instead", where)
    s = estimate_metric_scale(np.asarray(points_xyz), c2w[:, :, 3], c2w[:, :, 1].mean(0), camera_height, where=where)
    print(f"metric scale: {s.metres_per_unit:.4g} metres per data unit (camera {camera_height} m above the ground plane)")
    return s.metres_per_unit, s.up
