"""A real view warped into another camera through rendered depth: the training pairs' ground truth
from raised cameras (:mod:`nerf2gs_plugin.enhancer.pairs`) and the reference input of a
``warped``-conditioned enhancer (``ns2gs-enhance train --condition warped``).

A conditioned enhancer sees, beside a render, the nearest real training view warped into the
render's camera through the reference's depth, and where that warp is valid (4 channels: RGB and
the validity mask, RGB zero where invalid). Where the warp is valid it can copy real detail; elsewhere
(surfaces no nearby camera saw, rooftops from above) it has only the render. It lives here, below
the data managers and the enhancer trainer, because both build that input: the trainer for its
pairs, the augmentation for each bird's-eye view.
"""

from __future__ import annotations

from typing import Optional

import torch
import torch.nn.functional as F
from torch import Tensor

DEPTH_TOLERANCE = 0.03  # relative depth disagreement that counts as occluded
WARPED_CHANNELS = 4  # RGB + validity
REFERENCE_KINDS = ("image", "warped")
"""What an enhancer's reference input holds: ``image``, a real view as it is (resized to the image;
Difix's convention); ``warped``, :func:`warped_reference` (RGB + validity, 4 channels)."""


def warp_into(camera, depth: Tensor, source_c2w: Tensor, fx: float, fy: float, cx: float, cy: float,
              source_depth: Tensor, source_image: Tensor, source_mask: Tensor) -> tuple[Tensor, Tensor]:
    """Warp ``source_image`` ``[3, h, w]`` (seen by the source camera) into ``camera`` through its
    rendered ray ``depth`` ``[H, W, 1]``: (warped image ``[3, H, W]``, valid mask ``[1, H, W]``)."""
    h, w = int(camera.height[0]), int(camera.width[0])
    sh, sw = source_image.shape[-2:]
    rays = camera.generate_rays(0)
    points = rays.origins + rays.directions * depth.reshape(-1, 1).to(rays.origins)
    rot, origin = source_c2w[:, :3].to(points), source_c2w[:, 3].to(points)
    local = (points - origin) @ rot  # camera frame (OpenGL: looks down -z)
    z = -local[:, 2]
    zc = z.clamp_min(1e-6)
    u = cx + fx * local[:, 0] / zc
    v = cy - fy * local[:, 1] / zc
    grid = torch.stack([2 * u / sw - 1, 2 * v / sh - 1], -1).reshape(1, h, w, 2).float().cpu()
    sample = lambda img, mode: F.grid_sample(img[None].float().cpu(), grid, mode=mode, align_corners=False, padding_mode="border")[0]  # noqa: E731
    warped = sample(source_image, "bilinear")
    seen_depth = sample(source_depth, "nearest")[0]
    dist = (points - origin).norm(dim=-1).reshape(h, w).float().cpu()
    inside = (grid.abs() <= 1).all(-1)[0] & (z.reshape(h, w).cpu() > 1e-3)
    visible = (dist - seen_depth).abs() < DEPTH_TOLERANCE * seen_depth + 1e-3 * seen_depth.median()
    clear = sample(source_mask, "nearest")[0] > 0.5
    return warped, (inside & visible & clear).float()[None]


def clear_mask(transient: Optional[Tensor], h: int, w: int) -> Tensor:
    """``[1, H, W]``: 1 where a real image shows the static scene (``transient`` ``[H, W, 1]`` grown by 2 px is 0)."""
    if transient is None:
        return torch.ones(1, h, w)
    t = F.max_pool2d(transient.float().cpu().permute(2, 0, 1)[None], 5, 1, 2)[0]
    return 1 - t


def ray_depth(depth: Tensor, camera, along: str) -> Tensor:
    """A rendered depth ``[H, W, 1]`` as distance along the unit ray (``along``: "z" or "ray")."""
    if along == "ray":
        return depth.float().cpu()
    if along != "z":
        raise ValueError(f"depth_along must be 'z' or 'ray', got {along!r}")
    rays = camera.generate_rays(0)
    forward = -camera.camera_to_worlds[0, :, 2].to(rays.directions)  # OpenGL cameras look down -z
    cos = (rays.directions @ forward).clamp_min(1e-6).reshape(depth.shape).float().cpu()
    return depth.float().cpu() / cos


def warped_reference(camera, depth: Tensor, source_camera, source_depth: Tensor, source_image: Tensor,
                     source_clear: Tensor, depth_along: str = "ray") -> Tensor:
    """The reference input of a ``warped`` enhancer, ``[H, W, 4]``: ``source_image`` ``[h, w, 3]``
    (a real view, seen by ``source_camera``) warped into ``camera`` through the render's ``depth``
    ``[H, W, 1]``, zero where invalid, and the validity mask (the point falls inside the source image,
    in front of it, unoccluded there by the source's rendered ``source_depth`` ``[h, w, 1]``, and on
    a ``source_clear`` ``[1, h, w]`` pixel)."""
    warped, valid = warp_into(camera, ray_depth(depth, camera, depth_along), source_camera.camera_to_worlds[0],
                              float(source_camera.fx[0]), float(source_camera.fy[0]), float(source_camera.cx[0]),
                              float(source_camera.cy[0]), ray_depth(source_depth, source_camera, depth_along).permute(2, 0, 1),
                              source_image.float().cpu().permute(2, 0, 1), source_clear.float().cpu())
    return torch.cat([warped * valid, valid]).permute(1, 2, 0).contiguous()


def nearest_camera(centre: Tensor, centres: Tensor, exclude: Optional[int] = None) -> int:
    """Index of the camera centre in ``centres`` ``[N, 3]`` nearest ``centre`` ``[3]`` (never ``exclude``)."""
    d = (centres.float().cpu() - centre.float().cpu()).norm(dim=-1)
    if exclude is not None and len(d) > 1:
        d[exclude] = float("inf")
    return int(d.argmin())


def condition_source(c2w: Tensor, c2ws: Tensor, exclude: Optional[int] = None) -> int:
    """Index of the camera in ``c2ws`` ``[N, 3, 4]`` a view ``c2w`` ``[3, 4]`` takes its warped condition
    from: the nearest centre among those facing the same way (viewing axes under 90 deg apart), else
    the nearest (never ``exclude``). Nearest by centre alone can pick a camera of the other pass of a
    street, looking the other way: its warp would be all invalid."""
    c2w, c2ws = c2w.float().cpu(), c2ws.float().cpu()
    d = (c2ws[:, :, 3] - c2w[:, 3]).norm(dim=-1)
    if exclude is not None and len(d) > 1:
        d[exclude] = float("inf")
    facing = (c2ws[:, :, 2] @ c2w[:, 2]) > 0  # OpenGL cameras look down -z: same sign, same way
    if bool((facing & torch.isfinite(d)).any()):
        d = torch.where(facing, d, torch.full_like(d, float("inf")))
    return int(d.argmin())


__all__ = ["DEPTH_TOLERANCE", "REFERENCE_KINDS", "WARPED_CHANNELS", "clear_mask", "condition_source", "nearest_camera", "ray_depth",
           "warp_into", "warped_reference"]
