"""The budget read from the views (``strategy.pixel_steps_per_gaussian``): training pixels times the
densification window over it, capped by ``max_gaussians``; growth stops there; more views (a view from above) give more room."""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from splat_tiny_scene import make_cameras, make_train_data, needs_rasterizer, psnr, render_truth, train
from test_weight_prune import _views

from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_config
from nerf2gs_plugin.methods.splatfacto.strategy import DefaultStrategy, DefaultStrategyConfig

STEPS = 80


def _grown(pixels, points: int = 0, **cfg) -> tuple[int, int]:
    """(budget, primitives after one refinement) of 10 small Gaussians, 9 of them above the gradient threshold;
    ``points``: the sparse points the model would report."""
    params = nn.ParameterDict({"means": nn.Parameter(torch.randn(10, 3)), "scales": nn.Parameter(torch.full((10, 3), -6.0)),
                               "quats": nn.Parameter(torch.tensor([[1.0, 0, 0, 0]]).repeat(10, 1)),
                               "opacities": nn.Parameter(torch.full((10,), 3.0))})
    strat = DefaultStrategy(DefaultStrategyConfig(warmup_length=0, refine_every=10, reset_alpha_every=0, stop_split_at=100, **cfg))
    strat.budget.pixels_fn = (lambda: pixels) if pixels is not None else None
    strat.budget.points = points
    strat._reset_stats(10, torch.device("cpu"))
    strat.grad_accum[:] = torch.arange(10).float()
    strat.count[:] = 1.0
    budget = strat.budget.value
    strat.refine(10, params, None)
    return budget, params["means"].shape[0]


def test_budget_is_the_pixels_over_pixels_per_gaussian():
    assert _grown(1300, pixel_steps_per_gaussian=10000.0) == (13, 13)  # 3 clones fit
    assert _grown(1500, pixel_steps_per_gaussian=10000.0) == (15, 15)  # more pixels, more room
    assert _grown(1500, pixel_steps_per_gaussian=10000.0, max_gaussians=12) == (12, 12)  # the smaller of the two
    assert _grown(None, pixel_steps_per_gaussian=10000.0, max_gaussians=12) == (12, 12)  # views not known yet: max-gaussians
    assert _grown(1500, pixel_steps_per_gaussian=0.0) == (0, 19)  # off: unlimited (every candidate cloned)


def test_budget_is_at_least_the_gaussians_per_sparse_point():
    assert _grown(None, points=6, gaussians_per_sparse_point=2.0) == (12, 12)  # the content term alone
    assert _grown(1300, points=6, gaussians_per_sparse_point=2.0, pixel_steps_per_gaussian=10000.0) == (13, 13)  # views larger
    assert _grown(1300, points=8, gaussians_per_sparse_point=2.0, pixel_steps_per_gaussian=10000.0) == (16, 16)  # points larger
    assert _grown(1300, points=8, gaussians_per_sparse_point=2.0, pixel_steps_per_gaussian=10000.0, max_gaussians=14) == (14, 14)
    assert _grown(1300, points=0, gaussians_per_sparse_point=2.0, pixel_steps_per_gaussian=10000.0) == (13, 13)  # no points: views
    assert _grown(1300, points=8, gaussians_per_sparse_point=0.0, pixel_steps_per_gaussian=10000.0) == (13, 13)  # off


def _cfg(pixel_steps_per_gaussian: float):
    base = splatfacto_config.pipeline.model
    strategy = dataclasses.replace(base.strategy, warmup_length=10, refine_every=10, reset_alpha_every=0, stop_split_at=50,
                                   stop_screen_size_at=0, densify_grad_thresh=0.0002, prune_weight_fraction=0.0,
                                   path_clearance_m=0.0, max_gaussians=0, pixel_steps_per_gaussian=pixel_steps_per_gaussian,
                                   gaussians_per_sparse_point=0.0)
    return dataclasses.replace(base, sh_degree_interval=20, strategy=strategy)


@needs_rasterizer
def test_training_stays_within_the_views_budget_and_learns():
    cams = make_cameras(8, 40, 24)
    imgs, skies = render_truth(cams)
    counts = {}
    for name, views in (("free", cams), ("budget", cams), ("more views", make_cameras(16, 40, 24))):
        torch.manual_seed(0)
        model = _cfg(0.0 if name == "free" else 320.0).setup(train_data=make_train_data(cams))
        n0, p0 = model.num_primitives(), psnr(model, cams, imgs)
        train(model, gaussian_optimizers(STEPS), cams, imgs, skies, STEPS, pipeline=_views(views))
        counts[name] = model.num_primitives()
        if name == "budget":
            assert model.training_pixels() == 8 * 40 * 24 and model.strategy.budget.value == 8 * 40 * 24 * (50 - 10) // 320
            assert n0 < counts[name] <= model.strategy.budget.value
            assert psnr(model, cams, imgs) > p0 + 3.0
    assert counts["budget"] < counts["free"], counts  # the budget binds on this scene
    assert counts["more views"] > counts["budget"], counts  # twice the pixels: room to grow further


def test_the_model_gives_its_budget_the_sparse_points_also_after_a_reload():
    base = splatfacto_config.pipeline.model
    cfg = dataclasses.replace(base, strategy=dataclasses.replace(base.strategy, pixel_steps_per_gaussian=0.0,
                                                                  gaussians_per_sparse_point=2.5, max_gaussians=0))
    data = make_train_data(make_cameras(4, 40, 24))
    model = cfg.setup(train_data=data)
    assert model.strategy.budget.points == len(data.points3D_xyz) > 0
    assert model.strategy.budget.value == int(2.5 * len(data.points3D_xyz))
    model.load_model_state(model.state_dict())
    assert model.strategy.budget.value == int(2.5 * len(data.points3D_xyz))
    no_points = cfg.setup(train_data=make_train_data(make_cameras(4, 40, 24), with_points=False))
    assert no_points.strategy.budget.value == 0  # nothing to read: unlimited, as max-gaussians 0
