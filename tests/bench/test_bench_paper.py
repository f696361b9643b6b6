"""The paper-table bench machinery on tiny runs of the example plugin method: one progress bar
over the plan, a log file, JSON/Markdown/PNG outputs, LPIPS n/a, reuse on the second run."""

import json

import pytest

from nerf2gs_bench.runs import RunSpec


def test_paper_bench_runs_a_plan_with_one_bar_and_log(tiny_scene, tmp_path, monkeypatch):
    from nerf2gs_plugin.utils import lpips as lpips_mod
    from nerf2gs_bench.paper import run_named_bench

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
    from nerf2gs_bench.cli import Stability
    from nerf2gs_plugin.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown stress 'nothing'"):  # before any work: no dataset made
        Stability(methods=("splatfacto",), stresses=("nothing",), runs=tmp_path / "runs").main()
    assert not (tmp_path / "runs").exists()


def test_paper_bench_records_failed_runs_and_goes_on(tiny_scene, tmp_path, monkeypatch):
    """A run that diverges (NaN loss) and one whose evaluation errors are failed rows (reason in
    the JSON, a "failed: ..." cell in the Markdown), the runs after them still train, a run that
    augments from a failed run fails too, and the bench ends with BenchFailed (exit status 2)."""
    from ns2gs_example_method import VoxelGridModel

    from nerf2gs_plugin.utils import lpips as lpips_mod
    from nerf2gs_bench.runner import BenchFailed
    from nerf2gs_bench.paper import run_named_bench

    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)
    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    orig_loss = VoxelGridModel.get_loss_dict

    def poisoned(self, outputs, batch, metrics):  # resolution 9: the run that diverges
        losses = orig_loss(self, outputs, batch, metrics)
        return {k: v * float("nan") for k, v in losses.items()} if self.config.resolution == 9 else losses

    monkeypatch.setattr(VoxelGridModel, "get_loss_dict", poisoned)
    from nerf2gs_plugin.eval import evaluate as evaluate_mod  # bench_io imports evaluate_run at call time

    real_evaluate = evaluate_mod.evaluate_run

    def flaky(run, *args, **kwargs):  # resolution 10: training is fine, evaluation raises
        if run.model.config.resolution == 10:
            raise KeyError("eval split broken")
        return real_evaluate(run, *args, **kwargs)

    monkeypatch.setattr(evaluate_mod, "evaluate_run", flaky)
    grid = lambda r: {"max_num_iterations": 6, "steps_per_save": 6, "steps_per_eval_image": 0,  # noqa: E731
                      "pipeline": {"model": {"resolution": r, "num_samples": 8}}}
    plan = [RunSpec("bad", "voxel-grid", grid(9)), RunSpec("bad + views", "voxel-grid", grid(12), augment_from="bad"),
            RunSpec("broken eval", "voxel-grid", grid(10)), RunSpec("grid", "voxel-grid", grid(12)),
            RunSpec("grid + views", "voxel-grid", grid(12), augment_from="grid")]
    out, runs = tmp_path / "results", tmp_path / "runs"
    with pytest.raises(BenchFailed, match=r"3 of 5 runs failed: 'bad' \(TrainingDiverged: .*'bad \+ views' \(reference run 'bad' failed\)"):
        run_named_bench("tiny_table", plan, tiny_scene, runs, out, "Tiny table", compare=[("grid + views", "grid"), ("bad + views", "bad")])
    doc = json.loads((out / "tiny_table.json").read_text())
    res = doc["results"]
    assert list(res) == [s.label for s in plan]
    assert res["bad"]["failed"] and res["bad"]["error"].startswith("TrainingDiverged: training diverged at step 0")
    assert res["broken eval"]["failed"] and "KeyError" in res["broken eval"]["error"]
    assert not res["grid"].get("failed") and res["grid"]["results"]["street"]["psnr"] > 5
    assert not res["grid + views"].get("failed")
    assert set(doc["failed"]) == {"bad", "bad + views", "broken eval"}
    md = (out / "tiny_table.md").read_text()
    assert "| bad | failed: TrainingDiverged: training diverged at step 0" in md
    assert "| bad + views | failed: reference run 'bad' failed | - |" in md
    assert "**3 of 5 runs failed**" in md and "| grid + views vs grid |" in md and "bad + views vs bad" not in md
    assert (out / "tiny_table.png").is_file()


