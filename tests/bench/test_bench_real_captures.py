"""``ns2gs-bench real-captures`` on a tiny synthetic stand-in capture: the hole measure, the missing-frames
line, the bonnet crop and the keys of the results (the SfM and training stages are the real-photos bench's,
replaced here by two tiny runs)."""

import json

import numpy as np
import pytest
import torch

from nerf2gs_bench import real_captures as rc
from nerf2gs_plugin.errors import DataError


def test_hole_fraction_counts_pixels_below_half_accumulation():
    a = torch.ones(4, 5, 1)
    a[0, :2] = 0.49  # 2 holes
    b = torch.zeros(2, 5)  # 10 holes, no channel axis
    b[0, 0] = 0.5  # exactly 0.5 is covered
    assert rc.hole_fraction([a, b]) == pytest.approx(11 / 30)
    assert rc.hole_fraction([]) == 0.0


def test_missing_frames_name_the_capture_and_the_source(tmp_path):
    cap = rc.CAPTURES[0]
    with pytest.raises(DataError) as e:
        rc.capture_frames(cap, tmp_path)
    msg = str(e.value)
    assert f"capture '{cap.name}'" in msg and cap.fetch in msg and str(tmp_path / cap.folder) in msg


def test_missing_ground_truth_is_named_apart_from_the_frames(tmp_path):
    cap = next(c for c in rc.CAPTURES if c.truth)
    _frames(tmp_path / cap.folder, n=4)
    with pytest.raises(DataError, match="ground-truth cameras missing") as e:
        rc.capture_frames(cap, tmp_path)
    assert cap.fetch in str(e.value) and cap.truth in str(e.value)
    (tmp_path / cap.truth).mkdir(parents=True)
    assert len(rc.capture_frames(cap, tmp_path)) == 4


def _frames(folder, n=10, h=20, w=40):
    import cv2

    folder.mkdir(parents=True)
    for i in range(n):
        cv2.imwrite(str(folder / f"{i:04d}.png"), np.full((h, w, 3), 10 * i, np.uint8))


def test_capture_summary_takes_static_psnr_from_the_eval_results():
    """The static PSNR and its delta come from ns2gs-eval's ``static_psnr`` of the held-out split; a run
    whose held-out frames have no moving-object masks (no key, or null) gives null, never all-pixel PSNR."""
    def doc(static):
        res = {rc.REFERENCE: {"failed": True}}
        res.update({lab: {"results": {"test": {"psnr": p, **({"static_psnr": s} if s is not None else {})}}}
                    for lab, p, s in ((rc.TARGET, 20.0, static[0]), (rc.AUGMENTED, 19.5, static[1]))})
        return {"process": {"frames": 10, "registered": 10, "metres_per_unit": 1.0, "scale_source": "x", "stage_seconds": {}},
                "results": res, "stage_seconds": {}, "wall_seconds": 1.0}

    cap = rc.CAPTURES[0]
    c = rc.capture_summary(cap, doc((21.0, 20.75)), {})
    assert c["static_psnr"] == {rc.REFERENCE: None, rc.TARGET: 21.0, rc.AUGMENTED: 20.75}
    assert c["static_psnr_delta"] == pytest.approx(-0.25) and c["psnr_delta"] == pytest.approx(-0.5)
    assert "static pixels" in rc.target_lines([{**c, "bev_hole_fraction": {"target": None, "augmented": None}}])[2]
    c = rc.capture_summary(cap, doc((21.0, None)), {})
    assert c["static_psnr"][rc.AUGMENTED] is None and c["static_psnr_delta"] is None


def test_seeds_pool_into_mean_deltas_and_the_targets_name_them():
    """Several seeds' target pairs: the deltas are the means over the seeds that have both runs, the per-seed
    deltas are kept, and the target line reads the mean and names every seed's delta."""
    def rec(seed, alone, aug, static=None):
        return {"seed": seed, "psnr": {rc.TARGET: alone, rc.AUGMENTED: aug}, "static_psnr": static}

    pooled = rc.pool_seeds([rec(42, 20.0, 19.5, {rc.REFERENCE: 18.0, rc.TARGET: 22.0, rc.AUGMENTED: 21.5}),
                            rec(43, 20.0, 20.1, {rc.REFERENCE: None, rc.TARGET: 22.0, rc.AUGMENTED: 22.3}),
                            rec(44, 20.0, None, None)])
    assert pooled["seeds"] == [42, 43, 44] and len(pooled["per_seed"]) == 3
    assert pooled["psnr_delta"] == pytest.approx(-0.2) and pooled["psnr_delta_per_seed"][2] is None
    assert pooled["static_psnr_delta"] == pytest.approx(-0.1)
    assert pooled["static_psnr_delta_per_seed"][:2] == [pytest.approx(-0.5), pytest.approx(0.3)]
    line = rc.target_lines([{"capture": "x", **pooled, "bev_hole_fraction": {"target": None, "augmented": None}}])[2]
    assert "-0.10 dB" in line and "seeds 42, 43, 44: -0.50 / +0.30 / n/a" in line and "met" in line
    none = rc.pool_seeds([rec(42, None, 19.0), rec(43, 20.0, None)])
    assert none["psnr_delta"] is None and none["static_psnr_delta"] is None
    assert pooled["psnr_delta_validation"] is None  # no per-frame PSNR: no halves


