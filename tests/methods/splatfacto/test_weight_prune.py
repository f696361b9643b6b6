"""The blending-weight prune (``strategy.prune_weight_fraction``): weights are what the rasterizer
composites, the prune ends smaller than densification alone and still learns, and a scene seen by
more views keeps more primitives."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pytest
import torch

from splat_tiny_scene import make_cameras, make_train_data, needs_rasterizer, psnr, render_truth, train

from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_config
from nerf2gs_plugin.methods.splatfacto.strategy import DefaultStrategyConfig, light_mask

STEPS = 80


def _cfg(fraction: float):
    base = splatfacto_config.pipeline.model
    strategy = dataclasses.replace(base.strategy, warmup_length=10, refine_every=10, reset_alpha_every=0, stop_split_at=50,
                                   stop_screen_size_at=0, densify_grad_thresh=0.0002, prune_weight_fraction=fraction)
    return dataclasses.replace(base, sh_degree_interval=20, strategy=strategy)


def _views(cams):
    """What the training callbacks read the training views from (the pipeline's data manager)."""
    return SimpleNamespace(datamanager=SimpleNamespace(all_train_cameras=cams))


@pytest.fixture(scope="module")
def scene():
    cams = make_cameras(8, 40, 24)
    imgs, skies = render_truth(cams)
    return cams, imgs, skies


def _trained(scene, fraction: float):
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg(fraction).setup(train_data=make_train_data(cams))
    p0 = psnr(model, cams, imgs)
    train(model, gaussian_optimizers(STEPS), cams, imgs, skies, STEPS, pipeline=_views(cams))
    return model, p0, psnr(model, cams, imgs)


def test_light_mask_follows_how_the_weight_is_spread():
    even = torch.ones(100)
    tailed = torch.cat([torch.full((10,), 100.0), torch.full((90,), 0.1)])  # 10 carry 99% of the weight
    assert int(light_mask(even, 0.05).sum()) == 5
    assert int(light_mask(tailed, 0.05).sum()) == 90
    w = torch.rand(1000, generator=torch.Generator().manual_seed(0)) ** 4
    m = light_mask(w, 0.1)
    assert float(w[m].sum()) <= 0.1 * float(w.sum()) < float(w[m].sum()) + float(w[~m].min())  # the lightest, as many as fit
    assert bool(light_mask(torch.tensor([0.0, 1.0, 2.0]), 0.0)[0])  # unseen primitives always go
    assert int(light_mask(torch.zeros(0), 0.5).sum()) == 0


@needs_rasterizer
def test_blend_weights_sum_to_the_rendered_alpha(scene):
    """Per pixel the blending weights of all Gaussians add up to its alpha (2DGS: test_two_dgs.py)."""
    cams = scene[0]
    torch.manual_seed(0)
    model = _cfg(0.0).setup(train_data=make_train_data(cams)).eval()
    w = model.blend_weights(cams[:3])
    alpha = sum(float(model.render_camera(cams[i])["accumulation"].sum()) for i in range(3))
    assert w.shape == (model.num_primitives(),) and bool((w >= 0).all())
    assert float(w.sum()) == pytest.approx(alpha, rel=1e-4)
    assert int((w > 0).sum()) > model.num_primitives() // 2  # most initial points are in view


@needs_rasterizer
def test_prune_ends_smaller_and_still_learns(scene):
    dense, _, p_dense = _trained(scene, 0.0)
    pruned, p0, p1 = _trained(scene, 0.1)
    assert pruned.num_primitives() < 0.8 * dense.num_primitives(), (pruned.num_primitives(), dense.num_primitives())
    assert p1 > p0 + 3.0, (p0, p1)
    assert p1 > p_dense - 1.5, (p1, p_dense)


@needs_rasterizer
def test_more_views_keep_more_primitives(scene):
    """The same trained model pruned on two of its views or on all eight: what only the other views
    see has no weight in the first, so the scene seen by more views keeps a larger model."""
    cams = scene[0]
    model, _, _ = _trained(scene, 0.0)
    kept = {}
    for name, views in (("few", cams[:2]), ("all", cams)):
        model._train_cameras = lambda v=views: v
        kept[name] = int((~light_mask(model.training_blend_weights(), 0.05)).sum())
    assert kept["few"] < 0.9 * kept["all"] <= model.num_primitives(), kept


@needs_rasterizer
def test_prune_default_and_without_views(scene):
    # on at the CPU scale (size follows the scene); nerfstudio's own strategy defaults keep it off
    assert splatfacto_config.pipeline.model.strategy.prune_weight_fraction == 0.1
    assert DefaultStrategyConfig().prune_weight_fraction == 0.0
    # the fraction read from the fit: 2DGS's (its fixed 10% fell out of the band at the default scale), not Splatfacto's
    from nerf2gs_plugin.registry import get_method

    assert get_method("2dgs").config.pipeline.model.strategy.prune_margin_db == 2.0
    assert splatfacto_config.pipeline.model.strategy.prune_margin_db == 0.0 == DefaultStrategyConfig().prune_margin_db
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg(0.5).setup(train_data=make_train_data(cams))
    assert model.training_blend_weights() is None  # no training callbacks yet: nothing to render
    n = model.num_primitives()
    assert model.strategy.prune_by_weight(model.gauss, None) == 0 and model.num_primitives() == n



def _strategy(fraction: float, margin: float, fidelity_fn):
    from nerf2gs_plugin.methods.splatfacto.strategy import DefaultStrategy

    strategy = DefaultStrategy(DefaultStrategyConfig(prune_weight_fraction=fraction, prune_margin_db=margin))
    strategy.fidelity_fn = fidelity_fn
    return strategy


def _params(n: int) -> torch.nn.ParameterDict:
    return torch.nn.ParameterDict({"means": torch.nn.Parameter(torch.zeros(n, 3)), "opacities": torch.nn.Parameter(torch.zeros(n))})


def test_margin_picks_the_largest_fraction_whose_change_stays_below_the_error():
    """A stand-in measurement: the renders change by 60 dB minus 100 x the hidden weight share, the model's
    error is 25 dB. The margin decides the fraction; one no candidate meets prunes nothing."""
    weights = torch.rand(400, generator=torch.Generator().manual_seed(1)) ** 3

    def measure(cull):
        return 60.0 - 100.0 * float(weights[cull].sum() / weights.sum()), 25.0

    def pruned(margin: float) -> tuple[int, dict]:
        s = _strategy(0.2, margin, measure)
        s.weights_fn = lambda: weights
        n = s.prune_by_weight(_params(400), None)
        return n, s.weight_prunes[-1]

    n_free, log_free = pruned(0.0)  # off: exactly the fraction, nothing measured
    assert n_free == int(light_mask(weights, 0.2).sum()) and log_free["fraction"] == 0.2
    assert log_free["change_db"] != log_free["change_db"]  # nan
    n_loose, log_loose = pruned(5.0)  # 0.2 hides <= 20% of the weight: 40 dB >= 25 + 5, the whole fraction
    assert n_loose == n_free and log_loose["change_db"] >= 30.0 and log_loose["error_db"] == 25.0
    n_mid, log_mid = pruned(27.0)  # needs <= 8% hidden: 0.2 x 3/8 = 0.075 is the largest candidate
    assert log_mid["fraction"] == pytest.approx(0.075) and log_mid["change_db"] >= 52.0
    assert 0 < n_mid < n_loose and n_mid == int(light_mask(weights, 0.075).sum())
    n_none, log_none = pruned(34.99)  # even 0.2 x 1/8 hides more than 0.01%: nothing goes
    assert n_none == 0 and log_none["fraction"] == 0.0 and log_none["change_db"] < 59.99


def test_margin_without_views_prunes_the_fraction():
    """No training views to measure on (None): the configured fraction, as without a margin."""
    weights = torch.rand(100, generator=torch.Generator().manual_seed(2))
    s = _strategy(0.1, 4.0, lambda cull: None)
    s.weights_fn = lambda: weights
    assert s.prune_by_weight(_params(100), None) == int(light_mask(weights, 0.1).sum())


@needs_rasterizer
def test_prune_fidelity_measures_what_the_hidden_primitives_draw(scene):
    """Hiding nothing changes nothing (100 dB); the heaviest primitives change the renders more than as many
    of the lightest; a larger weight fraction changes them more; the error is the renders' PSNR against the
    images over the pixels not masked as sky; the opacities are put back exactly."""
    cams, imgs, skies = scene
    model, _, trained_psnr = _trained(scene, 0.0)
    batches = lambda i: {"image": imgs[i], "sky_mask": torch.zeros_like(imgs[i][..., :1], dtype=torch.bool)}
    before = model.gauss["opacities"].detach().clone()
    weights = model.blend_weights(cams)
    none = torch.zeros_like(weights, dtype=torch.bool)
    change, error = model.prune_fidelity(cams, batches, none)
    assert change == pytest.approx(100.0) and error == pytest.approx(trained_psnr, abs=0.5)
    order = torch.argsort(weights)
    light, heavy = none.clone(), none.clone()
    light[order[:20]], heavy[order[-20:]] = True, True
    assert model.prune_fidelity(cams, batches, heavy)[0] + 10.0 < model.prune_fidelity(cams, batches, light)[0]
    assert model.prune_fidelity(cams, batches, light_mask(weights, 0.2))[0] < model.prune_fidelity(cams, batches, light_mask(weights, 0.05))[0]
    assert torch.equal(model.gauss["opacities"].detach(), before)
    top = lambda i: {"image": imgs[i], "sky_mask": torch.arange(imgs[i].shape[0])[:, None, None] < imgs[i].shape[0] // 2}
    assert model.prune_fidelity(cams, top, none)[1] != pytest.approx(error, abs=1e-3)  # masked pixels left out
    model._train_cameras = None
    assert model.training_prune_fidelity(light) is None
