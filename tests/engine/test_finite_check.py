"""The finite check before a save renders the first training view at most ``FINITE_CHECK_SIDE`` pixels on its
longer side: a non-finite render still refuses the save, and the check leaves the random state (so the
training after it) as it was."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from nerf2gs_plugin.engine import trainer as trainer_module
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.errors import TrainingDiverged
from nerf2gs_plugin.registry import get_method


def _trainer(data, out) -> Trainer:
    cfg = dataclasses.replace(get_method("voxel-grid").config, data=data, output_dir=out, max_num_iterations=6,
                              steps_per_eval_image=0, steps_per_save=3, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    trainer._write_run_files()
    return trainer


def test_the_check_renders_a_small_view_and_still_refuses_a_nonfinite_one(tiny_scene, tmp_path, monkeypatch):
    trainer = _trainer(tiny_scene, tmp_path)
    model = trainer.pipeline.model
    full = trainer.pipeline.datamanager.train_images.cameras[0]
    assert max(int(full.width[0]), int(full.height[0])) > 8
    monkeypatch.setattr(trainer_module, "FINITE_CHECK_SIDE", 8)
    seen, render = [], model.render_camera

    def spy(camera):
        seen.append((int(camera.width[0]), int(camera.height[0])))
        return render(camera)

    monkeypatch.setattr(model, "render_camera", spy)
    rng = torch.get_rng_state()
    trainer.check_finite_state(0)
    assert seen and max(seen[-1]) <= 8
    assert torch.equal(rng, torch.get_rng_state())

    def nan_render(camera):
        out = render(camera)
        return {**out, "rgb": out["rgb"] * float("nan")}

    monkeypatch.setattr(model, "render_camera", nan_render)
    with pytest.raises(TrainingDiverged, match="finite parameters render non-finite rgb"):
        trainer.save_checkpoint(2)
