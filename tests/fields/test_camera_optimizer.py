"""The per-image SO3xR3 camera optimizer: identity at the start and for non-training cameras,
corrections of rays and cameras that agree, a regulariser with a finite gradient at zero."""


import pytest
import torch

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.fields.camera_optimizer import CameraOptimizer, CameraOptimizerConfig


def _cams(n: int = 3) -> Cameras:
    ang = torch.linspace(0, 2, n)
    eye = torch.stack([torch.cos(ang) * 3, torch.sin(ang) * 3, torch.full_like(ang, 1.5)], -1)
    return Cameras(look_at(eye, torch.zeros(n, 3), torch.tensor([0.0, 0.0, 1.0])), fx=10.0, fy=10.0, cx=4.0, cy=3.0, width=8, height=6)


def test_off_builds_nothing_and_zero_is_the_identity():
    assert not CameraOptimizerConfig().enabled
    with pytest.raises(ValueError):
        CameraOptimizer(CameraOptimizerConfig(), 3)
    opt = CameraOptimizer(CameraOptimizerConfig(mode="SO3xR3"), 3)
    rays = _cams().generate_rays(torch.tensor([0, 1, 2, 2]), torch.tensor([[0, 0], [3, 2], [7, 5], [1, 4]]))
    moved = opt.apply_to_rays(rays)
    assert torch.equal(moved.origins, rays.origins) and torch.equal(moved.directions, rays.directions)


def test_only_training_cameras_move_and_rays_agree_with_cameras():
    cams = _cams()
    opt = CameraOptimizer(CameraOptimizerConfig(mode="SO3xR3"), 2)  # camera 2 is not a training image (a bird's-eye view)
    with torch.no_grad():
        opt.pose_adjustment.copy_(torch.tensor([[0.1, 0.0, -0.05, 0.02, 0.01, -0.03], [0.0, 0.2, 0.0, 0.0, -0.04, 0.0]]))
    idx = torch.tensor([0, 1, 2, 0, 1, 2])
    rays = cams.generate_rays(idx, torch.tensor([[0, 0], [3, 2], [7, 5], [4, 3], [1, 1], [2, 2]]))
    moved = opt.apply_to_rays(rays)
    third = idx == 2
    assert torch.equal(moved.origins[third], rays.origins[third]) and torch.equal(moved.directions[third], rays.directions[third])
    assert bool((moved.origins[~third] - rays.origins[~third]).norm(dim=-1).gt(0.05).all())
    refined = opt.apply_to_cameras(cams, torch.arange(3))
    again = refined.generate_rays(idx, torch.tensor([[0, 0], [3, 2], [7, 5], [4, 3], [1, 1], [2, 2]]))
    torch.testing.assert_close(again.origins, moved.origins)
    torch.testing.assert_close(again.directions, moved.directions, atol=1e-6, rtol=0)
    assert torch.equal(moved.camera_indices, rays.camera_indices) and torch.equal(moved.pixel_radius, rays.pixel_radius)


def test_regulariser_and_metrics():
    cfg = CameraOptimizerConfig(mode="SO3xR3", trans_l2_penalty=0.5, rot_l2_penalty=2.0)
    opt = CameraOptimizer(cfg, 2)
    opt.regulariser().backward()  # at zero, where training starts: no NaN from the norm
    assert bool(torch.isfinite(opt.pose_adjustment.grad).all())
    with torch.no_grad():
        opt.pose_adjustment.copy_(torch.tensor([[3.0, 4.0, 0.0, 0.0, 0.0, 0.1], [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]]))
    assert float(opt.regulariser().detach()) == pytest.approx(0.5 * (5 + 1) / 2 + 2.0 * 0.1 / 2)
    m = opt.metrics()
    assert float(m["camera_opt_translation_max"]) == pytest.approx(5.0)
    assert float(m["camera_opt_rotation_deg_max"]) == pytest.approx(0.1 * 180 / torch.pi, rel=1e-5)


def test_gradient_reaches_only_the_cameras_of_the_rays():
    opt = CameraOptimizer(CameraOptimizerConfig(mode="SO3xR3"), 3)
    rays = _cams().generate_rays(torch.tensor([1, 1, 1]), torch.tensor([[0, 0], [3, 2], [7, 5]]))
    moved = opt.apply_to_rays(rays)
    (moved.origins.sum() + (moved.directions * torch.tensor([1.0, 2.0, 3.0])).sum()).backward()
    g = opt.pose_adjustment.grad
    assert bool((g[1].abs() > 0).any()) and bool((g[[0, 2]] == 0).all())
