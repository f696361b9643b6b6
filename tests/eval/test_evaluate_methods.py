"""ns2gs-eval on a tiny run of every built-in method: the same JSON schema for NeRF and splats."""

import dataclasses
import json
import math

import numpy as np
import pytest

from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.eval.evaluate import evaluate_run
from nerf2gs_plugin.registry import get_method


@pytest.mark.parametrize("method", ["splatfacto", "scaffold-gs", "2dgs", "streetnerf"])
def test_eval_schema_on_each_method(method, tiny_scene, tmp_path):
    cfg = get_method(method).config
    if method == "streetnerf":  # a few small ray batches: this test is about eval, not training
        cfg = apply_plain(cfg, {"pipeline": {"datamanager": {"rays_per_batch": 128}}})
    cfg = dataclasses.replace(cfg, data=tiny_scene, output_dir=tmp_path, max_num_iterations=3,
                              steps_per_save=3, steps_per_eval_image=0, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    run = load_run(trainer.train())
    res = evaluate_run(run, ["bev_1"], max_images=1, fps_repeats=1, render_dir=tmp_path / "grids")
    json.dumps(res, allow_nan=False)
    assert res["method_name"] == method and list(res["results"]) == ["bev_1"]
    r = res["results"]["bev_1"]
    assert r["num_images"] == 1 and 3 < r["psnr"] < 60 and -1 <= r["ssim"] <= 1 and r["psnr_std"] == 0.0
    assert res["lpips_available"] and 0 < r["lpips"] < 1.5  # LPIPS is required in the test environment
    cam, batch = next(iter(run.pipeline.datamanager.eval_images("bev_1")))  # PSNR checked independently
    pred = run.model.render_camera(cam)["rgb"].clamp(0, 1).detach().double().numpy()
    direct = 10 * np.log10(1.0 / np.mean((pred - batch["image"].double().numpy()) ** 2))
    assert r["psnr"] == pytest.approx(direct, abs=1e-3)
    assert res["fps"] > 0 and math.isfinite(res["fps"])
    assert res["size"]["primitives"] > 0 and res["size"]["parameters"] > 0 and res["size"]["checkpoint_megabytes"] > 0
    assert res["step"] == 2 and res["train_seconds"] > 0
    assert (tmp_path / "grids" / "bev_1.png").is_file()
