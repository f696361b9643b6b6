"""Camera poses of the synthetic street (OpenGL camera-to-world ``[N, 3, 4]``, metres, z up).

  * train: a car-mounted camera at ``cam_height``, 0 deg pitch, driving along the right-hand lane
    toward +x, then back toward -x in the other lane, with small lateral and yaw wobble;
  * street: held-out street-level poses between the training positions (also 0 deg pitch);
  * bev: raised by ``delta_h`` above the training height and pitched down by ``pitch`` degrees,
    placed on an ellipse around the street centre and looking inward along the street (the paper's
    MatrixCity protocol, in a street canyon where looking across would show only a facade).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import look_at
from nerf2gs_plugin.data.synthetic.layout import ROAD_HALF

_UP = torch.tensor([0.0, 0.0, 1.0])


def heading_pose(x: Tensor, y: Tensor, z: Tensor, yaw: Tensor, pitch_deg: float | Tensor) -> Tensor:
    """Cameras at ``(x, y, z)`` with heading ``yaw`` (radians from +x) pitched down by ``pitch``."""
    p = torch.deg2rad(torch.as_tensor(pitch_deg, dtype=torch.float32)).expand_as(yaw)
    fwd = torch.stack([torch.cos(p) * torch.cos(yaw), torch.cos(p) * torch.sin(yaw), -torch.sin(p)], dim=-1)
    eye = torch.stack([x, y, z], dim=-1)
    return look_at(eye, eye + fwd, _UP)


def train_poses(n: int, half_len: float, cam_height: float, gen: torch.Generator) -> tuple[Tensor, Tensor]:
    """``n`` training poses (first half forward, second half back) and their capture times (s)."""
    n_fwd = (n + 1) // 2
    n_back = n - n_fwd
    xf = torch.linspace(-half_len, half_len, n_fwd)
    xb = torch.linspace(half_len, -half_len, n_back) if n_back else torch.zeros(0)
    x = torch.cat([xf, xb])
    lane = torch.cat([torch.full((n_fwd,), -ROAD_HALF / 2), torch.full((n_back,), ROAD_HALF / 2)])
    y = lane + (torch.rand(n, generator=gen) - 0.5) * 0.6
    yaw = torch.cat([torch.zeros(n_fwd), torch.full((n_back,), math.pi)]) + torch.deg2rad((torch.rand(n, generator=gen) - 0.5) * 6.0)
    z = torch.full((n,), cam_height)
    step = (2 * half_len) / max(n_fwd - 1, 1)
    times = torch.arange(n, dtype=torch.float32) * step / 6.0 + torch.cat([torch.zeros(n_fwd), torch.full((n_back,), 4.0)])  # 6 m/s, a turn
    return heading_pose(x, y, z, yaw, 0.0), times


def street_poses(n: int, half_len: float, cam_height: float, gen: torch.Generator) -> Tensor:
    """Held-out street-level poses: between training stations, both directions, off the lanes."""
    x = torch.linspace(-half_len * 0.9, half_len * 0.9, n) + (torch.rand(n, generator=gen) - 0.5) * 1.5
    back = torch.arange(n) % 2 == 1
    y = torch.where(back, ROAD_HALF / 2, -ROAD_HALF / 2) + (torch.rand(n, generator=gen) - 0.5) * 1.2
    yaw = torch.where(back, math.pi, 0.0) + torch.deg2rad((torch.rand(n, generator=gen) - 0.5) * 16.0)
    return heading_pose(x, y, torch.full((n,), cam_height), yaw, 0.0)


def street_poses_between(n: int, half_len: float, cam_height: float, gen: torch.Generator) -> Tensor:
    """Validation street-level poses: like :func:`street_poses` but half a spacing further along
    (between the test street views) and over a shorter stretch, so none coincides with a test view."""
    spacing = 1.8 * half_len * 0.85 / max(n - 1, 1)
    x = torch.linspace(-half_len * 0.85, half_len * 0.85, n) + 0.5 * spacing + (torch.rand(n, generator=gen) - 0.5) * 1.0
    x = x.clamp(-half_len * 0.9, half_len * 0.9)
    back = torch.arange(n) % 2 == 0
    y = torch.where(back, ROAD_HALF / 2, -ROAD_HALF / 2) + (torch.rand(n, generator=gen) - 0.5) * 1.2
    yaw = torch.where(back, math.pi, 0.0) + torch.deg2rad((torch.rand(n, generator=gen) - 0.5) * 16.0)
    return heading_pose(x, y, torch.full((n,), cam_height), yaw, 0.0)


def bev_poses(n: int, half_len: float, height: float, pitch_deg: float, phase: float, gen: torch.Generator) -> Tensor:
    """Bird's-eye poses around the street, looking inward: headings alternate between the two
    street directions, each within +-15 deg of the axis (``phase`` in [0, 1) shifts the pattern),
    and each camera sits on an ellipse (semi-axes ``0.75 half_len`` along, 1.8 m across) on the
    far side of the centre from where it looks, so every view has a long stretch of road below it."""
    k = torch.arange(n, dtype=torch.float32)
    frac = ((k // 2) + 0.5 + phase) / max((n + 1) // 2, 1)
    off = torch.deg2rad(-15.0 + 30.0 * torch.remainder(frac * 1.618034, 1.0))
    off = off + torch.deg2rad((torch.rand(n, generator=gen) - 0.5) * 6.0)
    yaw = torch.where(k % 2 == 0, 0.0, math.pi) + off
    x = -0.75 * half_len * torch.cos(yaw)
    y = -1.8 * torch.sin(yaw)
    return heading_pose(x, y, torch.full((n,), height), yaw, pitch_deg)


def lane_shift_poses(n: int, half_len: float, cam_height: float, offset: float, gen: torch.Generator,
                     road_half: float = ROAD_HALF - 0.25) -> Tensor:
    """Level cameras ``offset`` metres to the side of the drive (the XLD benchmark's cross-lane views):
    along the training lanes in both directions, shifted across the road (y) to alternating sides,
    each flipped to the other side where the shift would leave the road (``|y| > road_half``)."""
    x = torch.linspace(-half_len * 0.85, half_len * 0.85, n) + (torch.rand(n, generator=gen) - 0.5) * 1.5
    k = torch.arange(n)
    back = k % 2 == 1
    lane = torch.where(back, ROAD_HALF / 2, -ROAD_HALF / 2)
    side = torch.where((k // 2) % 2 == 0, 1.0, -1.0)
    y = lane + side * offset
    y = torch.where(y.abs() > road_half, lane - side * offset, y)
    yaw = torch.where(back, math.pi, 0.0) + torch.deg2rad((torch.rand(n, generator=gen) - 0.5) * 6.0)
    return heading_pose(x, y, torch.full((n,), cam_height), yaw, 0.0)
