"""``extra_view_appearance``: an additional view's render passes through a learned colour transform before
its loss (the NeRF's colour goes there, not into the Gaussians); input views and renders outside training
never do, and a checkpoint brings its transforms back."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import batch_for, make_cameras, make_train_data, needs_rasterizer, render_truth

from nerf2gs_plugin.methods.splatfacto.config import splatfacto_config

N_INPUT, N_EXTRA = 4, 2


def _model(mode: str, extra: int = N_EXTRA):
    cams = make_cameras(N_INPUT + N_EXTRA, 40, 24)
    images, skies = render_truth(cams)
    cfg = dataclasses.replace(splatfacto_config.pipeline.model, extra_view_appearance=mode)
    model = cfg.setup(train_data=make_train_data(cams[:N_INPUT]))
    model.add_extra_views(extra)
    model.train()
    return model, cams, images, skies


def _step(model, cams, images, skies, idx: int) -> dict:
    batch = batch_for(images, skies, idx) if idx < N_INPUT else {"image": images[idx], "weight": torch.tensor(1.0), "image_idx": idx}
    out = model.get_outputs(cams[idx])
    losses = model.get_loss_dict(out, batch, model.get_metrics_dict(out, batch))
    sum(losses.values()).backward()
    return losses


@needs_rasterizer
def test_off_adds_no_transform():
    model, *_ = _model("off")
    assert model.extra_appearance is None and "extra_appearance" not in model.get_param_groups()


@needs_rasterizer
@pytest.mark.parametrize("mode,count", [("per-view", N_EXTRA), ("shared", 1)])
def test_only_additional_views_train_their_transform(mode, count):
    model, cams, images, skies = _model(mode)
    assert model.extra_appearance.transforms.shape == (count, 3, 4)
    assert "extra_appearance" in model.get_param_groups()
    _step(model, cams, images, skies, 0)  # an input view: no transform, no gradient
    assert model.extra_appearance.transforms.grad is None
    losses = _step(model, cams, images, skies, N_INPUT + 1)
    grad = model.extra_appearance.transforms.grad
    assert "extra_appearance_reg" in losses
    if mode == "per-view":  # the view's own transform, not its neighbour's
        assert float(grad[1].abs().sum()) > 0 and float(grad[0].abs().sum()) == 0
    else:
        assert float(grad[0].abs().sum()) > 0


@needs_rasterizer
def test_the_transform_takes_a_colour_cast_and_renders_ignore_it():
    model, cams, images, skies = _model("shared")
    idx = N_INPUT
    with torch.no_grad():
        model.extra_appearance.transforms[0, :, :3] *= 0.5
    plain = model.render_camera(cams[idx])["rgb"]
    batch = {"image": plain * 0.5, "weight": torch.tensor(1.0), "image_idx": idx}
    out = model.get_outputs(cams[idx])
    loss = model.get_loss_dict(out, batch, model.get_metrics_dict(out, batch))["main_loss"]
    assert float(loss) < 1e-3  # the halved render matches the halved image: the transform explains it
    model.eval()
    assert torch.allclose(model.render_camera(cams[idx])["rgb"], plain)  # no transform outside training


@needs_rasterizer
def test_a_checkpoint_brings_its_transforms_back():
    model, *_ = _model("per-view")
    with torch.no_grad():
        model.extra_appearance.transforms[1, 0, 3] = 0.25
    state = model.state_dict()
    fresh, *_ = _model("off", extra=0)  # e.g. ns2gs-eval: no additional views
    fresh.load_model_state(state)
    assert float(fresh.extra_appearance.transforms[1, 0, 3]) == pytest.approx(0.25)


class _TwiceTheViews:
    """A data-manager wrapper that adds as many (extra) views as the input views: all the pipeline asks of it."""

    def __init__(self, inner) -> None:
        self.inner = inner

    @property
    def all_train_cameras(self):
        from nerf2gs_plugin.cameras import Cameras

        return Cameras.cat([self.inner.train_images.cameras] * 2)

    def initial_points(self):
        return None


def test_the_pipeline_gives_the_model_one_transform_per_additional_view(tiny_scene):
    from nerf2gs_plugin.engine.pipeline import Pipeline

    pipeline_cfg = dataclasses.replace(splatfacto_config.pipeline, model=dataclasses.replace(
        splatfacto_config.pipeline.model, extra_view_appearance="per-view"))
    pipeline = Pipeline(pipeline_cfg, tiny_scene, "cpu", wrap_datamanager=_TwiceTheViews)
    assert pipeline.model.extra_appearance.transforms.shape[0] == pipeline.model.num_train_images > 0
