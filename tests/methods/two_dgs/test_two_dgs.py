"""2DGS on the tiny analytic street: learns, splits in the tangent plane, has its losses, reloads."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from torch import nn

from splat_tiny_scene import needs_rasterizer, batch_for, make_cameras, make_train_data, psnr, render_truth, train

from nerf2gs_plugin.utils.quaternions import quat_to_rotmat
from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers
from nerf2gs_plugin.methods.splatfacto.strategy import DefaultStrategy, DefaultStrategyConfig
from nerf2gs_plugin.methods.two_dgs.config import paper_scale, two_dgs_method
from nerf2gs_plugin.methods.two_dgs.model import ZERO_LOG_SCALE


def _cfg(**kw):
    model = two_dgs_method.config.pipeline.model
    strategy = dataclasses.replace(model.strategy, warmup_length=20, refine_every=10, reset_alpha_every=60, stop_split_at=100,
                                   stop_screen_size_at=0, max_gaussians=4000)
    base = dict(sh_degree_interval=15, dist_start=10, normal_start=20, strategy=strategy)
    base.update(kw)
    return dataclasses.replace(model, **base)


@pytest.fixture(scope="module")
def scene():
    cams = make_cameras(6, 40, 24)
    imgs, skies = render_truth(cams)
    return cams, imgs, skies


@pytest.fixture(scope="module")
def trained(scene):
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg().setup(train_data=make_train_data(cams))
    p0 = psnr(model, cams, imgs)
    train(model, gaussian_optimizers(50), cams, imgs, skies, 50)
    return model, p0


def test_spec():
    assert two_dgs_method.config.method_name == "2dgs"
    assert paper_scale(two_dgs_method.config).pipeline.model.normal_start == 7000


@needs_rasterizer
def test_blend_weights_sum_to_the_rendered_alpha(scene, trained):
    """The weight prune's significance (splatfacto's strategy.prune_weight_fraction) for surfels:
    per pixel the surfels' blending weights add up to its alpha."""
    cams = scene[0]
    model = trained[0].eval()
    w = model.blend_weights(cams[:3])
    alpha = sum(float(model.render_camera(cams[i])["accumulation"].sum()) for i in range(3))
    model.train()
    assert w.shape == (model.num_primitives(),) and bool((w >= 0).all()) and int((w > 0).sum()) > 0
    assert float(w.sum()) == pytest.approx(alpha, rel=1e-4)


@needs_rasterizer
def test_training_raises_psnr(scene, trained):
    cams, imgs, _ = scene
    model, p0 = trained
    assert model.gauss["scales"].shape[1] == 2
    assert psnr(model, cams, imgs) > p0 + 2.0
    assert model.num_primitives() != 600


@needs_rasterizer
def test_outputs_and_regularisers(scene, trained):
    cams, imgs, skies = scene
    model, _ = trained
    model.train()
    out = model.get_outputs(cams[0])
    losses = model.get_loss_dict(out, batch_for(imgs, skies, 0), {})
    assert {"main_loss", "normal_loss", "distortion_loss"} <= set(losses)
    assert all(torch.isfinite(v) for v in losses.values())
    model.eval()
    r = model.render_camera(cams[0])
    assert set(r) == {"rgb", "depth", "accumulation", "normals"}
    covered = r["accumulation"][..., 0] > 0.5
    assert torch.allclose(r["normals"][covered].norm(dim=-1), torch.ones(int(covered.sum())), atol=1e-4)


@needs_rasterizer
def test_losses_respect_start_steps(scene):
    cams, imgs, skies = scene
    model = _cfg(dist_start=100, normal_start=100).setup(train_data=make_train_data(cams))
    model.train()
    losses = model.get_loss_dict(model.get_outputs(cams[0]), batch_for(imgs, skies, 0), {})
    assert "normal_loss" not in losses and "distortion_loss" not in losses


