"""The paper-table bench machinery on tiny runs of the example plugin method: one progress bar
over the plan, a log file, JSON/Markdown/PNG outputs, LPIPS n/a, reuse on the second run."""

import json

import pytest

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


def test_bench_cli_dispatches_subcommands(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    exe = str(Path(sys.executable).parent / "ns2gs-bench")
    res = tmp_path / "results"
    res.mkdir()
    def result(target, fps, bev, secs, run_dir):
        return {"target": target, "fps": fps, "train_seconds": secs, "size": {"primitives": 1}, "run_dir": run_dir,
                "results": {"bev_1": {"psnr": bev}, "bev_2": {"psnr": bev}}}

    table = {"a": result("splatfacto", 30.0, 18.0, 100, "/a"), "b": result("streetnerf", 0.2, 20.0, 500, "/b")}
    (res / "paper_table.json").write_text(json.dumps({"machine": {"cpu": "c", "cores": 2, "torch": "t"}, "results": table}))
    p = subprocess.run([exe, "speed-quality", "--results", str(res), "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "o" / "speed_quality.json").read_text())["front_fps"] == ["b", "a"]
    from nerf2gs_plugin.cli.bench import Stability
    from nerf2gs_plugin.errors import ConfigError

    with pytest.raises(ConfigError, match="matches no stability case"):
        Stability(methods=("splatfacto",), cases=("nothing",), runs=tmp_path / "runs").main()
