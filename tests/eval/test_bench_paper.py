"""The paper-table bench machinery on tiny runs of the example plugin method: one progress bar
over the plan, a log file, JSON/Markdown/PNG outputs, LPIPS n/a, reuse on the second run."""

import json

from nerf2gs_plugin.eval.bench_runs import RunSpec


def test_paper_bench_runs_a_plan_with_one_bar_and_log(tiny_scene, tmp_path, monkeypatch):
    from nerf2gs_plugin.eval import lpips as lpips_mod
    from nerf2gs_plugin.eval.bench_paper import run_named_bench

    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)
    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    base = {"max_num_iterations": 6, "steps_per_save": 6, "steps_per_eval_image": 0,
            "pipeline": {"model": {"resolution": 12, "num_samples": 8}}}
    plan = [RunSpec("grid", "voxel-grid", base), RunSpec("grid + views", "voxel-grid", base, augment_from="grid")]
    out, runs = tmp_path / "results", tmp_path / "runs"
    results = run_named_bench("tiny_table", plan, tiny_scene, runs, out, "Tiny table", compare=[("grid + views", "grid")])
    assert list(results) == ["grid", "grid + views"]
    doc = json.loads((out / "tiny_table.json").read_text())
    assert doc["machine"]["cores"] and doc["results"]["grid"]["results"]["street"]["lpips"] is None
    md = (out / "tiny_table.md").read_text()
    assert "| grid + views vs grid |" in md and "n/a" in md  # LPIPS missing -> n/a, never a number
    assert (out / "tiny_table.png").is_file() and (out / "tiny_table_speed_quality.png").is_file()
    log = (runs / "logs" / "tiny_table.log").read_text()
    assert "(2/2) grid + views" in log and log.count("[bench] train ") == 2
    run_named_bench("tiny_table", plan, tiny_scene, runs, out, "Tiny table", compare=[])
    assert (runs / "logs" / "tiny_table.log").read_text().count("[bench] reuse ") == 2
