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


MIN_BELOW_FRACTION = 0.5
"""A ground plane lies below the cameras: its inliers' median must be at least this fraction of the median
camera height above the plane below the median camera, along the cameras' own mean up. Photos of a facade
see little floor, and a plane through the walls' points at the cameras' height passes the tilt limit
while lying far closer to the cameras than a road does (docs/capture.md)."""


def below_cameras(plane: GroundPlane, points: np.ndarray, cam_centres: np.ndarray, cam_up: np.ndarray,
                  rel_thresh: float = 0.05) -> float:
    """How far the plane's inliers (within ``rel_thresh`` x the median camera height of it) lie below the
    median camera along ``cam_up``, in median camera heights above the plane (0 without inliers)."""
    up = np.asarray(cam_up, dtype=np.float64) / np.linalg.norm(cam_up)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    inl = pts[np.abs(plane.height(pts)) < rel_thresh * plane.median_camera_height]
    if len(inl) == 0 or plane.median_camera_height <= 0:
        return 0.0
    cams = np.asarray(cam_centres, dtype=np.float64).reshape(-1, 3)
    return float((np.median(cams @ up) - np.median(inl @ up)) / plane.median_camera_height)


UPRIGHT_FROM_MEAN_DEG = 45.0
"""The most the cameras' upright (from their horizontal axes) may differ from their mean up and still be
taken: photos look up or down by tens of degrees, but a portrait (rolled) photo's axis is no horizon."""


def cameras_upright(cam_up: np.ndarray, cam_right: Optional[np.ndarray]) -> np.ndarray:
    """The up of the cameras alone: perpendicular to every camera's horizontal axis (people and cars hold
    cameras without roll, while photos of facades look up, tilting the mean up) when those axes turn enough
    to say it, else the cameras' mean up."""
    from nerf2gs_plugin.data.road_plane import upright_normal

    up = np.asarray(cam_up, dtype=np.float64) / np.linalg.norm(cam_up)
    if cam_right is None:
        return up
    upright = upright_normal(up, cam_right, np.zeros((1, 3)), min_extent=np.inf, max_deg=UPRIGHT_FROM_MEAN_DEG)
    return up if upright is None else upright


@dataclass
class MetricScale:
    metres_per_unit: float
    up: np.ndarray  # [3] in data units
    source: str  # "camera-height" | "camera-height, lowest layer" | "override"
    plane: Optional[GroundPlane] = None
    note: str = ""  # why the ground plane was not used (one line), or ""


def estimate_metric_scale(points: np.ndarray, cam_centres: np.ndarray, cam_up: np.ndarray, camera_height: float = 1.5,
                          metres_per_unit: Optional[float] = None, where: str = "sparse points",
                          cam_right: Optional[np.ndarray] = None) -> MetricScale:
    """Up and metres-per-unit from the ground plane (``metres_per_unit`` overrides the scale; the
    plane still gives up when found). No plane and no override: a DataError naming the flags. Given
    the cameras' horizontal axes ``cam_right [N, 3]``, up is the cameras' upright direction when it
    agrees with the plane (:func:`~nerf2gs_plugin.data.road_plane.upright_normal`); the scale is the
    plane's either way. A plane whose points are not below the cameras (:data:`MIN_BELOW_FRACTION`) is
    rejected (``note`` says why): up is then the cameras' own (:func:`cameras_upright`, as without a plane)
    and the scale the camera height over the densest layer of points below them along it."""
    from nerf2gs_plugin.data.road_plane import upright_normal

    plane = fit_ground_plane(points, cam_centres, cam_up)
    note = ""
    below = below_cameras(plane, points, cam_centres, cam_up) if plane is not None else 1.0
    if below < MIN_BELOW_FRACTION:
        note = (f"the ground plane's points lie {below:.2f} camera heights below the cameras (at least {MIN_BELOW_FRACTION:g}: "
                "a wall at their height, not the ground?)")
        plane = None
    if plane is None:
        up = cameras_upright(cam_up, cam_right)
    else:
        upright = None if cam_right is None else upright_normal(plane.normal, cam_right, cam_centres, plane.median_camera_height)
        up = plane.normal if upright is None else upright
    if metres_per_unit is not None:
        if not metres_per_unit > 0:
            raise DataError(f"--metres-per-unit must be positive, got {metres_per_unit}", where)
        return MetricScale(float(metres_per_unit), up, "override", plane, note)
    if not camera_height > 0:
        raise DataError(f"--camera-height must be positive, got {camera_height}", where)
    if plane is None and note:  # a rejected plane: the camera height over the densest layer of points below along up
        from nerf2gs_plugin.data.road_plane import road_layer

        offset, _ = road_layer(points, cam_centres, up)
        height = float(np.median(np.asarray(cam_centres, dtype=np.float64).reshape(-1, 3) @ up + offset)) if offset is not None else 0.0
        if height > 0:
            return MetricScale(float(camera_height / height), up, "camera-height, lowest layer", None, note)
    if plane is None:
        raise DataError(f"no ground plane found below the cameras (within {MAX_TILT_DEG:.0f} deg of their up) to set the "
                        "metric scale: pass --metres-per-unit (metres per data unit) instead", where)
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
