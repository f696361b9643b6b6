"""Scaffold-GS on the tiny analytic street: learns, grows and prunes anchors, reloads, exports."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import needs_rasterizer, make_cameras, make_train_data, psnr, render_truth, train

from nerf2gs_plugin.methods.gaussian_utils import read_gaussian_ply, write_gaussian_ply
from nerf2gs_plugin.methods.scaffold_gs.anchors import grow_anchors, prune_anchors, voxelize
from nerf2gs_plugin.methods.scaffold_gs.config import paper_scale, scaffold_gs_method, scaffold_optimizers
from nerf2gs_plugin.engine.optimizers import Optimizers


def _cfg(**kw):
    base = dict(start_stat=5, update_from=10, update_interval=10, update_until=100)
    base.update(kw)
    return dataclasses.replace(scaffold_gs_method.config.pipeline.model, **base)


@pytest.fixture(scope="module")
def scene():
    cams = make_cameras(6, 40, 24)
    imgs, skies = render_truth(cams)
    return cams, imgs, skies


@pytest.fixture(scope="module")
def trained(scene):
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg(appearance_dim=4).setup(train_data=make_train_data(cams))
    p0 = psnr(model, cams, imgs)
    train(model, scaffold_optimizers(50), cams, imgs, skies, 50)
    return model, p0


def test_spec_and_voxelize():
    assert scaffold_gs_method.config.method_name == "scaffold-gs"
    assert paper_scale(scaffold_gs_method.config).pipeline.model.update_until == 15000
    paper = paper_scale(scaffold_gs_method.config).pipeline.model
    assert paper.anchor_growth == 0 and paper.pixel_steps_per_anchor == 0  # Scaffold-GS grows without a budget
    # an anchor spawns n-offsets neural Gaussians: the views term gives each Splatfacto's pixel-steps per Gaussian
    from nerf2gs_plugin.methods.splatfacto.model import SplatfactoModelConfig

    own = scaffold_gs_method.config.pipeline.model
    assert own.pixel_steps_per_anchor == own.n_offsets * SplatfactoModelConfig().strategy.pixel_steps_per_gaussian
    pts = torch.tensor([[0.01, 0.0, 0.0], [0.04, 0.0, 0.0], [0.27, 0.0, 0.0], [0.31, 0.01, 0.0]])
    anchors = voxelize(pts, 0.1)
    assert anchors.shape == (2, 3)
    assert torch.allclose(anchors.sort(0).values[:, 0], torch.tensor([0.0, 0.3]))


@needs_rasterizer
def test_training_raises_psnr_and_has_structure(scene, trained):
    cams, imgs, _ = scene
    model, p0 = trained
    assert psnr(model, cams, imgs) > p0 + 2.0
    c = model.config
    assert model.anchor["offsets"].shape[1:] == (c.n_offsets, 3) and model.anchor["anchor_feat"].shape[1] == c.feat_dim
    assert model.appearance is not None and model._image_index(cams[2]) == 2


@needs_rasterizer
def test_only_positive_opacity_in_frustum_is_rasterized(scene, trained):
    cams, _, _ = scene
    model, _ = trained
    model.train()
    model.get_outputs(cams[0])
    last = model._last
    assert last is not None
    assert int(last["keep"].sum()) == last["meta"]["means2d"].shape[1]
    assert bool((last["opacity"][last["keep"]] > 0).all())
    # anchors behind the camera are culled
    vis = model.visible_anchors(cams[0])
    w2c = cams[0].viewmats()[0]
    z = (model.anchor["anchors"] @ w2c[:3, :3].T + w2c[:3, 3])[:, 2]
    assert bool((z[vis] > 0).all())


def test_visible_anchors_culls_behind_and_outside_the_frustum(scene):
    """Anchors placed in front of, behind and far beside the camera: only the first is visible."""
    cams, _, _ = scene
    model = _cfg().setup(train_data=make_train_data(cams))
    c2w = cams.camera_to_worlds[0]
    centre, right, fwd = c2w[:, 3], c2w[:, 0], -c2w[:, 2]  # OpenGL: the camera looks down -z
    probes = torch.stack([centre + 2 * fwd, centre - 2 * fwd, centre + 2 * fwd + 50 * right])
    n = model.anchor["anchors"].shape[0]
    with torch.no_grad():
        model.anchor["anchors"].data = torch.cat([model.anchor["anchors"].data, probes])
    vis = set(model.visible_anchors(cams[0]).tolist())
    assert n in vis and n + 1 not in vis and n + 2 not in vis


def _fresh_with_optimizers(scene, **cfg):
    cams, _, _ = scene
    model = _cfg(**cfg).setup(train_data=make_train_data(cams))
    opts = Optimizers(scaffold_optimizers(10), model.get_param_groups())
    model.stats.reset(model.num_primitives(), model.config.n_offsets, torch.device("cpu"))
    return model, opts


def test_grow_adds_anchors_only_in_empty_voxels(scene):
    torch.manual_seed(0)
    model, opts = _fresh_with_optimizers(scene)
    k, m0 = model.config.n_offsets, model.num_primitives()
    # push the offsets of 40 anchors far away so their Gaussians sit in empty voxels, with large gradients
    with torch.no_grad():
        model.anchor["offsets"][:40] = 3.0
        model.anchor["anchor_feat"][:40] = torch.randn(40, model.config.feat_dim)
    slots = torch.arange(40 * k)
    model.stats.grad_accum[slots] = 1.0
    model.stats.denom[:] = 100.0
    added = grow_anchors(model.config, model.stats, model.anchor, float(model.voxel), opts)
    assert added > 0 and model.num_primitives() == m0 + added
    a = model.anchor["anchors"]
    assert torch.unique(torch.round(a / float(model.voxel)).long(), dim=0).shape[0] == a.shape[0]  # no duplicates
    assert model.anchor["offsets"][m0:].abs().sum() == 0
    assert model.stats.denom.shape[0] == model.num_primitives() * k and model.stats.denom[slots].sum() == 0
    # with no gradient nothing grows
    assert grow_anchors(model.config, model.stats, model.anchor, float(model.voxel), opts) == 0


def test_prune_drops_transparent_anchors(scene):
    model, opts = _fresh_with_optimizers(scene)
    m0 = model.num_primitives()
    model.stats.anchor_denom[:] = 100.0
    model.stats.opacity_accum[:] = 10.0
    model.stats.opacity_accum[:7] = 0.0  # never opaque
    kept_feat = model.anchor["anchors"][7:].clone()
    assert prune_anchors(model.config, model.stats, model.anchor, opts) == 7
    assert model.num_primitives() == m0 - 7
    assert torch.equal(model.anchor["anchors"], kept_feat)
    assert model.stats.grad_accum.shape[0] == (m0 - 7) * model.config.n_offsets


@needs_rasterizer
def test_checkpoint_reload_and_export(scene, trained, tmp_path):
    cams, _, _ = scene
    model, _ = trained
    fresh = _cfg(appearance_dim=4).setup(train_data=make_train_data(cams))
    fresh.load_model_state({k: v.clone() for k, v in model.state_dict().items()})
    model.eval()
    fresh.eval()
    a, b = model.render_camera(cams[4]), fresh.render_camera(cams[4])
    for key in a:
        assert torch.allclose(a[key], b[key], atol=1e-6), key
    for view in (1, -1):
        g = fresh.export_gaussians(cameras=cams, view=view)
        assert g["means"].shape[0] > 0 and g["log_scales"].shape[1] == 3
        write_gaussian_ply(tmp_path / f"v{view}.ply", **g)
        back = read_gaussian_ply(tmp_path / f"v{view}.ply")
        assert torch.allclose(back["means"], g["means"]) and torch.allclose(back["features_dc"], g["features_dc"])
    assert fresh.export_gaussians(cameras=cams, view=-1)["means"].shape[0] >= fresh.export_gaussians(cameras=cams, view=0)["means"].shape[0]


def test_with_steps_rescales_anchor_schedule():
    from nerf2gs_plugin.utils.schedule import with_steps

    quick = with_steps(scaffold_gs_method.config, 1500)
    m = quick.pipeline.model
    assert (m.start_stat, m.update_from, m.update_until, m.update_interval) == (25, 75, 750, 50)
    assert quick.optimizers["offsets"].max_steps == 1500 and quick.optimizers["anchors"].max_steps == 30000


def _assert_growth_stops_at(model, opts, m0: int, room: int) -> None:
    """40 anchors' offsets well above the growing threshold: growth adds exactly the budget's room."""
    model.stats.reset(m0, model.config.n_offsets, torch.device("cpu"))
    k = model.config.n_offsets
    with torch.no_grad():
        model.anchor["offsets"][:40] = 3.0
    model.stats.grad_accum[torch.arange(40 * k)] = 1.0
    model.stats.denom[:] = 100.0
    added = grow_anchors(model.config, model.stats, model.anchor, float(model.voxel), opts, model.strategy.budget.value)
    assert added == room and model.num_primitives() == m0 + room


@needs_rasterizer
def test_growth_stops_at_the_budget_read_from_the_views(scene):
    """``pixel_steps_per_anchor``: the views' pixels x the growing steps over it caps the anchors; the
    model reads the views from the training callbacks, also after a checkpoint reload."""
    from types import SimpleNamespace

    from nerf2gs_plugin.engine.callbacks import TrainingCallbackAttributes

    cams = scene[0]
    torch.manual_seed(0)
    m0 = _cfg().setup(train_data=make_train_data(cams)).num_primitives()
    pixels, steps = cams.pixel_count(), 100 - 10  # update_until - update_from
    assert pixels == 6 * 40 * 24
    model, opts = _fresh_with_optimizers(scene, pixel_steps_per_anchor=pixels * steps / (m0 + 5), anchor_growth=0.0)
    assert model.strategy.budget.value == model.config.max_anchors  # views not named yet
    model.get_training_callbacks(TrainingCallbackAttributes(optimizers=opts, pipeline=SimpleNamespace(
        datamanager=SimpleNamespace(all_train_cameras=cams))))
    assert model.strategy.budget.value == m0 + 5
    model.load_model_state(model.state_dict())  # a reload makes a new strategy: still reading the views
    assert model.strategy.budget.value == m0 + 5
    _assert_growth_stops_at(model, opts, m0, 5)


@needs_rasterizer
def test_growth_stops_at_a_multiple_of_the_initial_anchors(scene):
    """``anchor_growth``: the anchors grow to at most that many times the initial ones (the voxelised sparse
    points; the views term off), with no views named and after a checkpoint reload; with the views term on too, the larger."""
    cams = scene[0]
    m0 = _cfg().setup(train_data=make_train_data(cams)).num_primitives()
    model, opts = _fresh_with_optimizers(scene, anchor_growth=(m0 + 5) / m0, pixel_steps_per_anchor=0.0)
    assert model.strategy.budget.value == m0 + 5
    model.load_model_state(model.state_dict())
    assert model.strategy.budget.value == m0 + 5
    _assert_growth_stops_at(model, opts, m0, 5)
    pixels = cams.pixel_count() * (100 - 10)
    both, _ = _fresh_with_optimizers(scene, anchor_growth=(m0 + 5) / m0, pixel_steps_per_anchor=pixels / (m0 + 9))
    both.strategy.budget.pixels_fn = lambda: cams.pixel_count()
    assert both.strategy.budget.value == m0 + 9
