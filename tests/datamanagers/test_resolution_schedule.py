"""Coarse to fine (``--pipeline.datamanager.num-downscales`` / ``resolution-schedule``): a training view and
its batch at 1/d, the intrinsics matching the block-averaged pixels, and the factor halving on schedule."""

from __future__ import annotations

import dataclasses

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.datamanagers.resolution import downscale_at, downscaled


def test_the_factor_halves_every_schedule_steps():
    assert [downscale_at(s, 2, 100) for s in (0, 99, 100, 199, 200, 5000)] == [4, 4, 2, 2, 1, 1]
    assert downscale_at(0, 0, 100) == downscale_at(0, 2, 0) == 1  # off


def _camera(w: int, h: int) -> Cameras:
    c2w = torch.eye(4)[None, :3]
    return Cameras(camera_to_worlds=c2w, fx=torch.tensor([50.0]), fy=torch.tensor([52.0]), cx=torch.tensor([w / 2 + 1.3]),
                   cy=torch.tensor([h / 2 - 0.7]), width=torch.tensor([w]), height=torch.tensor([h]))


def test_a_view_at_a_quarter_keeps_its_pixels_where_the_camera_puts_them():
    """A point that lands in pixel (u, v) of the full view lands in the small view's pixel (u // 4, v // 4), whose
    colour is the mean of that 4 x 4 block; a mask keeps the blocks mostly set; scalars pass through."""
    w, h, d = 42, 26, 4  # sizes that 4 does not divide: the last rows and columns are dropped
    cam = _camera(w, h)
    image = torch.rand(h, w, 3)
    mask = torch.zeros(h, w, 1, dtype=torch.bool)
    mask[4:8, 8:11] = True  # 3 of a 4-wide block's columns set: kept; the block beside it (1 of 4) is not
    small, batch = downscaled(cam, {"image": image, "sky_mask": mask, "image_idx": 3, "weight": torch.tensor(0.5)}, d)
    assert (int(small.width[0]), int(small.height[0])) == (w // d, h // d) and batch["image"].shape == (h // d, w // d, 3)
    assert batch["image_idx"] == 3 and float(batch["weight"]) == 0.5 and batch["sky_mask"].dtype == torch.bool
    assert torch.allclose(batch["image"][2, 5], image[8:12, 20:24].mean((0, 1)))
    assert batch["sky_mask"][1, 2] and not batch["sky_mask"][1, 1] and int(batch["sky_mask"].sum()) == 1
    point = torch.tensor([[0.37, -0.21, -2.0]])  # in front of the camera (OpenGL: looks along -z)
    uv, _ = cam.project(point, 0)
    uv_small, _ = small.project(point, 0)
    assert torch.allclose(uv_small, uv / d, atol=1e-5)
    assert downscaled(cam, {"image": image}, 1)[1]["image"] is image  # factor 1: as it is


def test_splatfacto_trains_coarse_to_fine(tiny_scene, tmp_path):
    """The first steps render and learn at a quarter, then a half, then the full size (Splatfacto's depth loss
    reads its points' pixels at the step's size); the schedule rescales with the run's length."""
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    spec = get_method("splatfacto")
    cfg = spec.with_steps(9)
    dm = dataclasses.replace(cfg.pipeline.datamanager, num_downscales=2, resolution_schedule=3)
    cfg = dataclasses.replace(cfg, data=tiny_scene, run_dir=tmp_path / "run", progress=False, pipeline=dataclasses.replace(cfg.pipeline, datamanager=dm))
    trainer = Trainer(cfg)
    trainer.setup()
    manager = trainer.pipeline.datamanager
    sizes, losses = [], []
    real_next, real_loss = manager.next_train, trainer.pipeline.model.get_loss_dict

    def next_train(step):
        camera, batch = real_next(step)
        sizes.append((int(camera.height[0]), int(batch["image"].shape[0])))
        return camera, batch

    def get_loss_dict(outputs, batch, metrics):
        out = real_loss(outputs, batch, metrics)
        losses.append(out)
        return out

    manager.next_train, trainer.pipeline.model.get_loss_dict = next_train, get_loss_dict
    trainer.train()
    full = int(manager.train_images.cameras.height[0])
    assert [s[0] for s in sizes] == [full // 4] * 3 + [full // 2] * 3 + [full] * 3 and all(a == b for a, b in sizes)
    assert all(torch.isfinite(v).all() for out in losses for v in out.values())
    assert "depth_loss" in losses[0]  # the sparse points' depth at a quarter
    base = spec.config.pipeline.datamanager.resolution_schedule
    assert spec.with_steps(2 * spec.config.max_num_iterations).pipeline.datamanager.resolution_schedule == 2 * base
