"""Sparse-point depth supervision: visibility from a point z-buffer, and the loss it drives."""

import json
import shutil

import warnings

import pytest
import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data import parse_dataset
from nerf2gs_plugin.methods.point_visibility import visible_point_rays
from nerf2gs_plugin.methods.streetnerf.point_depth import line_of_sight_loss

from test_streetnerf import make_trainer, small_model_config


def _one_camera(w: int = 64, h: int = 48) -> Cameras:
    c2w = torch.eye(4)[:3].unsqueeze(0)  # at the origin, OpenGL: looking down -z
    return Cameras(c2w, fx=50.0, fy=50.0, cx=w / 2, cy=h / 2, width=w, height=h)


def test_visibility_keeps_the_nearest_point_per_block_and_gives_its_distance():
    cams = _one_camera()
    pts = torch.tensor([
        [0.0, 0.0, -5.0],     # visible
        [0.02, 0.0, -10.0],   # same pixel block, twice as far: hidden behind the first
        [2.0, 0.5, -5.0],     # visible, elsewhere in the image
        [0.0, 0.0, 5.0],      # behind the camera
        [50.0, 0.0, -5.0],    # outside the image
    ])
    pr = visible_point_rays(cams, pts, cell=8, tolerance=0.1)
    assert len(pr) == 2
    assert pr.camera_indices.tolist() == [0, 0]
    # rays through the pixel centres: t* is the distance along each ray, within half a pixel of |p|
    expected = pts[[0, 2]].norm(dim=-1)
    assert torch.allclose(pr.t_star, expected, rtol=2e-3)
    u, v = pr.coords[0].tolist()
    assert (u, v) == (32, 24)  # the principal point's pixel


def test_line_of_sight_loss_is_zero_on_target_and_bounded_elsewhere():
    t_mid = torch.tensor([[1.0, 2.0, 4.0, 8.0]])
    on = torch.tensor([[0.0, 1.0, 0.0, 0.0]])
    off = torch.tensor([[0.0, 0.0, 0.0, 1.0]])
    t_star = torch.tensor([[2.0]])
    assert float(line_of_sight_loss(on, t_mid, on.sum(-1, keepdim=True), t_star)) == 0.0
    assert float(line_of_sight_loss(off, t_mid, off.sum(-1, keepdim=True), t_star)) == 1.0  # clamped at 1
    empty = torch.zeros(1, 4)
    assert float(line_of_sight_loss(empty, t_mid, empty.sum(-1, keepdim=True), t_star)) == 1.0  # missing mass


def test_point_depth_loss_trains_down_on_a_scene_with_points(tiny_scene, tmp_path):
    """The tiny scene ships 200 sparse points on its ground plane."""
    torch.manual_seed(0)
    tr = make_trainer(tiny_scene, tmp_path / "out", ground_reg=False)
    model = tr.pipeline.model
    assert model.use_point_depth and len(model.pt_t_star) > 100
    assert "pt_t_star" not in model.state_dict()  # rebuilt from the data, never checkpointed

    def point_loss() -> float:
        torch.manual_seed(1)
        with torch.no_grad():
            return float(model._point_depth_loss())

    before = point_loss()
    for step in range(150):
        tr.train_step(step)
    after = point_loss()
    assert after < 0.5 * before, (before, after)


def test_point_depth_off_without_points(tiny_scene, tmp_path):
    root = tmp_path / "no_points"
    shutil.copytree(tiny_scene, root)
    meta = json.loads((root / "transforms.json").read_text())
    del meta["ply_file_path"]
    (root / "transforms.json").write_text(json.dumps(meta))
    data = parse_dataset(root, "train")
    with pytest.warns(UserWarning, match="no sparse points"):
        model = small_model_config().setup(train_data=data)
    assert not model.use_point_depth
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # switched off on purpose: no warning
        assert not small_model_config(point_depth=False).setup(train_data=data).use_point_depth


def test_point_depth_loss_skips_the_colour_without_changing_loss_or_gradients(tiny_scene, tmp_path):
    """The point rays render no colour (no loss reads it): the loss and every gradient are bit-for-bit those of
    a render with colour, and no colour-only parameter gets a gradient either way."""
    torch.manual_seed(0)
    tr = make_trainer(tiny_scene, tmp_path / "out")
    model = tr.pipeline.model
    for step in range(5):  # past the first steps' zero-ish fields
        tr.train_step(step)
    render = model._render_rays
    colour_calls = []

    def run(with_colour: bool) -> tuple[torch.Tensor, dict]:
        model._render_rays = lambda r, idx, *a, colour=True: colour_calls.append(colour) or render(r, idx, *a, colour=colour or with_colour)
        model.zero_grad(set_to_none=True)
        torch.manual_seed(3)
        loss = model._point_depth_loss()
        loss.backward()
        return loss.detach(), {k: p.grad.clone() for k, p in model.named_parameters() if p.grad is not None}

    try:
        loss_c, grads_c = run(True)
        loss_n, grads_n = run(False)
    finally:
        model._render_rays = render
    assert colour_calls == [False, False]  # the loss asks for no colour
    assert torch.equal(loss_c, loss_n) and grads_c.keys() == grads_n.keys()
    assert all(torch.equal(grads_c[k], grads_n[k]) for k in grads_c)
    assert any(k.startswith("field.encoding") for k in grads_n) and any(k.startswith("field.density_mlp") for k in grads_n)
    assert not any(k.startswith(("field.color_mlp", "sky_model", "appearance")) for k in grads_n)