def test_held_out_frames_split_into_validation_and_test_halves():
    """The 1st, 3rd, ... held-out frame choose, the 2nd, 4th, ... report; unlabelled frames are left out; seeds pool."""
    assert rc.split_delta([20.0, 21.0, 22.0], [21.0, 20.0, 22.5]) == (pytest.approx(0.75), pytest.approx(-1.0))
    assert rc.split_delta([20.0, None, 22.0, 21.0], [19.0, 25.0, 23.0, 21.5]) == (pytest.approx(0.0), pytest.approx(0.5))
    assert rc.split_delta([20.0], [21.0]) is None and rc.split_delta(None, [1.0]) is None and rc.split_delta([1.0, 2.0], [1.0]) is None
    recs = [{"seed": s, "psnr": {rc.TARGET: 20.0, rc.AUGMENTED: 20.0}, "static_psnr": None,
             "psnr_per_image": {rc.TARGET: [20.0, 20.0], rc.AUGMENTED: [20.0 + v, 20.0 + t]}} for s, v, t in ((42, 1.0, -1.0), (43, 0.0, -0.5))]
    pooled = rc.pool_seeds(recs)
    assert pooled["psnr_delta_validation"] == pytest.approx(0.5) and pooled["psnr_delta_test"] == pytest.approx(-0.75)
    assert pooled["psnr_delta_halves_per_seed"] == [(pytest.approx(1.0), pytest.approx(-1.0)), (pytest.approx(0.0), pytest.approx(-0.5))]
    assert pooled["static_psnr_delta_validation"] is None


def test_stage_frames_crops_the_bonnet_and_keeps_the_order(tmp_path):
    import cv2

    _frames(tmp_path / "cam")
    cap = rc.Capture("x", "cam", "nowhere", "none", "test", camera_height=1.5, first=2, last=9, crop_bottom=0.25)
    frames = rc.capture_frames(cap, tmp_path)
    assert [f.name for f in frames] == [f"{i:04d}.png" for i in range(2, 9)]
    staged = rc.stage_frames(cap, frames, tmp_path / "staged", count=3)
    assert [f.name for f in staged] == ["0002.png", "0003.png", "0004.png"]
    assert cv2.imread(str(staged[0])).shape == (15, 40, 3)
    everything = rc.stage_frames(cap, frames, tmp_path / "staged", count=None)  # a full scale in the same folder
    assert len(everything) == 7
    again = rc.stage_frames(cap, frames, tmp_path / "staged", count=3)  # then the quick one: only its frames stay
    assert sorted(p.name for p in (tmp_path / "staged").iterdir()) == [f.name for f in again] == ["0002.png", "0003.png", "0004.png"]
    assert rc.downscale_for(800, rc.SCALES["quick"]) == 2.0 and rc.downscale_for(1600, rc.SCALES["full"]) == 1.0


