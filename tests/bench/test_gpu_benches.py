"""The two benches made for a GPU (splat render speed at a display resolution, StreetNeRF's paper preset
on a capture) run end to end on the CPU at toy sizes and write what they claim."""

import json

from nerf2gs_bench.paper_scale_real import run as paper_scale_real, steps_for_budget
from nerf2gs_bench.render_fps import run as render_fps


def test_steps_for_budget_fits_the_rate_and_stays_in_bounds():
    assert steps_for_budget(0.1, 240, 25000) == 2400
    assert steps_for_budget(0.1, 1e6, 25000) == 25000
    assert steps_for_budget(10.0, 240, 25000) == 200
    assert steps_for_budget(10.0, 240, 25000, floor=5) == 5


def test_render_fps_rows(tmp_path):
    doc = render_fps(tmp_path, "cpu", 64, 48, counts=(500, 2000), surfel_counts=(500,), repeats=2)
    rows = doc["rows"]
    assert [(r["kind"], r["primitives"]) for r in rows] == [("3DGS", 500), ("3DGS", 2000), ("2DGS", 500)]
    assert all(r["fps"] > 0 and r["fwd_bwd_ms"] > 0 and r["visible"] > 0 for r in rows)
    assert json.loads((tmp_path / "render_fps_cpu.json").read_text())["width"] == 64
    assert "| 3DGS | 2,000 |" in (tmp_path / "render_fps_cpu.md").read_text()


def test_paper_scale_real_trains_both_and_reports(tiny_scene, tmp_path):
    doc = paper_scale_real(tiny_scene, tmp_path / "out", tmp_path / "runs", budget_s=0.01, probe_steps=2,
                           device="cpu", name="tiny", min_steps=3, default_steps=6)
    paper, default = doc["rows"]["paper"], doc["rows"]["default"]
    assert paper["steps"] == 3 and paper["rays_per_batch"] == 4096
    assert default["steps"] == 6 and default["rays_per_batch"] == 1024
    for row in (paper, default):
        assert row["split"] == "street" and row["psnr"] > 5 and row["size"]["parameters"] > 0
    assert paper["full_schedule_minutes"] > 0
    md = (tmp_path / "out" / "paper_scale_real_tiny.md").read_text()
    assert "| paper | 3 | 4096 |" in md