def test_bench_cli_exits_nonzero_on_failed_runs(monkeypatch, capsys):
    from nerf2gs_bench import cli as bench_cli
    from nerf2gs_plugin.cli.common import run_cli
    from nerf2gs_bench import paper as bench_paper
    from nerf2gs_bench.runner import BenchFailed

    def failing(*args, **kwargs):
        raise BenchFailed("1 of 3 runs failed: 'x' (TrainingDiverged: boom); results written to out/quick.md")

    monkeypatch.setattr(bench_paper, "run_named_bench", failing)
    monkeypatch.setattr(bench_cli, "ensure_street", lambda data, runs: data)
    with pytest.raises(SystemExit) as exc:
        run_cli(bench_cli.Quick().main)
    assert exc.value.code == 2 and "1 of 3 runs failed" in capsys.readouterr().err


def test_tables_gain_lane_and_extrapolated_columns(tiny_scene, tmp_path, monkeypatch):
    """A dataset with lane splits: the bench evaluates them, the Markdown has lane_2 / lane_4 and the
    extrapolated mean (of bev_1, bev_2, lane_2, lane_4) as columns and in the differences; a result
    without lane views keeps the three old columns."""
    import shutil

    from nerf2gs_plugin.utils import lpips as lpips_mod
    from nerf2gs_bench.paper import markdown_table, run_named_bench, target_groups

    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)
    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    data = tmp_path / "scene"
    shutil.copytree(tiny_scene, data)
    meta = json.loads((data / "transforms.json").read_text())
    ev = meta["eval_splits"]
    ev.update(bev_2=ev["bev_1"], lane_2=ev["street"][:1], lane_4=ev["street"][1:])  # stand-ins: only the names matter here
    (data / "transforms.json").write_text(json.dumps(meta))
    base = {"max_num_iterations": 4, "steps_per_save": 4, "steps_per_eval_image": 0,
            "pipeline": {"model": {"resolution": 10, "num_samples": 8}}}
    plan = [RunSpec("grid", "voxel-grid", base), RunSpec("grid + views", "voxel-grid", base, augment_from="grid")]
    out = tmp_path / "results"
    results = run_named_bench("lanes", plan, data, tmp_path / "runs", out, "Lanes", compare=[("grid + views", "grid")])
    r = results["grid"]["results"]
    assert {"lane_2", "lane_4", "bev_2"} <= set(r)
    mean = sum(r[s]["psnr"] for s in ("bev_1", "bev_2", "lane_2", "lane_4")) / 4
    assert results["grid"]["extrapolated"]["psnr"] == pytest.approx(mean)  # ns2gs-eval's result has the mean too
    md = (out / "lanes.md").read_text()
    head = next(line for line in md.splitlines() if line.startswith("| method"))
    assert "PSNR lane_2 | PSNR lane_4 | PSNR extrapolated |" in head
    row = next(line for line in md.splitlines() if line.startswith("| grid |"))
    cells = [c.strip().strip("*_") for c in row.split("|")[1:-1]]
    assert cells[head.split("|")[1:-1].index(" PSNR extrapolated ")] == f"{mean:.2f}"
    assert "d PSNR extrapolated" in md
    old = {"a": {"label": "a", "target": "t", "fps": 1.0, "size": {"primitives": 1, "megabytes": 1.0},
                 "results": {s: {"psnr": 20.0, "ssim": 0.5} for s in ("street", "bev_1", "bev_2")}}}
    old_md = markdown_table(old, target_groups(old), "old")
    assert "PSNR bev_2 | SSIM street" in old_md and "lane" not in old_md and "extrapolated" not in old_md