def test_bench_keys_and_holes_on_a_stand_in_capture(tiny_scene, tmp_path, monkeypatch):
    """The bench end to end on a synthetic stand-in: run_real_photos replaced by two tiny runs, the holes
    from above rendered from them by ns2gs-render compare; the JSON carries the issue's keys, the Markdown,
    the picture and the docs' side by side are written."""
    import dataclasses

    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    runs = {}
    for label in (rc.TARGET, rc.AUGMENTED):
        cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path / label.replace(" ", "_"),
                                  max_num_iterations=2, steps_per_eval_image=0, progress=False, timestamp="run")
        t = Trainer(cfg)
        t.setup()
        runs[label] = t.train()

    seen = {}

    def fake_real_photos(opts, runs_root, out_dir, rerun=False, log=print, name=None):
        seen["matching"] = opts.matching
        res = {rc.REFERENCE: {"failed": True, "error": "not trained here"}}
        res.update({lab: {"run_dir": str(runs[lab]), "results": {"test": {"psnr": p}}}
                    for lab, p in ((rc.TARGET, 20.0), (rc.AUGMENTED, 19.5))})
        return {"process": {"frames": 10, "registered": 9, "metres_per_unit": 1.0, "scale_source": "camera height",
                            "stage_seconds": {"features": 1.0}},
                "masks": {"coverage": {"sky": 0.2, "transient": 0.01}}, "results": res,
                "stage_seconds": {"process": 1.0, "masks": 2.0, f"train + eval: {rc.TARGET}": 3.0}, "wall_seconds": 6.0}

    monkeypatch.setattr("nerf2gs_bench.real_photos.run_real_photos", fake_real_photos)
    cap = rc.Capture("standin", "standin", "tests", "CC0", "synthetic stand-in", camera_height=1.5, show_renders=True)
    monkeypatch.setattr(rc, "CAPTURES", (cap,))
    monkeypatch.setattr(rc, "SCALES", {"quick": dataclasses.replace(rc.SCALES["quick"], above_views=3)})
    _frames(tmp_path / "data" / "standin")
    doc = rc.run(["standin"], tmp_path / "data", tmp_path / "runs", tmp_path / "out", "quick", log=lambda s: None,
                 docs_picture=tmp_path / "docs.png")

    saved = json.loads((tmp_path / "out" / "real_captures.json").read_text())
    assert seen["matching"] == "sequential"  # a car's frames are a drive: matched as a video's, so the motion route runs
    c = saved["captures"][0]
    for key in ("moving_iou", "static_psnr_delta", "bev_hole_fraction", "stage_seconds", "registered_fraction", "masks_coverage"):
        assert key in c
    holes = c["bev_hole_fraction"]
    assert 0.0 <= holes["target"] <= 1.0 and 0.0 <= holes["augmented"] <= 1.0 and holes["reference"] is None
    assert c["registered_fraction"] == pytest.approx(0.9) and c["psnr_delta"] == pytest.approx(-0.5)
    assert c["moving_iou"] is None and c["static_psnr_delta"] is None  # no labels: not invented
    assert c["stage_seconds"]["masks"] == 2.0 and "holes from above" in c["stage_seconds"]
    assert saved["machine"]["cores"] and doc["scale"] == "quick" and saved["load_average"]["start"] >= 0
    md = (tmp_path / "out" / "real_captures.md").read_text()
    assert "Quick scale" in md and "synthetic stand-in" in md and "CC0" in md
    assert (tmp_path / "out" / "real_captures.png").stat().st_size > 1000

    # holes and picture come from ns2gs-render compare: its labelled frames, its measures
    views = sorted((tmp_path / "runs" / rc.STEM / "standin" / "compare-birds-eye").glob("*.png"))
    measures = json.loads((tmp_path / "runs" / rc.STEM / "standin" / "compare-birds-eye.measures.json").read_text())
    assert views and {m["label"]: m["bev_hole_fraction"] for m in measures} == {
        rc.COMPARE_LABELS[rc.TARGET]: holes["target"], rc.COMPARE_LABELS[rc.AUGMENTED]: holes["augmented"]}
    assert (tmp_path / "docs.png").stat().st_size <= 300_000

    # a rerun reuses the compare (same runs, same render code) and reports the same holes
    lines: list[str] = []
    again = rc.run(["standin"], tmp_path / "data", tmp_path / "runs", tmp_path / "out", "quick", log=lines.append)
    assert any("reusing the compare from above" in line for line in lines)
    c2 = again["captures"][0]
    assert c2["bev_hole_fraction"] == holes and "holes from above" in c2["reused_stages"]
    assert c2["stage_seconds"]["holes from above"] == c["stage_seconds"]["holes from above"]  # the saved seconds


def test_unknown_capture_is_refused_before_any_work(tmp_path):
    from nerf2gs_plugin.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown capture 'nope'"):
        rc.run(["nope"], tmp_path, tmp_path, tmp_path)


def test_a_capture_that_fails_is_recorded_and_the_bench_goes_on(tmp_path, monkeypatch):
    """SfM that registers too few frames of one capture: that capture's record says why, its figures are
    null, and the JSON/Markdown are still written."""
    import dataclasses

    from nerf2gs_plugin.errors import DataError

    def failing_real_photos(opts, runs_root, out_dir, rerun=False, log=print, name=None):
        raise DataError(f"{opts.images}: registration failed: only 3 of 10 frames registered")

    monkeypatch.setattr("nerf2gs_bench.real_photos.run_real_photos", failing_real_photos)
    cap = rc.Capture("standin", "standin", "tests", "CC0", "synthetic stand-in", camera_height=1.5, show_renders=True)
    monkeypatch.setattr(rc, "CAPTURES", (cap,))
    monkeypatch.setattr(rc, "SCALES", {"quick": dataclasses.replace(rc.SCALES["quick"], above_views=3)})
    _frames(tmp_path / "data" / "standin")
    rc.run(["standin"], tmp_path / "data", tmp_path / "runs", tmp_path / "out", "quick", log=lambda s: None)
    c = json.loads((tmp_path / "out" / "real_captures.json").read_text())["captures"][0]
    assert "only 3 of 10 frames registered" in c["failed"] and c["psnr_delta"] is None
    assert c["bev_hole_fraction"] == {"target": None, "augmented": None, "reference": None}
    assert "failed: " in (tmp_path / "out" / "real_captures.md").read_text()
