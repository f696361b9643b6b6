import math

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.methods.splatfacto.shared import Background, camera_directions
from nerf2gs_plugin.utils.sh import sh_basis, sh_rotation


def _rotation(seed: int) -> torch.Tensor:
    q = torch.randn(4, generator=torch.Generator().manual_seed(seed))
    w, x, y, z = q / q.norm()
    return torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _camera(rot: torch.Tensor, distortion=None) -> Cameras:
    c2w = torch.cat([rot, torch.tensor([[1.0], [-2.0], [0.5]])], 1)[None]
    return Cameras(camera_to_worlds=c2w, fx=torch.tensor([40.0]), fy=torch.tensor([36.0]), cx=torch.tensor([24.0]),
                   cy=torch.tensor([15.0]), width=torch.tensor([48]), height=torch.tensor([32]), distortion_params=distortion)


def test_sh_rotation_maps_the_basis_of_rotated_directions():
    d = torch.nn.functional.normalize(torch.randn(50, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64), dim=-1)
    rot = _rotation(2).double()
    for degree in range(4):
        turn = sh_rotation(degree, rot)
        assert torch.allclose(sh_basis(degree, d) @ turn, sh_basis(degree, d @ rot.T), atol=1e-10)


def test_sky_background_equals_the_per_pixel_basis_and_its_gradient():
    bg = Background("sky", 3)
    with torch.no_grad():
        bg.coeffs.normal_(0.0, 0.5, generator=torch.Generator().manual_seed(3))
    for seed, dist in ((4, None), (5, torch.tensor([[0.05, -0.01, 0.001, 0.002]]))):
        cam = _camera(_rotation(seed), dist)
        fast = bg(cam, True)
        g = torch.randn(fast.shape, generator=torch.Generator().manual_seed(seed))
        (grad_fast,) = torch.autograd.grad((fast * g).sum(), bg.coeffs)
        slow = torch.sigmoid(sh_basis(3, camera_directions(cam)) @ bg.coeffs)
        (grad_slow,) = torch.autograd.grad((slow * g).sum(), bg.coeffs)
        assert fast.shape == (32, 48, 3)
        assert (fast - slow).abs().max() < 1e-6
        assert torch.allclose(grad_fast, grad_slow, rtol=1e-4, atol=1e-5)
    assert len(bg._bases) == 2  # one camera-frame basis per intrinsics


def test_sky_background_of_a_scaled_pose_takes_the_per_pixel_path():
    bg = Background("sky", 2)
    with torch.no_grad():
        bg.coeffs.normal_(0.0, 0.5, generator=torch.Generator().manual_seed(6))
    cam = _camera(_rotation(7) * 1.5)
    want = torch.sigmoid(sh_basis(2, camera_directions(cam)) @ bg.coeffs)
    assert torch.equal(bg(cam, True), want)
    assert not bg._bases
    assert math.isclose(float(want.mean()), float(bg(cam, False).mean()))
