import math

import torch

from nerf2gs_plugin.cameras import (
    Cameras,
    birds_eye_poses,
    distort_normalized,
    look_at,
    opencv_w2c_to_opengl_c2w,
    undistort_normalized,
)


def _random_cameras(n=3, dist=None, seed=0):
    g = torch.Generator().manual_seed(seed)
    eye = torch.randn(n, 3, generator=g) * 2
    target = torch.randn(n, 3, generator=g) * 0.1
    c2w = look_at(eye, target, torch.tensor([0.0, 0.0, 1.0]))
    return Cameras(c2w, fx=40.0, fy=42.0, cx=31.5, cy=23.0, width=64, height=48, distortion_params=dist)


def test_pixel_ray_projection_round_trip():
    cams = _random_cameras()
    for i in range(len(cams)):
        coords = torch.tensor([[0, 0], [10, 20], [63, 47], [32, 24]])
        rays = cams.generate_rays(torch.full((4,), i), coords)
        pts = rays.origins + 3.7 * rays.directions
        uv, z = cams.project(pts, i)
        assert torch.allclose(uv, coords.float() + 0.5, atol=1e-3)
        assert (z > 0).all()


def test_distorted_round_trip():
    cams = _random_cameras(dist=torch.tensor([-0.12, 0.03, 0.001, -0.002]))
    coords = torch.tensor([[1, 2], [60, 40], [30, 30]])
    rays = cams.generate_rays(torch.zeros(3, dtype=torch.long), coords)
    uv, _ = cams.project(rays.origins + rays.directions, 0)
    assert torch.allclose(uv, coords.float() + 0.5, atol=1e-3)
    x, y = torch.rand(50) - 0.5, torch.rand(50) - 0.5
    d = torch.tensor([-0.12, 0.03, 0.001, -0.002]).expand(50, 4)
    xu, yu = undistort_normalized(*distort_normalized(x, y, d), d)
    assert torch.allclose(xu, x, atol=1e-5) and torch.allclose(yu, y, atol=1e-5)


def test_opengl_opencv_round_trip_and_convention():
    cams = _random_cameras()
    w2c = cams.viewmats()
    assert torch.allclose(opencv_w2c_to_opengl_c2w(w2c), cams.camera_to_worlds, atol=1e-5)
    # a point straight ahead of an OpenGL camera (-z) has positive OpenCV depth (+z)
    ahead = cams.centers[0] - 2.0 * cams.camera_to_worlds[0, :, 2]
    p = w2c[0, :3, :3] @ ahead + w2c[0, :3, 3]
    assert abs(p[2].item() - 2.0) < 1e-4 and p[:2].abs().max() < 1e-4


def test_birds_eye_pose_height_and_pitch():
    up = torch.tensor([0.0, 0.0, 1.0])
    # level camera at 3 m looking along +x
    c2w = look_at(torch.tensor([[0.0, 0.0, 3.0]]), torch.tensor([[1.0, 0.0, 3.0]]), up)
    bev = birds_eye_poses(c2w, up, 10.0, 30.0)
    assert torch.allclose(bev[0, :, 3], torch.tensor([0.0, 0.0, 13.0]), atol=1e-5)
    fwd = -bev[0, :, 2]
    pitch = math.degrees(math.asin(-fwd[2].item()))
    assert abs(pitch - 30.0) < 1e-4  # pitched DOWN by 30 degrees
    assert torch.allclose(bev[0, :, 0], c2w[0, :, 0], atol=1e-6)  # right axis unchanged
    R = bev[0, :, :3]
    assert torch.allclose(R @ R.T, torch.eye(3), atol=1e-5)


def test_indexing_and_scaling():
    cams = _random_cameras(5)
    sub = cams[torch.tensor([0, 2])]
    assert len(sub) == 2 and torch.equal(sub.camera_to_worlds[1], cams.camera_to_worlds[2])
    half = cams.scaled(0.5)
    assert int(half.width[0]) == 32 and abs(float(half.fx[0]) - 20.0) < 1e-6
    assert len(Cameras.cat([cams, sub])) == 7
