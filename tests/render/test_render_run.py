"""ns2gs-render on a tiny trained run: MP4 and PNG frames, compare side by side with labels, the
measures from above, and bad input as one clear line."""

import dataclasses
import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
import torch

from nerf2gs_plugin.render.frames import LABEL_BAND, put_label, side_by_side
from nerf2gs_plugin.render.measures import PathMeasures, floater_mask, hole_mask


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    from tiny_scene import train_tiny_run

    return train_tiny_run(tiny_scene, tmp_path_factory.mktemp("runs"))


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.render", *map(str, args)], capture_output=True, text=True, timeout=120)


def test_video_and_png_frames_of_a_run(tiny_run, tmp_path):
    from nerf2gs_plugin.cli.render import RenderArgs, render
    from nerf2gs_plugin.render.paths import PathOptions
    from nerf2gs_plugin.render.render_path import OutputOptions

    mp4 = render(RenderArgs(tiny_run, path="orbit", output=tmp_path / "orbit.mp4", device="cpu", path_options=PathOptions(frames=6)),
                 compare=False)
    cap = cv2.VideoCapture(str(mp4))
    n, ok, frame = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), *cap.read()
    assert ok and n == 6 and frame.shape == (24, 32, 3)  # the tiny scene's 32x24 cameras
    assert not list(tmp_path.glob(".*tmp*"))  # the temporary file was renamed into place
    out = OutputOptions(output_format="images", rendered_output_names=("rgb", "depth", "accumulation"), downscale=0.5)
    frames = render(RenderArgs(tiny_run, path="interpolate", output=tmp_path / "frames", device="cpu", out=out), compare=False)
    pngs = sorted(frames.glob("*.png"))
    assert len(pngs) == 7 * 10 + 1  # 8 training cameras, 10 steps per transition
    img = cv2.imread(str(pngs[0]))
    assert img.shape == (48, 3 * 64, 3)  # downscale 0.5 doubles the size; rgb | depth | accumulation
    assert np.abs(img[:, :64].astype(int) - img[:, 64:128]).mean() > 5  # depth is colour-mapped, not the rgb again


def test_compare_side_by_side_same_cameras_and_labels(tiny_run, tmp_path):
    p = _cli("compare", tiny_run, tiny_run, "--path", "birds-eye", "--labels", "alone", "with NeRF views",
             "--output-format", "images", "--output", tmp_path / "cmp", "--measure", "--height", "3", "--device", "cpu")
    assert p.returncode == 0, p.stderr[-2000:]
    pngs = sorted((tmp_path / "cmp").glob("*.png"))
    assert len(pngs) == 8  # one fly-over view per training camera
    img = cv2.imread(str(pngs[0]))
    assert img.shape == (24 + LABEL_BAND, 2 * 32 + 4, 3)
    left, right = img[LABEL_BAND:, :32], img[LABEL_BAND:, 36:]
    assert np.array_equal(left, right)  # the same run on the same cameras
    assert img[:LABEL_BAND].max() > 200 and img[:LABEL_BAND, :32].sum() != img[:LABEL_BAND, 36:].sum()  # two labels
    doc = json.loads((tmp_path / "cmp.measures.json").read_text())
    assert [d["label"] for d in doc] == ["alone", "with NeRF views"] and 0 <= doc[0]["bev_hole_fraction"] <= 1
    assert "alone: holes" in p.stdout and "near-camera floaters" in p.stdout


def test_labels_are_burnt_in():
    tiles = [np.zeros((40, 120, 3), np.uint8), np.full((30, 100, 3), 90, np.uint8)]
    out = side_by_side(tiles, ["baseline", "+ NeRF views"], gap=4)
    assert out.shape == (40 + LABEL_BAND, 120 + 4 + 100, 3)
    assert put_label(tiles[0], "x")[:LABEL_BAND].max() > 200 and put_label(tiles[0], "")[:LABEL_BAND].max() == 0


def test_bad_input_is_one_line_and_nothing_written(tiny_run, tmp_path):
    p = _cli(tmp_path / "no_run", "--output", tmp_path / "x.mp4")
    assert p.returncode == 2 and p.stderr.strip() == f"error: {tmp_path / 'no_run'}: run directory or checkpoint does not exist"
    bad = tmp_path / "camera_path.json"
    bad.write_text(json.dumps({"render_height": 24, "camera_path": [{"camera_to_world": [1, 2], "fov": 50, "aspect": 1}]}))
    p = _cli(tiny_run, "--camera-path-file", bad, "--output", tmp_path / "x.mp4", "--device", "cpu")
    assert p.returncode == 2 and p.stderr.strip().splitlines() == [
        f"error: {bad}: malformed nerfstudio camera path ('camera_to_world' has 2 numbers, expected 16 (a 4x4 matrix))"]
    assert not (tmp_path / "x.mp4").exists()


