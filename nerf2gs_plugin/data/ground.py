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


MAX_TILT_DEG = 30.0
"""The steepest ground plane trusted, degrees between its normal and the cameras' mean up: people and
cars hold cameras roughly level, so a steeper plane is a wall, a roof line or the foot of the walls.
The one place this limit lives (RANSAC, the refit and every caller use it)."""


def fit_ground_plane(points: np.ndarray, cam_centres: np.ndarray, cam_up: Optional[np.ndarray] = None,
                     iterations: int = 2000, rel_thresh: float = 0.05, max_tilt_deg: float = MAX_TILT_DEG,
                     min_inliers: int = 15, seed: int = 0) -> Optional[GroundPlane]:
    """RANSAC plane over points below the cameras; ``None`` when no credible plane exists.

    ``cam_up`` (the cameras' mean up axis in data units) selects the candidate points (below the
    median camera along it) and bounds the plane: its normal is never more than ``max_tilt_deg``
    from it, neither for a RANSAC hypothesis nor after the refit. The best hypothesis is refitted by
    least squares on its inliers (three rounds); a refit that tilts past the limit (or loses the
    cameras above it, or its inliers) is dropped and the RANSAC plane kept.

    Inlier band (scale-free, the same for every hypothesis and the refit): a point is an inlier when
    its distance to the plane is below ``rel_thresh`` x the reference height, the median over the
    candidate points of the median camera's height above them along ``cam_up``. It is not each
    hypothesis's own camera height: that grows for planes tilted or far below the cameras and gave
    them a wider band, so they won by counting walls (on castle-P30 a steeply tilted plane far below
    the cameras, where this band finds the courtyard floor).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cams = np.asarray(cam_centres, dtype=np.float64).reshape(-1, 3)
    if len(cams) == 0 or len(pts) < min_inliers:
        return None
    up = np.asarray(cam_up, dtype=np.float64) if cam_up is not None else np.array([0.0, 0.0, 1.0])
    up = up / (np.linalg.norm(up) + 1e-12)
    cam_level = np.median(cams @ up)
    cand = pts[pts @ up < cam_level]
    if len(cand) < min_inliers:
        return None
    band = rel_thresh * float(np.median(cam_level - cand @ up))  # > 0: every candidate is below cam_level
    cos_limit = np.cos(np.radians(max_tilt_deg))
    rng = np.random.default_rng(seed)
    tri = cand[rng.integers(0, len(cand), size=(iterations, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n, p0 = n[ok] / norm[ok, None], tri[ok, 0]
    n = n * np.where(n @ up < 0, -1.0, 1.0)[:, None]  # point toward the cameras' up
    ok = n @ up > cos_limit
    if not ok.any():
        return None
    n, p0 = n[ok], p0[ok]
    d = -(n * p0).sum(1)
    cam_h = np.median(cams @ n.T + d, axis=0)  # [T] median camera height above each hypothesis
    counts = np.zeros(len(n), dtype=np.int64)
    for s in range(0, len(n), 64):  # chunks of hypotheses: no loop over points
        sl = slice(s, s + 64)
        counts[sl] = (np.abs(cand @ n[sl].T + d[sl]) < band).sum(0)
    counts[~(cam_h > 0)] = 0
    if counts.max() < min_inliers:
        return None
    best = int(counts.argmax())
    ransac = GroundPlane(n[best], float(d[best]), int(counts[best]), int(len(cand)), float(cam_h[best]))
    normal, offset = ransac.normal, ransac.offset
    for _ in range(3):  # least-squares refit on the inliers (smallest singular vector), oriented up
        inl = cand[np.abs(cand @ normal + offset) < band]
        if len(inl) < 3:
            return ransac
        c = inl.mean(0)
        normal = np.linalg.svd(inl - c, full_matrices=False)[2][-1]
        normal = normal if normal @ up > 0 else -normal
        offset = float(-normal @ c)
    med = float(np.median(cams @ normal + offset))
    if not (normal @ up > cos_limit and med > 0):  # the refit left the cone (or the cameras): keep RANSAC's
        return ransac
    inliers = int((np.abs(cand @ normal + offset) < band).sum())
    return GroundPlane(normal, offset, inliers, int(len(cand)), med)


@dataclass
class MetricScale:
    metres_per_unit: float
    up: np.ndarray  # [3] in data units
    source: str  # "camera-height" | "override"
    plane: Optional[GroundPlane] = None


def estimate_metric_scale(points: np.ndarray, cam_centres: np.ndarray, cam_up: np.ndarray, camera_height: float = 1.5,
                          metres_per_unit: Optional[float] = None, where: str = "sparse points",
                          cam_right: Optional[np.ndarray] = None) -> MetricScale:
    """Up and metres-per-unit from the ground plane (``metres_per_unit`` overrides the scale; the
    plane still gives up when found). No plane and no override: a DataError naming the flags. Given
    the cameras' horizontal axes ``cam_right [N, 3]``, up is the cameras' upright direction when it
    agrees with the plane (:func:`~nerf2gs_plugin.data.road_plane.upright_normal`); the scale is the
    plane's either way."""
    from nerf2gs_plugin.data.road_plane import upright_normal

    plane = fit_ground_plane(points, cam_centres, cam_up)
    if plane is None:
        up = np.asarray(cam_up, dtype=np.float64) / np.linalg.norm(cam_up)
    else:
        upright = None if cam_right is None else upright_normal(plane.normal, cam_right, cam_centres, plane.median_camera_height)
        up = plane.normal if upright is None else upright
    if metres_per_unit is not None:
        if not metres_per_unit > 0:
            raise DataError(f"--metres-per-unit must be positive, got {metres_per_unit}", where)
        return MetricScale(float(metres_per_unit), up, "override", plane)
    if plane is None:
        raise DataError(f"no ground plane found below the cameras (within {MAX_TILT_DEG:.0f} deg of their up) to set the "
                        "metric scale: pass --metres-per-unit (metres per data unit) instead", where)
    if not camera_height > 0:
        raise DataError(f"--camera-height must be positive, got {camera_height}", where)
    return MetricScale(float(camera_height / plane.median_camera_height), up, "camera-height", plane)


def scale_from_frames(train_c2w, points_xyz, camera_height: float, where) -> tuple[float, "np.ndarray"]:
    """Metres-per-unit and up for a parsed dataset (``--pipeline.datamanager.dataparser.camera-height``):
    train cameras ``[N, 3, 4]`` OpenGL (their y axis is up) and the sparse points, original frame."""
    c2w = np.asarray(train_c2w, dtype=np.float64)
    if points_xyz is None or len(points_xyz) == 0:
        raise DataError("--camera-height needs sparse points (a COLMAP model or ply_file_path) to find the ground; "
                        "pass --metres-per-unit instead", where)
    s = estimate_metric_scale(np.asarray(points_xyz), c2w[:, :, 3], c2w[:, :, 1].mean(0), camera_height, where=where,
                              cam_right=c2w[:, :, 0])
    print(f"metric scale: {s.metres_per_unit:.4g} metres per data unit (camera {camera_height} m above the ground plane)")
    return s.metres_per_unit, s.up
