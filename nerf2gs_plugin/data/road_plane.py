"""The ground plane of ``--segmenter auto`` levelled with the camera path: a camera carried at a
steady height over a road moves parallel to it.

Why: the RANSAC plane of ``data/ground.py`` rests on the sparse points below the cameras, which a
forward drive at low resolution gives few of, and its tilt along the drive is then off by degrees:
the camera heights above it change by more than half along a short drive, so far road lies metres
off the plane. ``ns2gs-data process`` keeps its own plane for the metric scale: levelling it there
made the bench's scale error worse (with few inliers the offset moves a few centimetres either way),
so that is left alone. The path itself pins that tilt down:
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


UPRIGHT_MAX_DEG = 10.0
"""The most the cameras' upright direction may differ from the plane's normal and still replace it:
beyond, the cameras are rolled on purpose (portrait photos, a tilted mount) and the points decide."""


UPRIGHT_COMPETE_DEG = 20.0
"""Beyond UPRIGHT_MAX_DEG and up to this, the cameras' upright still competes with the points' normal
on the support of the road layer along each (:func:`level_plane`)."""


def upright_normal(normal: np.ndarray, cam_right: np.ndarray, centres: np.ndarray, min_extent: float,
                   max_deg: float = UPRIGHT_MAX_DEG) -> Optional[np.ndarray]:
    """The direction perpendicular to every camera's horizontal axis (``cam_right [N, 3]``, OpenGL x)
    and to the camera path (:func:`path_directions`), on ``normal``'s side; None when those leave
    more than one direction free or the result is more than ``max_deg`` from ``normal``.

    Why: people and cars hold cameras without roll and drive parallel to the road, and hundreds of
    camera axes pin the up down better than the few sparse points below a forward drive; levelling the
    plane with the path alone (:func:`level_normal`) still takes the roll about a straight drive from
    the points (``benchmarks/results/ground_fit.md``)."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    right = np.asarray(cam_right, dtype=np.float64).reshape(-1, 3)
    right = right / np.linalg.norm(right, axis=1, keepdims=True).clip(1e-12)
    rows = np.concatenate([right / np.sqrt(max(len(right), 1)), path_directions(centres, min_extent)])
    if len(rows) < 2:
        return None
    _, s, vt = np.linalg.svd(rows, full_matrices=True)
    if len(s) < 2 or s[1] < 0.1 * s[0]:  # the axes and the path span one direction: two are free
        return None
    up = vt[2] if vt[2] @ n > 0 else -vt[2]
    return up if up @ n >= np.cos(np.radians(max_deg)) else None


def road_layer(points: np.ndarray, centres: np.ndarray, normal: np.ndarray, rel_thresh: float = 0.05,
               min_inliers: int = 10) -> tuple[Optional[float], int]:
    """``(offset, support)`` of the densest layer of points below the cameras along ``normal`` (1-D
    RANSAC over the points' heights: every point's height is a candidate, its support the points
    within ``rel_thresh`` x the camera height above it; then the median of that band); offset None
    without ``min_inliers`` support."""
    n = np.asarray(normal, dtype=np.float64)
    cam = float(np.median(np.asarray(centres, dtype=np.float64).reshape(-1, 3) @ n))
    h = np.asarray(points, dtype=np.float64).reshape(-1, 3) @ n
    h = np.sort(h[h < cam])
    if len(h) < min_inliers:
        return None, len(h)
    band = rel_thresh * (cam - h)
    counts = np.searchsorted(h, h + band, side="right") - np.searchsorted(h, h - band, side="left")
    best = int(counts.argmax())
    if counts[best] < min_inliers:
        return None, int(counts[best])
    level = float(h[best])
    for _ in range(3):
        inl = h[np.abs(h - level) < rel_thresh * (cam - level)]
        if len(inl) < min_inliers:
            break
        level = float(np.median(inl))
    return -level, int(counts[best])


def plane_offset(points: np.ndarray, centres: np.ndarray, normal: np.ndarray, rel_thresh: float = 0.05,
                 min_inliers: int = 10) -> Optional[float]:
    """Offset ``d`` of the plane ``normal . x + d = 0`` through the densest layer of points below the
    cameras (:func:`road_layer`); None without ``min_inliers`` support."""
    return road_layer(points, centres, normal, rel_thresh, min_inliers)[0]


def level_plane(normal: np.ndarray, offset: float, points: np.ndarray, centres: np.ndarray,
                rel_thresh: float = 0.05, cam_right: Optional[np.ndarray] = None) -> tuple[np.ndarray, float]:
    """``(normal, offset)`` of a RANSAC ground plane levelled with the camera path (see the module
    docstring) or, given the cameras' horizontal axes ``cam_right``, made upright with them
    (:func:`upright_normal`), through the densest layer of points below the cameras along the new
    normal (:func:`plane_offset`; the old plane's height under the median camera when there is none).
    The path must spread by at least the camera height to say anything."""
    n = np.asarray(normal, dtype=np.float64)
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    cam_h = float(np.median(c @ n + offset))
    ext = max(cam_h, 1e-12)
    up = upright_normal(n, cam_right, c, min_extent=ext) if cam_right is not None else None
    n2 = up if up is not None else level_normal(n, c, min_extent=ext)
    d2, support = road_layer(points, c, n2, rel_thresh)
    if up is None and cam_right is not None:
        # the points' normal leans past UPRIGHT_MAX_DEG from the cameras' upright: movers, car roofs
        # and facade feet can tilt a plane fitted on few road points (the roll of a straight drive
        # is theirs alone), yet a tilted mount also gets here: the normal whose road layer holds
        # more points wins
        far = upright_normal(n, cam_right, c, min_extent=ext, max_deg=UPRIGHT_COMPETE_DEG)
        if far is not None:
            d3, support3 = road_layer(points, c, far, rel_thresh)
            if d3 is not None and support3 > support:
                n2, d2 = far, d3
    if d2 is None:
        d2 = -float(np.median(c, axis=0) @ n2 - cam_h)
    return n2, float(d2)
