"""The bird's-eye views' geometry as one value: compared whole, read back from a manifest's config with
the old behaviour of options it predates, and the same raise-and-pitch the enhancer's pairs use."""

import math
from dataclasses import asdict
from types import SimpleNamespace

import torch

from nerf2gs_plugin.augment.config import AugmentConfig
from nerf2gs_plugin.augment.geometry import ViewGeometry
from nerf2gs_plugin.cameras import Cameras, look_at, raise_and_pitch
from nerf2gs_plugin.enhancer.pairs import PITCH_DEG, RAISE_M, SIDE_M, perturb_pose


def test_geometry_of_a_config_equals_the_one_its_manifest_records():
    aug = AugmentConfig(delta_h=7, theta_pitch=25, every_n=0, delta_h_spread=1.5)
    g = ViewGeometry.of(aug)
    assert g == ViewGeometry(7.0, 25.0, 1, "absolute", 1.5, 0.0) and isinstance(g.delta_h, float) and g.every_n == 1
    assert ViewGeometry.recorded({**asdict(aug), "every_n": 1}) == g
    assert ViewGeometry.recorded(asdict(AugmentConfig(theta_pitch=26))) != ViewGeometry.of(AugmentConfig())
    # an entry written before pitch modes and spreads: relative pitch, no spread
    old = {k: v for k, v in asdict(AugmentConfig()).items() if k not in ("pitch_mode", "delta_h_spread", "theta_pitch_spread")}
    assert ViewGeometry.recorded(old) == ViewGeometry.of(AugmentConfig(pitch_mode="relative"))
    assert ViewGeometry.recorded({}) != ViewGeometry.of(AugmentConfig())  # no height recorded: never a match


def test_cameras_convert_metres_once_and_keep_every_nth_source():
    up = torch.tensor([0.0, 0.0, 1.0])
    eye = torch.stack([torch.arange(6.0), torch.zeros(6), torch.full((6,), 1.5)], 1)
    c2w = look_at(eye, eye + torch.tensor([0.0, 1.0, 0.0]), up)
    n = len(c2w)
    cams = Cameras(camera_to_worlds=c2w, fx=torch.full((n,), 50.0), fy=torch.full((n,), 50.0), cx=torch.full((n,), 32.0),
                   cy=torch.full((n,), 24.0), width=torch.full((n,), 64), height=torch.full((n,), 48))
    world = SimpleNamespace(up=up, metres_to_world=lambda m: m * 0.5)  # two metres per world unit
    bev = ViewGeometry(4.0, 30.0, every_n=2).cameras(cams, world)
    assert len(bev) == 3 and torch.equal(bev.fx, cams.fx[::2])
    torch.testing.assert_close(bev.camera_to_worlds[:, 2, 3], torch.full((3,), 1.5 + 2.0))
    assert torch.equal(bev.camera_to_worlds, raise_and_pitch(c2w[::2], up, 2.0, 30.0, "absolute"))


def test_perturbed_pairs_raise_and_pitch_as_before():
    """The enhancer's perturbed pose: the shared raise-and-pitch gives the private matrix's pose."""
    up = torch.tensor([0.0, 0.0, 1.0])
    p = math.radians(12.0)
    fwd = torch.tensor([0.0, math.cos(p), -math.sin(p)])
    right = torch.tensor([1.0, 0.0, 0.0])
    c2w = torch.cat([torch.stack([right, torch.linalg.cross(right, fwd), -fwd], 1), torch.tensor([[1.0], [2.0], [1.5]])], 1)
    got = perturb_pose(c2w, up, torch.Generator().manual_seed(5), metres=2.0)
    gen = torch.Generator().manual_seed(5)
    u = lambda lo, hi: lo + (hi - lo) * float(torch.rand((), generator=gen))  # noqa: E731
    a = -math.radians(u(*PITCH_DEG))
    rot = torch.tensor([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])
    want = c2w.clone()
    want[:, :3] = c2w[:, :3] @ rot  # about the camera's own x axis
    want[:, 3] = want[:, 3] + up * (u(*RAISE_M) / 2.0) + want[:, 0] * (u(-SIDE_M, SIDE_M) / 2.0)
    torch.testing.assert_close(got, want, atol=1e-6, rtol=0)
