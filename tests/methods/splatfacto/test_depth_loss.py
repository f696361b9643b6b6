"""Splatfacto's sparse-point depth loss (``depth_loss_weight``): the targets are the points' camera-axis
depths at their pixels, a floater in front of the surfaces raises the loss and its gradient fades the
floater, and training with it still learns. Off (0) by default: no targets, no term."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from splat_tiny_scene import batch_for, make_cameras, make_train_data, needs_rasterizer, psnr, render_truth, train

from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers, splatfacto_config


def _cfg(weight: float):
    return dataclasses.replace(splatfacto_config.pipeline.model, depth_loss_weight=weight)


@pytest.fixture(scope="module")
def scene():
    cams = make_cameras(6, 40, 24)
    imgs, skies = render_truth(cams)
    return cams, imgs, skies


def test_targets_are_the_points_camera_depths(scene):
    cams, _, _ = scene
    data = make_train_data(cams)
    model = _cfg(0.1).setup(train_data=data)
    v, u, z = model._depth_targets[2]
    assert len(z) > 50
    # every target is a sparse point's depth along the camera axis, seen at that pixel
    uv, depth = cams.project(data.points3D_xyz.float(), 2)
    inside = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 40) & (uv[:, 1] >= 0) & (uv[:, 1] < 24)
    cand: dict = {}
    for (a, b), d in zip(uv[inside].floor().long().tolist(), depth[inside].tolist()):
        cand.setdefault((a, b), []).append(d)
    # the target is taken along the pixel centre's ray: within the pixel's depth spread of some point there
    assert all(min(abs(d - float(zz)) for d in cand[(int(uu), int(vv))]) < 0.02 * float(zz) for uu, vv, zz in zip(u, v, z))
    assert _cfg(0.0).setup(train_data=data)._depth_targets is None  # off: nothing built


@needs_rasterizer
def test_a_floater_in_front_raises_the_loss_and_its_gradient_fades_it(scene):
    cams, imgs, skies = scene
    model = _cfg(0.1).setup(train_data=make_train_data(cams))
    model.train()
    out = model.get_outputs(cams[2])
    clean = float(model.get_loss_dict(out, batch_for(imgs, skies, 2), {})["depth_loss"])
    g = model.gauss
    c2w = cams.camera_to_worlds[2]
    with torch.no_grad():  # one large opaque Gaussian 0.1 in front of camera 2, covering its view
        for name in g:
            extra = g[name][:1].clone()
            if name == "means":
                extra = (c2w[:, 3] - 0.1 * c2w[:, 2])[None]
            elif name == "scales":
                extra = torch.full((1, 3), float(torch.log(torch.tensor(0.08))))
            elif name == "opacities":
                extra = torch.full((1,), 3.0)
            g[name] = torch.nn.Parameter(torch.cat([extra, g[name].data]))
    out = model.get_outputs(cams[2])
    loss = model.get_loss_dict(out, batch_for(imgs, skies, 2), {})["depth_loss"]
    assert float(loss) > clean + 0.02
    loss.backward()
    assert float(g["opacities"].grad[0]) > 0  # descending the loss lowers the floater's opacity


@needs_rasterizer
def test_training_with_the_depth_loss_learns(scene):
    cams, imgs, skies = scene
    torch.manual_seed(0)
    model = _cfg(0.1).setup(train_data=make_train_data(cams))
    p0 = psnr(model, cams, imgs)
    train(model, gaussian_optimizers(40), cams, imgs, skies, 40)
    assert psnr(model, cams, imgs) > p0 + 1.0
