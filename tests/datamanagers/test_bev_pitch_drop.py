"""Bird's-eye views: absolute pitch from the ground plane's horizon, and views that must not be
trained on (outside the scene box, mostly empty renders) dropped with one warning."""

import math

import pytest
import torch

from nerf2gs_plugin.cameras import birds_eye_poses, birds_eye_poses_absolute, look_at
from nerf2gs_plugin.datamanagers.augmented import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig


def _pitch_deg(c2w, up):
    f = -c2w[:, :, 2]
    return torch.rad2deg(torch.asin((f @ up).clamp(-1, 1)))


def test_absolute_pitch_is_below_the_horizon_whatever_the_tilt():
    up = torch.tensor([0.0, 0.0, 1.0])
    eye = torch.tensor([[0.0, 0, 1.5], [3, 1, 1.5], [6, 2, 1.6]])
    target = eye + torch.tensor([[1.0, 0, 0.36], [0, 1, 0.18], [1, 1, 0.0]])  # ~20 deg up, ~10 deg up, level
    c2w = look_at(eye, target, up)
    roll = birds_eye_poses(c2w, up, 0.0, 0.0)  # a rolled input: rotate the first camera about its axis
    roll[0, :, :3] = roll[0, :, :3] @ torch.tensor([[math.cos(0.2), -math.sin(0.2), 0], [math.sin(0.2), math.cos(0.2), 0], [0, 0, 1.0]])
    out = birds_eye_poses_absolute(roll, up, 2.0, 30.0)
    assert torch.allclose(_pitch_deg(out, up), torch.full((3,), -30.0), atol=1e-4)
    assert torch.allclose(out[:, :, 0] @ up, torch.zeros(3), atol=1e-6)  # levelled: no roll
    assert torch.allclose(out[:, :, 3] - roll[:, :, 3], 2.0 * up.expand(3, 3), atol=1e-6)
    rel = birds_eye_poses(roll, up, 2.0, 30.0)
    assert float(_pitch_deg(rel, up)[0]) > -15.0  # the relative mode keeps the ~20 deg upward tilt
    # level cameras (the synthetic street's): both modes agree
    level = look_at(eye, eye + torch.tensor([1.0, 0.3, 0.0]), up)
    assert torch.allclose(birds_eye_poses_absolute(level, up, 2.0, 30.0), birds_eye_poses(level, up, 2.0, 30.0), atol=1e-5)


class HalfEmpty:
    """A stand-in reference that sees nothing from every other bird's-eye camera."""

    def __init__(self):
        self.calls = 0

    def __call__(self, camera):
        self.calls += 1
        h, w = int(camera.height[0]), int(camera.width[0])
        acc = torch.ones(h, w, 1) * (self.calls % 2)
        return {"rgb": torch.full((h, w, 3), 0.3), "depth": torch.ones(h, w, 1), "accumulation": acc}


def test_empty_and_outside_views_are_dropped(tiny_scene, tmp_path):
    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    n = len(dm.train_images)
    with pytest.warns(UserWarning, match=r"of \d+ bird's-eye views dropped"):
        views = AugmentedDataManager(dm, Reference(HalfEmpty(), "ref:x", tmp_path), AugmentConfig(composites=False, delta_h=0.1)).views
    assert views.extra is not None and len(views.extra) == (n + 1) // 2
    dm2 = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    with pytest.warns(UserWarning, match="outside the scene box"):
        views2 = AugmentedDataManager(dm2, Reference(HalfEmpty(), "ref:y", tmp_path), AugmentConfig(composites=False, delta_h=1e4)).views
    assert views2.extra is None
