"""``background_from_extra_views``: whether a batch of an additional view (``image_idx`` past the input
views) trains the background; input views always do, and the Gaussians learn from both."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import batch_for, make_cameras, make_train_data, needs_rasterizer, render_truth

from nerf2gs_plugin.methods.splatfacto.config import splatfacto_config

N_INPUT = 4


def _grads(from_extra: bool, idx: int) -> tuple[float, float]:
    """The background's and the Gaussians' gradient norms after one step on view ``idx``."""
    cams = make_cameras(N_INPUT + 2, 40, 24)
    images, skies = render_truth(cams)
    cfg = dataclasses.replace(splatfacto_config.pipeline.model, background_from_extra_views=from_extra)
    model = cfg.setup(train_data=make_train_data(cams[:N_INPUT]))
    model.train()
    batch = batch_for(images, skies, idx) if idx < N_INPUT else {"image": images[idx], "weight": torch.tensor(1.0), "image_idx": idx}
    out = model.get_outputs(cams[idx])
    sum(model.get_loss_dict(out, batch, model.get_metrics_dict(out, batch)).values()).backward()
    bg = sum(float(p.grad.norm()) for p in model.background.parameters() if p.grad is not None)
    return bg, float(model.gauss["features_dc"].grad.norm())


@needs_rasterizer
@pytest.mark.parametrize("from_extra", [True, False])
def test_an_additional_view_trains_the_background_only_when_asked(from_extra):
    bg, gauss = _grads(from_extra, N_INPUT + 1)
    assert gauss > 0  # the Gaussians learn from the view either way
    assert (bg > 0) == from_extra
    bg_input, _ = _grads(from_extra, 0)
    assert bg_input > 0  # an input view always trains the background
