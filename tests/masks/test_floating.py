"""Oncoming traffic from the reference's geometry (``masks/floating.py``): on a ray-cast road seen from 3 m up,
a box that floats over the road near the camera's path (an oncoming car's scaled copy) is found; the same box
standing on the road, one floating far to the side, and one whose underside hangs low are not."""

from __future__ import annotations

import math

import torch

from nerf2gs_plugin.masks.floating import floating_objects
from nerf2gs_plugin.masks.motion import ray_directions

W, H, CAM_H = 160, 96, 3.0
UP = torch.tensor([0.0, 0.0, 1.0])


def _camera() -> torch.Tensor:
    """Looking along +x, 3 m above the road z = 0, pitched 10 degrees down (OpenGL axes)."""
    p = math.radians(10.0)
    fwd = torch.tensor([math.cos(p), 0.0, -math.sin(p)])
    right = torch.tensor([0.0, -1.0, 0.0])
    up = torch.linalg.cross(right, fwd)
    c2w = torch.zeros(3, 4)
    c2w[:, 0], c2w[:, 1], c2w[:, 2], c2w[:, 3] = right, up, -fwd, torch.tensor([0.0, 0.0, CAM_H])
    return c2w


def _scene(boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(distance along each ray, the rays, which box each ray hits (-1: road or nothing))`` for axis-aligned ``boxes``."""
    c2w = _camera()
    rays = ray_directions(c2w, (80.0, 80.0, W / 2, H / 2), H, W)
    o = c2w[:, 3].double()
    t_road = torch.where(rays[..., 2] < -1e-9, -o[2] / rays[..., 2].clamp(max=-1e-9), torch.full((H, W), math.inf, dtype=torch.float64))
    dist, hit = t_road.clone(), torch.full((H, W), -1)
    for k, (lo, hi) in enumerate(boxes):
        lo_t, hi_t = torch.tensor(lo, dtype=torch.float64), torch.tensor(hi, dtype=torch.float64)
        inv = 1.0 / torch.where(rays.abs() < 1e-12, torch.full_like(rays, 1e-12), rays)
        t0, t1 = (lo_t - o) * inv, (hi_t - o) * inv
        near, far = torch.minimum(t0, t1).amax(-1), torch.maximum(t0, t1).amin(-1)
        ok = (near <= far) & (near > 0) & (near < dist)
        dist, hit = torch.where(ok, near, dist), torch.where(ok, torch.full_like(hit, k), hit)
    return dist.float(), rays, hit


def _found(boxes: list) -> list[float]:
    dist, rays, hit = _scene(boxes)
    m = floating_objects(dist, rays, _camera()[:, 3], UP, 0.0, 1.0, clear=0.4, reach=3.5)
    return [float(m[hit == k].float().mean()) for k in range(len(boxes))] + [float(m[hit == -1].float().mean())]


def test_a_box_floating_over_the_road_near_the_path_is_found():
    ghost = ((10.0, 1.0, 1.4), (12.5, 2.0, 2.2))  # 1.4-2.2 m up (0.47-0.73 of the camera height), 1-2 m aside
    on_ghost, on_road = _found([ghost])
    assert on_ghost > 0.6 and on_road == 0.0  # its top, seen at a grazing angle, is not depth-continuous


def test_standing_far_aside_and_low_slung_boxes_are_not_found():
    standing = ((10.0, 1.0, 0.0), (12.5, 2.0, 2.2))  # the same box on the road: a parked car, a wall
    aside = ((10.0, -8.0, 1.4), (12.5, -7.0, 2.2))  # floats, but 7-8 m from the path: not over the road
    low = ((10.0, -2.5, 0.3), (12.5, -1.5, 1.6))  # a car body over its wheels' gap: 0.3 m up
    assert _found([standing])[0] == 0.0
    assert _found([aside])[0] == 0.0
    assert _found([low])[0] == 0.0
