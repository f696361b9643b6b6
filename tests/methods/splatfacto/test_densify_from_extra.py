"""``densify_from_extra_views``: whether a batch of an additional view (``image_idx`` past the input views)
adds to the clone / split statistics; it still moves the Gaussians either way."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import batch_for, make_cameras, make_train_data, needs_rasterizer, render_truth

from nerf2gs_plugin.engine.callbacks import TrainingCallbackAttributes, TrainingCallbackLocation as Loc
from nerf2gs_plugin.engine.optimizers import Optimizers
from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_config

N_INPUT = 4


def _step(model, opts, callbacks, camera, batch, step):
    for cb in callbacks:
        cb.run(Loc.BEFORE_STEP, step)
    opts.zero_grad()
    out = model.get_outputs(camera)
    losses = model.get_loss_dict(out, batch, model.get_metrics_dict(out, batch))
    sum(losses.values()).backward()
    opts.step(step)
    for cb in callbacks:
        cb.run(Loc.AFTER_STEP, step)


def _stats_after_an_extra_view(from_extra: bool) -> tuple[float, float, bool]:
    """Visible count and gradient sum after one input-view step and one additional-view step (before
    any refinement), and whether the additional view moved the means."""
    cams = make_cameras(N_INPUT + 2, 40, 24)
    images, skies = render_truth(cams)
    cfg = dataclasses.replace(splatfacto_config.pipeline.model, densify_from_extra_views=from_extra)
    model = cfg.setup(train_data=make_train_data(cams[:N_INPUT]))
    model.train()
    opts = Optimizers(gaussian_optimizers(100), model.get_param_groups())
    callbacks = model.get_training_callbacks(TrainingCallbackAttributes(optimizers=opts, pipeline=None))
    _step(model, opts, callbacks, cams[0], batch_for(images, skies, 0), 1)
    count, grad = float(model.strategy.count.sum()), float(model.strategy.grad_accum.sum())
    means = model.gauss["means"].detach().clone()
    extra = {"image": images[N_INPUT + 1], "weight": torch.tensor(1.0), "image_idx": N_INPUT + 1}
    _step(model, opts, callbacks, cams[N_INPUT + 1], extra, 2)
    moved = not torch.equal(means, model.gauss["means"].detach())
    return float(model.strategy.count.sum()) - count, float(model.strategy.grad_accum.sum()) - grad, moved


@needs_rasterizer
@pytest.mark.parametrize("from_extra", [True, False])
def test_an_additional_view_counts_for_densification_only_when_asked(from_extra):
    d_count, d_grad, moved = _stats_after_an_extra_view(from_extra)
    assert moved  # the additional view trains the Gaussians either way
    if from_extra:
        assert d_count > 0 and d_grad > 0
    else:
        assert d_count == 0 and d_grad == 0
