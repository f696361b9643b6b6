"""The masks' ground plane levelled with the camera path (``data/road_plane.py``)."""

from __future__ import annotations

import numpy as np

from nerf2gs_plugin.data.road_plane import level_normal, level_plane, path_directions, plane_offset, upright_normal


def _drive(rng, n_cams: int = 30, n_road: int = 40, n_wall: int = 400):
    """A straight drive along x at 3 m over the road z = 0; few road points (low texture), many on
    two facades at y = +-8 m (from 1.5 m up: their feet hidden behind parked cars)."""
    x = np.linspace(-20, 20, n_cams)
    cams = np.stack([x, np.zeros_like(x), np.full_like(x, 3.0)], 1) + rng.normal(0, 0.02, (n_cams, 3))
    road = np.stack([rng.uniform(-25, 25, n_road), rng.uniform(-5, 5, n_road), rng.normal(0, 0.03, n_road)], 1)
    wall = np.stack([rng.uniform(-25, 25, n_wall), rng.choice([-8.0, 8.0], n_wall), rng.uniform(1.5, 12, n_wall)], 1)
    return cams, np.concatenate([road, wall])


def _rot(axis: str, deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])}[axis]


def test_path_directions_straight_and_turning():
    rng = np.random.default_rng(0)
    cams, _ = _drive(rng)
    d = path_directions(cams, min_extent=3.0)
    assert d.shape == (1, 3) and abs(abs(d[0, 0]) - 1) < 1e-3
    turn = np.concatenate([cams, np.stack([np.full(30, 20.0), np.linspace(0, 30, 30), np.full(30, 3.0)], 1)])
    assert path_directions(turn, min_extent=3.0).shape == (2, 3)
    assert path_directions(cams[:1].repeat(5, 0), min_extent=3.0).shape == (0, 3)


def test_level_plane_removes_a_tilt_along_the_drive_and_keeps_the_roll():
    """A RANSAC normal tilted 3 deg along the drive (the camera heights then run from 4 m to 2 m)
    is levelled to within a fraction of a degree, through the road points it still holds; a roll
    about the drive is none of the path's business and stays."""
    rng = np.random.default_rng(1)
    cams, pts = _drive(rng)
    tilted = _rot("y", 3.0) @ np.array([0.0, 0, 1])
    n, d = level_plane(tilted, 0.0, pts, cams)
    assert np.degrees(np.arccos(min(1.0, n @ np.array([0.0, 0, 1])))) < 0.3
    assert abs(d) < 0.05 and abs(np.median(cams @ n + d) - 3.0) < 0.05
    rolled = _rot("x", 4.0) @ np.array([0.0, 0, 1])
    n2 = level_normal(rolled, cams, min_extent=3.0)
    assert np.degrees(np.arccos(min(1.0, n2 @ rolled))) < 0.3


def test_plane_offset_finds_the_road_layer_below_the_cameras():
    rng = np.random.default_rng(2)
    cams, pts = _drive(rng)
    assert abs(plane_offset(pts, cams, np.array([0.0, 0, 1]))) < 0.05
    assert plane_offset(pts[:3], cams, np.array([0.0, 0, 1])) is None


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))))


def test_upright_normal_takes_the_roll_from_the_cameras():
    """A RANSAC normal rolled 4 deg about a straight drive (the path cannot see a roll) is made
    upright by the cameras' level horizontal axes (each a little noisy); level_plane does the same
    given them. Cameras rolled on purpose (portrait: x axis vertical) are no evidence: None, and
    level_plane falls back to levelling with the path."""
    rng = np.random.default_rng(3)
    cams, pts = _drive(rng)
    right = np.array([0.0, -1.0, 0.0]) + rng.normal(0, 0.01, (len(cams), 3))  # driving along +x, up +z
    rolled = _rot("x", 4.0) @ np.array([0.0, 0, 1])
    assert _angle(level_normal(rolled, cams, min_extent=3.0), np.array([0.0, 0, 1])) > 3.5
    up = upright_normal(rolled, right, cams, min_extent=3.0)
    assert up is not None and _angle(up, np.array([0.0, 0, 1])) < 0.3
    n, d = level_plane(rolled, 0.0, pts, cams, cam_right=right)
    assert _angle(n, np.array([0.0, 0, 1])) < 0.3 and abs(np.median(cams @ n + d) - 3.0) < 0.05
    portrait = np.tile(np.array([0.0, 0.0, 1.0]), (len(cams), 1))
    assert upright_normal(rolled, portrait, cams, min_extent=3.0) is None
    n2, _ = level_plane(rolled, 0.0, pts, cams, cam_right=portrait)
    assert np.allclose(n2, level_normal(rolled, cams, min_extent=3.0))
    # one camera standing still: its axis alone leaves two directions free
    assert upright_normal(rolled, right[:1], cams[:1], min_extent=3.0) is None


def test_metric_scale_up_from_the_cameras_scale_from_the_plane():
    """process's up: the upright direction when given the cameras' axes; the metric scale stays the
    plane's (camera height over the median camera height above it)."""
    from nerf2gs_plugin.data.ground import estimate_metric_scale

    rng = np.random.default_rng(4)
    cams, pts = _drive(rng, n_road=400)
    right = np.array([0.0, -1.0, 0.0]) + rng.normal(0, 0.01, (len(cams), 3))
    plain = estimate_metric_scale(pts, cams, np.array([0.0, 0, 1]), camera_height=3.0)
    upright = estimate_metric_scale(pts, cams, np.array([0.0, 0, 1]), camera_height=3.0, cam_right=right)
    assert upright.metres_per_unit == plain.metres_per_unit
    assert _angle(upright.up, np.array([0.0, 0, 1])) < 0.3


def test_a_plane_rolled_past_the_upright_guard_loses_to_the_cameras_when_the_road_says_so():
    """On a street with movers and parked cars the sparse points' plane can roll 12 deg about a
    straight drive: past UPRIGHT_MAX_DEG, so the cameras' upright alone may not replace it, but the
    road layer along the upright holds more points, and it wins. A mount rolled 15 deg on purpose
    (the cameras' axes rolled, the road level) keeps the points' normal: the road layer along the
    cameras' upright is smeared."""
    rng = np.random.default_rng(5)
    cams, pts = _drive(rng, n_road=80)
    right = np.array([0.0, -1.0, 0.0]) + rng.normal(0, 0.01, (len(cams), 3))
    rolled = _rot("x", 12.0) @ np.array([0.0, 0, 1])
    assert upright_normal(rolled, right, cams, min_extent=3.0) is None
    n, d = level_plane(rolled, 0.0, pts, cams, cam_right=right)
    assert _angle(n, np.array([0.0, 0, 1])) < 0.5 and abs(np.median(cams @ n + d) - 3.0) < 0.1
    tilted_mount = right @ _rot("x", 15.0).T
    n2, _ = level_plane(np.array([0.0, 0, 1]), 0.0, pts, cams, cam_right=tilted_mount)
    assert _angle(n2, np.array([0.0, 0, 1])) < 0.5
