"""Directions on the ground plane, shared by the path kinds."""

from __future__ import annotations

import torch
from torch import Tensor


def flat_forward(camera_to_worlds: Tensor, up: Tensor) -> Tensor:
    """``[N, 3]`` each camera's viewing direction projected on the ground plane (unit); a camera
    looking straight down uses its own up axis."""
    fwd = -camera_to_worlds[:, :, 2]
    flat = fwd - (fwd @ up)[:, None] * up
    cam_up = camera_to_worlds[:, :, 1] - (camera_to_worlds[:, :, 1] @ up)[:, None] * up
    weak = flat.norm(dim=-1, keepdim=True) < 1e-4
    return torch.nn.functional.normalize(torch.where(weak, cam_up, flat), dim=-1)


def lateral(camera_to_worlds: Tensor, up: Tensor) -> Tensor:
    """``[N, 3]`` the ground plane's lateral axis at each camera (to its right, level): the drive's
    sideways direction, whatever the camera's own roll."""
    return torch.nn.functional.normalize(torch.cross(flat_forward(camera_to_worlds, up), up.expand(len(camera_to_worlds), 3), dim=-1), dim=-1)
