"""SO(3) exp map and SO3xR3 corrections of rays and poses."""

import pytest
import torch

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.utils.lie import correct_poses, correct_rays, skew, so3_exp_map, so3xr3_matrices


def test_skew_is_the_cross_product():
    a, b = torch.randn(5, 3, generator=torch.Generator().manual_seed(0)), torch.randn(5, 3)
    torch.testing.assert_close((skew(a) @ b[..., None])[..., 0], torch.linalg.cross(a, b))


@pytest.mark.parametrize("scale", [0.0, 1e-5, 3e-3, 0.09, 0.2, 1.0, 3.0])
def test_exp_map_matches_the_matrix_exponential(scale):
    w = torch.randn(16, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    w = w / w.norm(dim=-1, keepdim=True) * scale
    R = so3_exp_map(w)
    torch.testing.assert_close(R, torch.linalg.matrix_exp(skew(w)), atol=1e-12, rtol=0)
    torch.testing.assert_close(R @ R.transpose(-1, -2), torch.eye(3, dtype=torch.float64).expand(16, 3, 3), atol=1e-12, rtol=0)


def test_exp_map_gradient_is_finite_and_right_at_zero():
    """Corrections start at zero: d exp(w) / dw there is the generator of each axis."""
    w = torch.zeros(1, 3, dtype=torch.float64, requires_grad=True)
    for axis in range(3):
        w.grad = None
        R = so3_exp_map(w)
        target = skew(torch.eye(3, dtype=torch.float64)[axis])
        (R[0] * target).sum().backward()
        expected = torch.zeros(3, dtype=torch.float64)
        expected[axis] = (target * target).sum()
        torch.testing.assert_close(w.grad[0], expected)
    assert torch.autograd.gradcheck(so3_exp_map, (torch.tensor([[1e-4, -2e-4, 5e-5], [0.3, -0.2, 0.5]], dtype=torch.float64,
                                                                requires_grad=True),))


def test_corrected_rays_are_the_rays_of_the_corrected_pose():
    eye = torch.tensor([[1.0, -2.0, 1.5], [0.0, 3.0, 1.0]])
    cams = Cameras(look_at(eye, torch.zeros(2, 3), torch.tensor([0.0, 0.0, 1.0])), fx=20.0, fy=20.0, cx=8.0, cy=6.0, width=16, height=12)
    tangent = torch.tensor([[0.1, -0.05, 0.02, 0.03, -0.02, 0.05], [0.0, 0.2, 0.0, -0.1, 0.0, 0.0]])
    corr = so3xr3_matrices(tangent)
    moved = cams.with_poses(correct_poses(cams.camera_to_worlds, corr))
    for i in range(2):
        rays = cams.generate_rays(i)
        o, d = correct_rays(rays.origins, rays.directions, corr[i].expand(len(rays), 3, 4))
        ref = moved.generate_rays(i)
        torch.testing.assert_close(o, ref.origins)
        torch.testing.assert_close(d, ref.directions, atol=1e-6, rtol=0)
    # centre moved by t, orientation turned by the angle |r|
    torch.testing.assert_close(moved.centers, cams.centers + tangent[:, :3])
    rel = moved.camera_to_worlds[:, :, :3] @ cams.camera_to_worlds[:, :, :3].transpose(-1, -2)
    angles = torch.arccos(((rel.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1))
    torch.testing.assert_close(angles, tangent[:, 3:].norm(dim=-1), atol=1e-4, rtol=0)
