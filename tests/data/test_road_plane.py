"""The masks' ground plane levelled with the camera path (``data/masks/road_plane.py``)."""

from __future__ import annotations

import numpy as np

from nerf2gs_plugin.data.masks.road_plane import level_normal, level_plane, path_directions, plane_offset


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
