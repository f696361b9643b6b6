"""The capture path kept clear (``strategy.path_clearance_m``): primitives near the path where the
cameras stood are pruned whatever their weight, training still learns, and a dataset whose sparse
points crowd the path (a wrong metric scale) switches the clearance off with a warning."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import make_cameras, make_train_data, needs_rasterizer, psnr, render_truth, train

from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_config
from nerf2gs_plugin.warn import Nerf2gsWarning

STEPS = 60
CLEAR = 0.1  # metres; the tiny scene's unit is a metre and its cameras stand 0.25 above the road


def _cfg(clear: float):
    base = splatfacto_config.pipeline.model
    strategy = dataclasses.replace(base.strategy, warmup_length=10, refine_every=10, reset_alpha_every=0, stop_split_at=40,
                                   stop_screen_size_at=0, densify_grad_thresh=0.0002, prune_weight_fraction=0.0,
                                   path_clearance_m=clear)
    return dataclasses.replace(base, sh_degree_interval=20, strategy=strategy)


def _data_with_floaters(cams, n: int):
    """The tiny street's sparse points plus ``n`` opaque-coloured points scattered within 5 cm of the
    cameras' path (the floaters of a real capture)."""
    data = make_train_data(cams)
    g = torch.Generator().manual_seed(3)
    centres = cams.camera_to_worlds[:, :3, 3]
    pick = torch.randint(len(cams) - 1, (n,), generator=g)
    t = torch.rand(n, 1, generator=g)
    on_path = centres[pick] * (1 - t) + centres[pick + 1] * t
    offset = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 0.05 * torch.rand(n, 1, generator=g)
    data.points3D_xyz = torch.cat([data.points3D_xyz, on_path + offset])
    data.points3D_rgb = torch.cat([data.points3D_rgb, torch.full((n, 3), 20, dtype=torch.uint8)])
    return data


@pytest.fixture(scope="module")
def scene():
    cams = make_cameras(8, 40, 24)
    imgs, skies = render_truth(cams)
    return cams, imgs, skies


@needs_rasterizer
def test_the_path_ends_clear_and_the_model_still_learns(scene):
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg(CLEAR).setup(train_data=_data_with_floaters(cams, 15))  # 15 of 615 points: the clearance stays on
    path = model.strategy.path
    assert path is not None and model.strategy.path_radius == pytest.approx(CLEAR)
    assert int(path.near(model.gauss["means"].detach(), CLEAR).sum()) == 15
    p0 = psnr(model, cams, imgs)
    train(model, gaussian_optimizers(STEPS), cams, imgs, skies, STEPS)
    assert int(path.near(model.gauss["means"].detach(), CLEAR).sum()) == 0
    assert psnr(model, cams, imgs) > p0 + 3.0


@needs_rasterizer
def test_without_clearance_the_floaters_stay(scene):
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg(0.0).setup(train_data=_data_with_floaters(cams, 15))
    assert model.strategy.path is None
    train(model, gaussian_optimizers(STEPS), cams, imgs, skies, STEPS)
    from nerf2gs_plugin.methods.capture_path import capture_path

    near = capture_path(cams.camera_to_worlds[:, :3, 3]).near(model.gauss["means"].detach(), CLEAR)
    assert int(near.sum()) > 0  # what the clearance removes: nothing else takes them out


def test_sparse_points_crowding_the_path_switch_it_off(scene):
    cams = scene[0]
    with pytest.warns(Nerf2gsWarning, match="within 0.1 m of the camera path.*metres-per-unit"):
        model = _cfg(CLEAR).setup(train_data=_data_with_floaters(cams, 100))  # 100 of 700: 14%
    assert model.strategy.path is None