def test_split_stays_in_tangent_plane():
    torch.manual_seed(0)
    n = 4
    params = nn.ParameterDict({
        "means": nn.Parameter(torch.zeros(n, 3)),
        "scales": nn.Parameter(torch.full((n, 2), -1.0)),
        "quats": nn.Parameter(torch.randn(n, 4)),
        "opacities": nn.Parameter(torch.zeros(n)),
    })
    strat = DefaultStrategy(DefaultStrategyConfig(warmup_length=0, refine_every=10, reset_alpha_every=0))
    strat._reset_stats(n, torch.device("cpu"))
    strat.grad_accum[:] = 1.0
    strat.count[:] = 1.0
    normals = quat_to_rotmat(params["quats"].detach())[:, :, 2]
    strat.refine(10, params, None)
    assert params["means"].shape[0] == 2 * n
    # children of surfel i sit in its plane (offset orthogonal to its normal)
    child_normals = quat_to_rotmat(params["quats"].detach())[:, :, 2]
    offs = (params["means"].detach() * child_normals).sum(-1)
    assert torch.allclose(offs, torch.zeros_like(offs), atol=1e-5)
    assert torch.allclose(child_normals.abs().sum(), normals.abs().sum() * 2, atol=1e-4)


@needs_rasterizer
def test_checkpoint_reload_and_export(scene, trained):
    cams, _, _ = scene
    model, _ = trained
    fresh = _cfg().setup(train_data=make_train_data(cams))
    fresh.load_model_state({k: v.clone() for k, v in model.state_dict().items()})
    model.eval()
    fresh.eval()
    a, b = model.render_camera(cams[3]), fresh.render_camera(cams[3])
    for k in a:
        assert torch.allclose(a[k], b[k], atol=1e-6), k
    ex = fresh.export_gaussians()
    assert ex["log_scales"].shape == (fresh.num_primitives(), 3)
    assert torch.all(ex["log_scales"][:, 2] == ZERO_LOG_SCALE)


@needs_rasterizer
def test_rendered_and_depth_normals_agree_on_a_tilted_surfel(scene):
    """The normal-consistency loss needs both normals in one frame with one orientation."""
    cams, _, _ = scene
    model = _cfg(background="black").setup(train_data=make_train_data(cams))
    cam = cams[2]
    c2w = cam.camera_to_worlds[0]
    centre = c2w[:, 3] - 0.6 * c2w[:, 2]  # 0.6 in front of the camera (OpenGL looks down -z)
    tilt = torch.tensor(0.5)
    # surfel normal = camera's backward axis tilted about the camera's x axis
    from nerf2gs_plugin.utils.quaternions import rotmat_to_quat

    Rx = torch.tensor([[1.0, 0, 0], [0, torch.cos(tilt), -torch.sin(tilt)], [0, torch.sin(tilt), torch.cos(tilt)]])
    R = c2w[:, :3] @ Rx
    with torch.no_grad():
        model.gauss["means"] = nn.Parameter(centre[None])
        model.gauss["scales"] = nn.Parameter(torch.full((1, 2), -1.0))
        model.gauss["quats"] = nn.Parameter(rotmat_to_quat(R[None]))
        model.gauss["opacities"] = nn.Parameter(torch.full((1,), 5.0))
        model.gauss["features_dc"] = nn.Parameter(torch.zeros(1, 3))
        model.gauss["features_rest"] = nn.Parameter(torch.zeros(1, 15, 3))
    model.eval()
    out = model._render(cam, training=False)
    h, w = out["accumulation"].shape[:2]
    centre_px = (slice(h // 2 - 3, h // 2 + 3), slice(w // 2 - 3, w // 2 + 3))
    n = torch.nn.functional.normalize(out["rendered_normals"][centre_px], dim=-1)
    sn = torch.nn.functional.normalize(out["surf_normals"][centre_px], dim=-1)
    assert float((n * sn).sum(-1).mean()) > 0.9
    # world normals face the camera and match the surfel's axis up to sign
    wn = out["normals"][centre_px].reshape(-1, 3).mean(0)
    assert abs(float(torch.dot(torch.nn.functional.normalize(wn, dim=0), R[:, 2]))) > 0.95
    assert float(torch.dot(wn, c2w[:, 3] - centre)) > 0
