"""A training batch without depth targets (an additional view from above) renders no depth channel: the
step's losses and every gradient are the same, bit for bit, as with the channel; a view with targets keeps it."""

from __future__ import annotations

import dataclasses

import torch

from splat_tiny_scene import batch_for, make_cameras, make_train_data, needs_rasterizer, render_truth

from nerf2gs_plugin.methods.splatfacto.config import splatfacto_config

N_INPUT = 4


def _step(model, outputs: dict, batch: dict) -> tuple[dict, dict]:
    """Losses and parameter gradients of one step from ``outputs``."""
    model.zero_grad(set_to_none=True)
    losses = model.get_loss_dict(outputs, batch, model.get_metrics_dict(outputs, batch))
    sum(losses.values()).backward()
    grads = {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
    return {k: v.detach().clone() for k, v in losses.items()}, grads


@needs_rasterizer
def test_a_view_without_depth_targets_trains_the_same_without_the_depth_channel():
    cams = make_cameras(N_INPUT + 2, 40, 24)
    images, skies = render_truth(cams)
    cfg = dataclasses.replace(splatfacto_config.pipeline.model, depth_loss_weight=0.1)
    torch.manual_seed(0)
    model = cfg.setup(train_data=make_train_data(cams[:N_INPUT]))
    model.train()
    extra = N_INPUT + 1
    batch = {"image": images[extra], "weight": torch.tensor(1.0), "image_idx": extra}
    lean = model.get_train_outputs(cams[extra], batch)
    assert "depth" not in lean  # no loss of this batch reads it
    full = model.get_outputs(cams[extra])
    for key in ("rgb", "accumulation"):
        assert torch.equal(lean[key], full[key])
    lean_losses, lean_grads = _step(model, lean, batch)
    full_losses, full_grads = _step(model, full, batch)
    assert lean_losses.keys() == full_losses.keys() and "depth_loss" not in lean_losses
    assert all(torch.equal(lean_losses[k], full_losses[k]) for k in lean_losses)
    assert lean_grads.keys() == full_grads.keys() and "gauss.means" in lean_grads
    assert all(torch.equal(lean_grads[k], full_grads[k]) for k in lean_grads)

    # an input view with targets renders its depth and trains its depth loss
    batch0 = batch_for(images, skies, 0)
    out0 = model.get_train_outputs(cams[0], batch0)
    assert "depth" in out0
    assert "depth_loss" in _step(model, out0, batch0)[0]
