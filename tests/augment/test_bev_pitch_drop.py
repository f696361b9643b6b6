"""Bird's-eye views: absolute pitch from the ground plane's horizon, and views that must not be
trained on (outside the scene box, mostly empty renders) dropped with one warning."""

import math
from types import SimpleNamespace

import pytest
import torch

from nerf2gs_plugin.cameras import birds_eye_poses, birds_eye_poses_absolute, look_at
from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
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


def test_spread_gives_each_view_its_own_height_and_pitch_and_none_keeps_the_old_views():
    from nerf2gs_plugin.cameras import Cameras
    from nerf2gs_plugin.augment.cache import cache_key
    from nerf2gs_plugin.augment.geometry import ViewGeometry
    from nerf2gs_plugin.errors import ConfigError

    up = torch.tensor([0.0, 0.0, 1.0])
    metric = SimpleNamespace(up=up, metres_to_world=lambda m: m)  # poses in metres
    eye = torch.stack([torch.arange(8.0), torch.zeros(8), torch.full((8,), 1.5)], 1)
    c2w = look_at(eye, eye + torch.tensor([1.0, 0.0, 0.0]), up)
    cams = Cameras(camera_to_worlds=c2w, fx=torch.full((8,), 50.0), fy=torch.full((8,), 50.0), cx=torch.full((8,), 32.0),
                   cy=torch.full((8,), 24.0), width=torch.full((8,), 64), height=torch.full((8,), 48))
    for mode in ("absolute", "relative"):
        plain = ViewGeometry(2.0, 30.0, pitch_mode=mode).cameras(cams, metric)
        # no spread: exactly the one-ring views of before (bitwise), and per-view tensors of one value agree with them
        assert torch.equal(ViewGeometry(2.0, 30.0, pitch_mode=mode, delta_h_spread=0.0).cameras(cams, metric).camera_to_worlds,
                           plain.camera_to_worlds)
        pose = birds_eye_poses_absolute if mode == "absolute" else birds_eye_poses
        same = pose(c2w, up, torch.full((8,), 2.0), torch.full((8,), 30.0))
        assert torch.allclose(same, plain.camera_to_worlds[:, :3, :4], atol=1e-5)
        spread = ViewGeometry(2.0, 30.0, pitch_mode=mode, delta_h_spread=1.0, theta_pitch_spread=10.0).cameras(cams, metric)
        raise_ = spread.camera_to_worlds[:, 2, 3] - 1.5
        pitch = -_pitch_deg(spread.camera_to_worlds[:, :3, :4], up)
        assert ((raise_ >= 1.0 - 1e-5) & (raise_ <= 3.0 + 1e-5)).all() and raise_.std() > 0.2  # heights 1..3, not all one
        assert ((pitch >= 20.0 - 1e-3) & (pitch <= 40.0 + 1e-3)).all() and pitch.std() > 2.0
        again = ViewGeometry(2.0, 30.0, pitch_mode=mode, delta_h_spread=1.0, theta_pitch_spread=10.0).cameras(cams, metric)
        assert torch.equal(again.camera_to_worlds, spread.camera_to_worlds)  # the same draws every time (the cache keys them)
    with pytest.raises(ConfigError, match="spread"):
        ViewGeometry(2.0, 30.0, delta_h_spread=-1.0).cameras(cams, metric)
    # a config without spreads keys the render cache as the configs made before the option did
    cfg = {k: v for k, v in AugmentConfig().__dict__.items()}
    old = {k: v for k, v in cfg.items() if k not in ("delta_h_spread", "theta_pitch_spread")}
    assert cache_key("r", "d", cfg, None, cams, "none") == cache_key("r", "d", old, None, cams, "none")
    assert cache_key("r", "d", {**cfg, "delta_h_spread": 2.0}, None, cams, "none") != cache_key("r", "d", cfg, None, cams, "none")


class SeesAll:
    def __call__(self, camera):
        h, w = int(camera.height[0]), int(camera.width[0])
        return {"rgb": torch.full((h, w, 3), 0.3), "depth": torch.ones(h, w, 1), "accumulation": torch.ones(h, w, 1)}


def test_augmentation_spreads_its_views_in_metres(tiny_scene, tmp_path):
    """--augment.delta-h-spread reaches the rendered views, converted to world units like delta-h."""
    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    td, n = dm.train_data, len(dm.train_images)
    up = td.up / td.up.norm()
    base = dm.train_images.cameras.camera_to_worlds[:, :3, 3] @ up
    views = AugmentedDataManager(dm, Reference(SeesAll(), "ref:s", tmp_path),
                                 AugmentConfig(composites=False, delta_h=0.2, delta_h_spread=0.1, theta_pitch_spread=5.0)).views
    raised = (views.extra.cameras.camera_to_worlds[:, :3, 3] @ up - base) / td.metres_to_world(1.0)  # metres
    assert len(views.extra) == n and ((raised > 0.1 - 1e-4) & (raised < 0.3 + 1e-4)).all() and raised.std() > 0.02