def test_compare_refuses_runs_of_different_datasets(tiny_run, tmp_path):
    from nerf2gs_plugin.errors import ConfigError
    from nerf2gs_plugin.render.render_path import check_same_dataset, load_runs

    runs = load_runs([tiny_run, tiny_run])
    runs[1] = dataclasses.replace(runs[1], dataset="another")
    with pytest.raises(ConfigError, match="trained on another dataset .* must share a dataset"):
        check_same_dataset(runs, [tiny_run, tmp_path / "other"])
    check_same_dataset(runs[:1] * 2, [tiny_run, tiny_run])  # one dataset: fine
    cams = runs[0].train_cameras
    runs[1] = dataclasses.replace(runs[0], train_cameras=cams.with_poses(cams.camera_to_worlds * 1.1))
    with pytest.raises(ConfigError, match="other normalised poses"):
        check_same_dataset(runs, [tiny_run, tmp_path / "other"])


def test_hole_and_floater_measures_on_synthetic_maps():
    acc = torch.ones(10, 20, 1)
    acc[:5, :4] = 0.2  # 20 of 200 pixels see through
    acc[9, 19] = 0.5  # exactly 0.5 is covered
    assert int(hole_mask(acc).sum()) == 20
    depth = torch.full((10, 20, 1), 8.0)
    depth[:5, :4] = 0.1  # near, but a hole: not a floater
    depth[8:, 10:12] = 0.5  # 4 near covered pixels
    assert int(floater_mask(depth, acc, near=1.0).sum()) == 4
    m = PathMeasures()
    m.add({"accumulation": acc, "depth": depth}, near=1.0)
    m.add({"accumulation": torch.ones(10, 20, 1), "depth": depth}, near=0.25)  # covered now: the 20 at 0.1 float, 0.5 is far enough
    r = m.result()
    assert r["bev_hole_fraction"] == pytest.approx(20 / 400) and r["floater_fraction"] == pytest.approx((4 + 20) / 400)
    assert r["frames"] == 2 and r["worst_frame_hole_fraction"] == pytest.approx(0.1)


def test_birds_eye_of_an_augmented_run_reads_its_manifest(tiny_scene, tiny_run, tmp_path):
    """A target trained with --augment-from: its birds-eye path is the views in its reference's cache
    manifest, and ns2gs-eval's measure from above uses them (``source`` names the manifest)."""
    from nerf2gs_plugin.augment.cache import cache_manifests
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.runs.model import load_run_model
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.eval.evaluate import measure_from_above
    from nerf2gs_plugin.registry import get_method
    from nerf2gs_plugin.render.scene import context_from_run_model

    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path, max_num_iterations=2,
                              steps_per_eval_image=0, progress=False, timestamp="aug", augment_from=tiny_run)
    cfg = dataclasses.replace(cfg, augment=dataclasses.replace(cfg.augment, delta_h=2.0, min_coverage=0.0, every_n=2))
    t = Trainer(cfg)
    t.setup()
    run = t.train()
    manifest = cache_manifests(tiny_run)[0]
    ctx = context_from_run_model(load_run_model(run))
    assert ctx.augment_source == str(manifest.path) and len(ctx.augment_views) == manifest.num_extra == 4
    assert torch.allclose(ctx.augment_views.camera_to_worlds, manifest.extra_poses())
    above = measure_from_above(load_run(run), views=3)
    assert above["source"] == str(manifest.path) and above["frames"] == 3


def test_writer_replaces_only_when_done(tmp_path):
    from nerf2gs_plugin.render.writer import FrameWriter

    frame = np.full((8, 10, 3), 100, np.uint8)
    for n in (3, 2):
        with FrameWriter(tmp_path / "frames", "images") as w:
            for _ in range(n):
                w.write(frame)
    assert len(list((tmp_path / "frames").glob("*.png"))) == 2  # the second render replaced the first
    with pytest.raises(RuntimeError):
        with FrameWriter(tmp_path / "frames", "images") as w:
            w.write(frame)
            raise RuntimeError("interrupted")
    assert len(list((tmp_path / "frames").glob("*.png"))) == 2 and sorted(p.name for p in tmp_path.iterdir()) == ["frames"]
    with FrameWriter(tmp_path / "v.mp4", "video", fps=5) as w:
        for _ in range(4):
            w.write(frame)
    assert int(cv2.VideoCapture(str(tmp_path / "v.mp4")).get(cv2.CAP_PROP_FRAME_COUNT)) == 4
