"""StreetNeRF's camera optimizer (``--pipeline.model.camera-optimizer.mode SO3xR3``): off by default
and then absent, training rays (image and sparse-point) moved by their camera's correction, eval
rays never, an optimizer group of its own that checkpoints and resumes, a clear error without it.
The recovery of a perturbed camera is in test_streetnerf.py (it reuses that module's trained field)."""

import dataclasses

import pytest
import torch

from nerf2gs_plugin.data import parse_dataset
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.fields.camera_optimizer import CameraOptimizerConfig
from nerf2gs_plugin.methods.streetnerf.config import streetnerf_config
from nerf2gs_plugin.utils.lie import correct_rays
from test_streetnerf import make_trainer, small_model_config

ON = CameraOptimizerConfig(mode="SO3xR3")
BASE_GROUPS = {"fields", "proposal_networks", "sky_appearance"}


def _model(tiny_scene, **kw):
    torch.manual_seed(0)
    return small_model_config(**kw).setup(train_data=parse_dataset(tiny_scene, "train"))


def _rays(model, tiny_scene, cams=(0, 1, 5)):
    cameras = parse_dataset(tiny_scene, "train").cameras
    idx = torch.tensor(cams).repeat_interleave(4)
    uv = torch.stack([torch.arange(len(idx)) % 32, torch.arange(len(idx)) % 24], -1)
    return cameras.generate_rays(idx, uv)


def test_off_by_default_and_then_absent(tiny_scene):
    assert streetnerf_config.pipeline.model.camera_optimizer.mode == "off"
    assert "camera_opt" in streetnerf_config.optimizers  # ready for the flag, unused while off
    model = _model(tiny_scene)
    assert model.camera_optimizer is None and set(model.get_param_groups()) == BASE_GROUPS
    assert not any("camera_optimizer" in k for k in model.state_dict())
    assert model.refined_train_cameras(parse_dataset(tiny_scene, "train").cameras) is None


def test_zero_corrections_render_as_off_and_add_the_group_and_penalty(tiny_scene):
    off, on = _model(tiny_scene), _model(tiny_scene, camera_optimizer=ON)
    assert set(on.get_param_groups()) == BASE_GROUPS | {"camera_opt"}
    assert on.get_param_groups()["camera_opt"] == [on.camera_optimizer.pose_adjustment]
    rays = _rays(off, tiny_scene)
    outs = []
    for m in (off, on):
        m.train()
        torch.manual_seed(3)
        outs.append(m.get_outputs(rays))
    assert torch.equal(outs[0]["rgb"], outs[1]["rgb"])
    batch = {"rgb": torch.rand(len(rays), 3), "weight": torch.ones(len(rays), 1)}
    torch.manual_seed(4)
    assert "camera_opt_reg" not in off.get_loss_dict(outs[0], batch, {})
    torch.manual_seed(4)
    assert float(on.get_loss_dict(outs[1], batch, {})["camera_opt_reg"].detach()) == 0.0


def test_training_image_and_point_rays_move_eval_rays_do_not(tiny_scene):
    model = _model(tiny_scene, camera_optimizer=ON)
    t = torch.tensor([0.05, -0.02, 0.03])
    with torch.no_grad():
        model.camera_optimizer.pose_adjustment[1, :3] = t
        model.camera_optimizer.pose_adjustment[1, 3:] = torch.tensor([0.0, 0.0, 0.02])
    rays = _rays(model, tiny_scene)
    moved = rays.camera_indices == 1
    model.train()
    out = model.get_outputs(rays)
    torch.testing.assert_close(out["origins"][moved], rays.origins[moved] + t)
    assert torch.equal(out["origins"][~moved], rays.origins[~moved]) and not torch.equal(out["directions"][moved], rays.directions[moved])
    model.eval()
    assert torch.equal(model.get_outputs(rays)["origins"], rays.origins)
    # the sparse-point rays of camera 1 move with its image (the same correction), the others stay
    seen = []
    render = model._render_rays
    model._render_rays = lambda r, idx, *a, **k: seen.append(r) or render(r, idx, *a, **k)
    model.train()
    torch.manual_seed(7)
    model._point_depth_loss()
    torch.manual_seed(7)
    n = model.pt_t_star.shape[0]
    idx = torch.randint(0, n, (min(model.config.point_rays_per_batch, n),))
    cams = model.pt_cameras[idx]
    assert bool((cams == 1).any()) and bool((cams != 1).any())
    o, d = correct_rays(model.pt_origins[idx], model.pt_directions[idx], model.camera_optimizer.corrections(cams))
    torch.testing.assert_close(seen[0].origins, o)
    torch.testing.assert_close(seen[0].directions, d)
    torch.testing.assert_close(o[cams == 1], model.pt_origins[idx][cams == 1] + t)
    assert torch.equal(o[cams != 1], model.pt_origins[idx][cams != 1])


def test_refined_train_cameras_are_the_corrected_training_rays(tiny_scene):
    model = _model(tiny_scene, camera_optimizer=ON)
    with torch.no_grad():
        model.camera_optimizer.pose_adjustment.copy_(torch.randn(8, 6, generator=torch.Generator().manual_seed(0)) * 0.02)
    cams = parse_dataset(tiny_scene, "train").cameras
    refined = model.refined_train_cameras(cams)
    rays = _rays(model, tiny_scene, cams=(2, 6))
    model.train()
    out = model.get_outputs(rays)
    again = refined.generate_rays(rays.camera_indices, torch.stack([torch.arange(len(rays)) % 32, torch.arange(len(rays)) % 24], -1))
    torch.testing.assert_close(out["origins"], again.origins)
    torch.testing.assert_close(out["directions"], again.directions, atol=1e-6, rtol=0)
    with pytest.raises(ValueError, match="8 training images"):
        model.refined_train_cameras(cams[torch.arange(3)])


def test_trains_checkpoints_and_resumes_the_corrections(tiny_scene, tmp_path):
    tr = make_trainer(tiny_scene, tmp_path / "a", steps=6, camera_optimizer=ON)
    assert "camera_opt" in tr.optimizers
    run = tr.train()
    adj = tr.pipeline.model.camera_optimizer.pose_adjustment.detach().clone()
    assert float(adj.abs().max()) > 0  # the colour loss reached the corrections
    assert "camera_opt_rotation_deg_mean" in tr.history.records()[-1]
    state = tr.optimizers["camera_opt"].state_dict()
    cfg = dataclasses.replace(tr.config, max_num_iterations=8, load_checkpoint=run, timestamp="resumed")
    back = Trainer(cfg)
    back.setup()
    assert back.step == 6
    assert torch.equal(back.pipeline.model.camera_optimizer.pose_adjustment.detach(), adj)
    again = back.optimizers["camera_opt"].state_dict()["state"][0]
    torch.testing.assert_close(again["exp_avg"], state["state"][0]["exp_avg"])
    back.train()
    assert not torch.equal(back.pipeline.model.camera_optimizer.pose_adjustment.detach(), adj)


def test_missing_optimizer_group_is_a_clear_error(tiny_scene, tmp_path):
    cfg = dataclasses.replace(streetnerf_config, data=tiny_scene, output_dir=tmp_path, progress=False,
                              optimizers={k: v for k, v in streetnerf_config.optimizers.items() if k != "camera_opt"},
                              pipeline=dataclasses.replace(streetnerf_config.pipeline, model=small_model_config(camera_optimizer=ON)))
    tr = Trainer(cfg)
    with pytest.raises(ConfigError, match=r"no optimizer config for parameter group\(s\) \['camera_opt'\]"):
        tr.setup()
