"""``ns2gs-bench real-photos`` output: the held-out-photo table and the Markdown (the training path is
the shared bench runner, exercised by the other benches' tests)."""

from nerf2gs_bench.real_photos import LABELS, RealPhotosOptions, held_out_table, results_md, run_overrides


def _doc():
    res = {lab: {"results": {"test": {"psnr": p, "ssim": 0.5, "lpips": 0.4, "num_images": 4}}, "train_seconds": 100.0}
           for lab, p in zip(LABELS, (19.8, 22.5, 22.1))}
    res[LABELS[2]] = {"failed": True, "error": "a|b"}
    opts = {"images": "photos", "provenance": "from somewhere", "camera_height": 1.6, "fov_deg": 58.2, "metres_per_unit": None,
            "matching": "auto", "reference_steps": 200, "downscale": 4.0, "streetnerf_steps": 600, "splatfacto_steps": 1000,
            "delta_h": 3.0, "theta_pitch": 30.0, "holdout_every": 8, "every_n": 2}
    return {"dataset": "castle", "options": opts, "results": res, "stage_seconds": {"process": 1.0},
            "process": {"registered": 30, "frames": 30, "points": 100, "matching": "exhaustive", "metres_per_unit": 1.0,
                        "scale_source": "override", "stage_seconds": {"features": 1.0}},
            "masks": {"reference_seconds": 1.0, "mask_seconds": 2.0, "coverage": {"sky": 0.1}},
            "reference_check": {"line": "the reference is 2.70 dB BELOW the baseline on 4 held-out views"}, "wall_seconds": 5.0}


def test_table_rows_and_markdown():
    t = held_out_table(_doc()["results"]).splitlines()
    assert t[0].startswith("| method | held-out photos | PSNR held-out | SSIM held-out | LPIPS held-out |")
    assert t[2] == "| StreetNeRF | 4 | 19.80 | 0.500 | 0.400 | 100 |"
    assert t[4].startswith("| splatfacto + NeRF views | failed: a/b |")
    md = results_md(_doc())
    assert "- StreetNeRF within 0.5 dB of Splatfacto: -2.70 dB (not met)." in md
    assert "from somewhere" in md and "2.70 dB BELOW" in md and "--fov-deg 58.2" in md and "every 8th photo" in md
    assert "per held-out photo" not in md  # results made before the per-image PSNR: no line


def test_per_photo_psnr_lines():
    doc = _doc()
    doc["results"][LABELS[1]]["results"]["test"]["psnr_per_image"] = [25.66, 9.62, 26.28, 25.82]
    md = results_md(doc)
    assert "PSNR per held-out photo (in name order):" in md and "- splatfacto: 25.66 / 9.62 / 26.28 / 25.82" in md
    assert "- StreetNeRF:" not in md  # its result has no per-image list


def test_overrides_hold_out_the_same_photos_in_every_run():
    opts = RealPhotosOptions(images="x", holdout_every=6, downscale=2.0)
    for method, steps in (("streetnerf", 100), ("splatfacto", 200)):
        ov = run_overrides(opts, method, steps)
        parser = ov["pipeline"]["datamanager"]["dataparser"]
        assert parser["holdout_every"] == 6 and parser["downscale"] == 2.0
        assert ov["max_num_iterations"] == steps and ov["steps_per_eval_image"] == 0


def test_renders_from_above_on_a_tiny_scene(tiny_scene, tmp_path):
    """Two tiny runs: a figure with the held-out photo, each run's render of it and from above."""
    import dataclasses

    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_bench.real_photos import renders_from_above
    from nerf2gs_plugin.registry import get_method

    runs = []
    for name in ("a", "b"):
        cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path / name, max_num_iterations=2,
                                  steps_per_eval_image=0, progress=False, timestamp="run")
        t = Trainer(cfg)
        t.setup()
        runs.append(t.train())
    out = renders_from_above(runs, ["a", "b"], tmp_path / "fig.png", RealPhotosOptions(images="x", delta_h=2.0), views=2, split="street")
    from PIL import Image

    w, h = Image.open(out).size
    assert h > w  # 4 rows (2 held-out views: street, above) of 3 columns
