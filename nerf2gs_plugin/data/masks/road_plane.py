"""The ground plane of ``--segmenter auto`` levelled with the camera path: a camera carried at a
steady height over a road moves parallel to it.

Why: the RANSAC plane of ``data/ground.py`` rests on the sparse points below the cameras, which a
forward drive at low resolution gives few of (48 inliers of 660 points on the bench's street), and
its tilt along the drive is then off by degrees: refitted in the reference's normalised world, the
camera heights above it ran from 6.2 m to 2.4 m along a 3 m drive, so far road lay metres off the
plane (levelled: 3.0-3.3 m). ``ns2gs-data process`` keeps its own plane for the metric scale:
levelled there, the bench's scale error went from +3.4% to +5.4% (48 inliers: the offset moves a
few centimetres either way), so that is left alone. The path itself pins that tilt down:
the plane's normal is made perpendicular to every direction the camera centres spread along (the
drive; both axes of a path that turns), keeping the points' say about the rest (the roll of a
straight drive), and the plane's height is refitted on the points (the densest layer below the
cameras along the new normal; the old plane's inliers, tilted, take in facade feet).
"""

from __future__ import annotations

from typing import Optional

import numpy as np


def path_directions(centres: np.ndarray, min_extent: float, ratio: float = 0.2) -> np.ndarray:
    """``[K, 3]`` unit directions the camera centres spread along (principal axes whose RMS spread
    is at least ``min_extent`` and ``ratio`` of the largest); ``[0, 3]`` for a camera that stays put."""
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    if len(c) < 3:
        return np.zeros((0, 3))
    _, s, vt = np.linalg.svd(c - c.mean(0), full_matrices=False)
    rms = s / np.sqrt(len(c))
    keep = (rms >= min_extent) & (rms >= ratio * rms[0])
    return vt[:2][keep[:2]]  # never all three: a plane needs a normal left


def level_normal(normal: np.ndarray, centres: np.ndarray, min_extent: float) -> np.ndarray:
    """``normal`` with its components along the camera path (:func:`path_directions`) removed,
    renormalised and pointing the same side; unchanged when the path does not spread."""
    n = np.asarray(normal, dtype=np.float64)
    dirs = path_directions(centres, min_extent)
    out = n - dirs.T @ (dirs @ n) if len(dirs) else n.copy()
    norm = np.linalg.norm(out)
    if norm < 1e-6:  # the path runs along the normal (a camera moving up a wall): nothing to level
        return n / np.linalg.norm(n)
    out = out / norm
    return out if out @ n > 0 else -out


def plane_offset(points: np.ndarray, centres: np.ndarray, normal: np.ndarray, rel_thresh: float = 0.05,
                 min_inliers: int = 10) -> Optional[float]:
    """Offset ``d`` of the plane ``normal . x + d = 0`` through the densest layer of points below the
    cameras (1-D RANSAC over the points' heights: every point's height is a candidate, its support
    the points within ``rel_thresh`` x the camera height above it; then the median of that band);
    None without ``min_inliers`` support."""
    n = np.asarray(normal, dtype=np.float64)
    cam = float(np.median(np.asarray(centres, dtype=np.float64).reshape(-1, 3) @ n))
    h = np.asarray(points, dtype=np.float64).reshape(-1, 3) @ n
    h = np.sort(h[h < cam])
    if len(h) < min_inliers:
        return None
    band = rel_thresh * (cam - h)
    counts = np.searchsorted(h, h + band, side="right") - np.searchsorted(h, h - band, side="left")
    best = int(counts.argmax())
    if counts[best] < min_inliers:
        return None
    level = float(h[best])
    for _ in range(3):
        inl = h[np.abs(h - level) < rel_thresh * (cam - level)]
        if len(inl) < min_inliers:
            break
        level = float(np.median(inl))
    return -level


def level_plane(normal: np.ndarray, offset: float, points: np.ndarray, centres: np.ndarray,
                rel_thresh: float = 0.05) -> tuple[np.ndarray, float]:
    """``(normal, offset)`` of a RANSAC ground plane levelled with the camera path (see the module
    docstring), through the densest layer of points below the cameras along the new normal
    (:func:`plane_offset`; the old plane's height under the median camera when there is none). The
    path must spread by at least the camera height to say anything."""
    n = np.asarray(normal, dtype=np.float64)
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    cam_h = float(np.median(c @ n + offset))
    n2 = level_normal(n, c, min_extent=max(cam_h, 1e-12))
    d2 = plane_offset(points, c, n2, rel_thresh)
    if d2 is None:
        d2 = -float(np.median(c, axis=0) @ n2 - cam_h)
    return n2, float(d2)
