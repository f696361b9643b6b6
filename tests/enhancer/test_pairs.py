"""Perturbed-pose pairs: the warp through rendered depth reproduces what the moved camera sees
(an analytic textured ground plane), occluded pixels are masked, and the perturbation goes up and
looks down."""

import math

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.enhancer.pairs import perturb_pose, split_indices, warp_into


def _camera(c2w: torch.Tensor, w: int = 64, h: int = 48, f: float = 40.0) -> Cameras:
    return Cameras(camera_to_worlds=c2w[None], fx=torch.tensor([f]), fy=torch.tensor([f]), cx=torch.tensor([w / 2]),
                   cy=torch.tensor([h / 2]), width=torch.tensor([w]), height=torch.tensor([h]))


def _street_camera(height: float, pitch_deg: float) -> torch.Tensor:
    """Looking along +y, pitched down, at (0, 0, height); z is up (OpenGL camera axes)."""
    p = math.radians(pitch_deg)
    forward = torch.tensor([0.0, math.cos(p), -math.sin(p)])
    right = torch.tensor([1.0, 0.0, 0.0])
    up = torch.linalg.cross(right, forward)
    return torch.stack([right, up, -forward, torch.tensor([0.0, 0.0, height])], 1)


def _ground(camera: Cameras) -> tuple[torch.Tensor, torch.Tensor]:
    """Analytic render of the textured plane z = 0: (rgb ``[3, H, W]``, ray depth ``[H, W, 1]``)."""
    h, w = int(camera.height[0]), int(camera.width[0])
    rays = camera.generate_rays(0)
    t = -rays.origins[:, 2] / rays.directions[:, 2]
    p = rays.origins + rays.directions * t[:, None]
    rgb = torch.stack([0.5 + 0.4 * torch.sin(p[:, 0] * 1.3), 0.5 + 0.4 * torch.cos(p[:, 1] * 0.9), 0.5 + 0.2 * torch.sin(p[:, 0] + p[:, 1])])
    return rgb.reshape(3, h, w), t.reshape(h, w, 1)


def test_warp_reproduces_the_moved_view_of_a_plane():
    src = _camera(_street_camera(1.5, 30.0))
    src_rgb, src_depth = _ground(src)
    moved_c2w = perturb_pose(src.camera_to_worlds[0], torch.tensor([0.0, 0.0, 1.0]), torch.Generator().manual_seed(3), metres=1.0)
    assert moved_c2w[2, 3] >= 1.5 + 1.0 - 1e-6  # raised by >= 1 m
    assert moved_c2w[2, 2] > src.camera_to_worlds[0, 2, 2] + 1e-3  # -z (forward) tilts further down
    moved = _camera(moved_c2w)
    truth, depth = _ground(moved)
    warped, valid = warp_into(moved, depth, src.camera_to_worlds[0], 40.0, 40.0, 32.0, 24.0, src_depth.permute(2, 0, 1),
                              src_rgb, torch.ones(1, 48, 64))
    assert valid.shape == (1, 48, 64) and 0.2 < valid.mean() < 1.0  # part of the moved view is outside the source view
    err = ((warped - truth).abs() * valid).sum() / (valid.sum() * 3)
    assert err < 0.01, float(err)
    # where the source camera saw something nearer (an occluder), the pixel is masked out
    blocked = src_depth.permute(2, 0, 1) * 0.5
    _, none_visible = warp_into(moved, depth, src.camera_to_worlds[0], 40.0, 40.0, 32.0, 24.0, blocked, src_rgb, torch.ones(1, 48, 64))
    assert none_visible.sum() == 0
    # transient pixels of the source image are not targets either
    _, no_transient = warp_into(moved, depth, src.camera_to_worlds[0], 40.0, 40.0, 32.0, 24.0, src_depth.permute(2, 0, 1), src_rgb,
                                torch.zeros(1, 48, 64))
    assert no_transient.sum() == 0


def test_split_indices_holds_out_every_kth():
    fit, held = split_indices(10, 4, None, torch.Generator())
    assert held == [0, 4, 8] and fit == [1, 2, 3, 5, 6, 7, 9]
    fit, held = split_indices(10, 0, 3, torch.Generator().manual_seed(0))
    assert held == [] and len(fit) == 3 and fit == sorted(fit)
