"""speed-quality, stability and model-size benches: the pure parts (Pareto fronts, plans,
outcome classification, picks, tables) and tiny end-to-end runs on the example plugin method."""

import json
import math

import pytest

from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_bench import size as bench_size, speed_quality as bench_speed_quality, stability as bench_stability
from nerf2gs_bench.runs import RunSpec
from nerf2gs_bench.size import size_plan, smallest_within
from nerf2gs_bench.speed_quality import collect_points, pareto_front
from nerf2gs_bench.stability import StressCase, classify, stability_plan, summarize
from nerf2gs_bench.perturb import Perturbation
from nerf2gs_plugin.registry import get_method


def test_pareto_front():
    xs = [1.0, 2.0, 3.0, 2.5, 0.5, float("nan")]
    ys = [20.0, 19.0, 15.0, 14.0, 21.0, 30.0]
    assert pareto_front(xs, ys) == [4, 0, 1, 2]  # (2.5, 14) is dominated by (3, 15); NaN never on it
    # lower x better (training time): only points nothing faster-and-better beats
    assert pareto_front([10.0, 20.0, 30.0, 5.0], [20.0, 25.0, 24.0, 10.0], x_higher=False) == [3, 0, 1]
    assert pareto_front([1.0, 1.0], [5.0, 5.0]) == [0, 1]  # ties dominate nobody
    assert pareto_front([], []) == []


def test_pareto_front_on_three_axes():
    from nerf2gs_bench.speed_quality import pareto_front_nd

    fps = [10.0, 20.0, 20.0, 5.0, float("nan")]
    psnr = [20.0, 19.0, 19.0, 21.0, 30.0]
    mb = [1.0, 2.0, 3.0, 9.0, 0.1]
    # 2 is beaten by 1 (same FPS and PSNR, smaller); 3 is on it by PSNR alone; NaN never
    assert pareto_front_nd([fps, psnr, mb], (True, True, False)) == [0, 1, 3]
    assert pareto_front_nd([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]], (True, True, False)) == [0, 1]  # ties


def _result(label, target, fps, bev, street, secs, prims, run_dir, mb=None):
    return {"label": label, "target": target, "fps": fps, "train_seconds": secs, "run_dir": run_dir,
            "size": {"primitives": prims, "megabytes": prims / 4000 if mb is None else mb},
            "results": {"street": {"psnr": street}, "bev_1": {"psnr": bev - 0.5}, "bev_2": {"psnr": bev + 0.5}}}


def test_speed_quality_reads_results_and_writes_outputs(tmp_path):
    res = tmp_path / "results"
    res.mkdir()
    with pytest.raises(DataError, match="run `ns2gs-bench paper-table` first"):
        collect_points(res)
    table = {"StreetNeRF": _result("StreetNeRF", "streetnerf", 0.1, 22.0, 23.0, 900, 0, "/r/nerf"),
             "splatfacto": _result("splatfacto", "splatfacto", 40.0, 17.0, 22.0, 300, 20000, "/r/sf"),
             "splatfacto + NeRF views": _result("splatfacto + NeRF views", "splatfacto", 35.0, 21.0, 22.5, 350, 30000, "/r/sfa")}
    ablation = {"StreetNeRF": table["StreetNeRF"], "StreetNeRF w/o sky": _result("StreetNeRF w/o sky", "streetnerf", 0.1, 20.0, 21.0, 800, 0, "/r/ns")}
    (res / "paper_table.json").write_text(json.dumps({"machine": {"cpu": "x", "cores": 2, "torch": "t"}, "results": table}))
    (res / "ablation.json").write_text(json.dumps({"machine": {"cpu": "x", "cores": 2, "torch": "t"}, "results": ablation}))
    points, machines = collect_points(res)
    assert [p["label"] for p in points] == ["StreetNeRF", "splatfacto", "splatfacto + NeRF views", "StreetNeRF w/o sky"]
    assert points[0]["source"] == "paper_table, ablation" and points[0]["bev_psnr"] == pytest.approx(22.0)
    payload = bench_speed_quality.run(res, tmp_path / "out")
    assert payload["front_fps"] == ["StreetNeRF", "splatfacto + NeRF views", "splatfacto"]
    assert payload["front_train_time"] == ["splatfacto", "splatfacto + NeRF views", "StreetNeRF"]
    # sizes 0 (StreetNeRF here), 5, 7.5 and 0 MB: the zero-MB runs have no size and are not ranked by it
    assert payload["front_megabytes"] == ["splatfacto", "splatfacto + NeRF views"]
    assert payload["front_fps_psnr_megabytes"] == ["splatfacto + NeRF views", "splatfacto"]
    md = (tmp_path / "out" / "speed_quality.md").read_text()
    assert "Machine: x, 2 cores" in md and "| StreetNeRF w/o sky | ablation | 0.10 | 20.00 |" in md
    assert "| splatfacto + NeRF views | 35.00 | 21.00 | 7.50 | 30000 |" in md  # listed on the three-axis front
    assert (tmp_path / "out" / "speed_quality.png").read_bytes()[:4] == b"\x89PNG"
    (res / "bad.json").write_text("{}")
    with pytest.raises(DataError, match="not a bench results file"):
        collect_points(res, ["bad"])


def test_stability_plan_walks_each_stress_mild_to_harsh():
    from nerf2gs_bench.stability_levels import STRESS_LEVELS

    plan = stability_plan("quick")
    own = get_method("splatfacto").config.seed
    sf = [c for c in plan if c.label_method == "splatfacto"]
    assert [c.variant for c in sf[:3]] == [f"seed {own}", f"seed {own + 1}", f"seed {own + 2}"]  # seeds first: the baseline
    assert [c.stress for c in sf[3:]] == [s for s in STRESS_LEVELS if s != "reference steps" for _ in STRESS_LEVELS[s]]
    pose = [c.perturbation for c in sf if c.stress == "pose noise"]
    assert [(p.rotation_deg, p.translation_m) for p in pose] == [(0.25, 0.025), (0.5, 0.05), (1, 0.1), (2, 0.2), (4, 0.4)]
    assert [c.perturbation.keep_every for c in sf if c.stress == "views kept"] == [2, 4, 8]
    assert [c.transients_factor for c in sf if c.stress == "transients"] == [2, 4, 8]
    assert [c.level_label for c in sf if c.stress == "mask drop"] == ["50%", "100%"]
    assert [c.level_label for c in sf if c.stress == "mask erosion"] == ["2px", "6px", "12px"]  # one kind, mild -> harsh
    spreads = [c.perturbation.exposure_spread for c in sf if c.stress == "exposure"]
    assert spreads == sorted(spreads) and len(spreads) >= 3
    for stress in STRESS_LEVELS:  # levels numbered 1.. in order
        assert [c.level for c in sf if c.stress == stress] == list(range(1, len([c for c in sf if c.stress == stress]) + 1))
    # the mild levels are the former one-level cases: same datasets, same runs (reused from the cache)
    assert next(c for c in sf if c.variant == "pose noise 0.5deg/5cm").perturbation == Perturbation(rotation_deg=0.5, translation_m=0.05, seed=7)
    assert next(c for c in sf if c.variant == "no masks").perturbation == Perturbation(drop_masks=True)
    assert next(c for c in sf if c.variant == "random init").perturbation == Perturbation(drop_points=True)
    from nerf2gs_bench.paper import paper_table_plan

    baseline = next(s for s in paper_table_plan("quick") if s.label == "splatfacto")
    assert sf[0].overrides == baseline.overrides  # the own-seed run is the paper-table run: trained once
    # the augmented pipeline: a reference per case; its training length is a stress of its own
    aug = [c for c in plan if c.label_method == "splatfacto + NeRF views"]
    ref_steps = [apply_plain(get_method("streetnerf").config, c.reference_overrides).max_num_iterations for c in aug]
    assert ref_steps[0] == 1500 and all(c.method == "splatfacto" for c in aug)
    short = [n for c, n in zip(aug, ref_steps) if c.stress == "reference steps"]
    assert short == sorted(short, reverse=True) and short[0] == 750 and short[-1] < 100
    assert all(c.stress != "reference steps" for c in plan if c.reference_overrides is None)
    for case in plan:  # every override is a real config field of its method
        cfg = apply_plain(get_method(case.method).config, case.overrides)
        assert cfg.seed == case.seed


def test_stability_plan_options_and_bad_names():
    plan = stability_plan("quick", ("2dgs",), stresses=("views kept",), steps_fraction=0.25, n_seeds=1)
    assert [c.variant for c in plan] == [f"seed {get_method('2dgs').config.seed}", "views kept 50%", "views kept 25%", "views kept 12%"]
    assert apply_plain(get_method("2dgs").config, plan[0].overrides).max_num_iterations == 200
    with pytest.raises(ConfigError, match="unknown stress 'wind'"):
        stability_plan("quick", ("splatfacto",), stresses=("wind",))
    with pytest.raises(ConfigError, match="unknown method 'nope'"):
        stability_plan("quick", ("nope+nerf",))
    with pytest.raises(ConfigError, match="reference cannot be trained on its own views"):
        stability_plan("quick", ("streetnerf+nerf",))
    with pytest.raises(ConfigError, match="steps-fraction"):
        stability_plan("quick", ("splatfacto",), steps_fraction=1.5)
    assert [c.label_method for c in stability_plan("quick", ("splatfacto + NeRF views",), stresses=("init",), n_seeds=1)] == \
        ["splatfacto + NeRF views"] * 2


def _level_row(method, stress, level, street, bev=15.0, status="ok", error=None):
    return {"method": method, "variant": f"{stress} L{level}", "stress": stress, "level": level, "level_label": f"L{level}",
            "status": status, "street_psnr": street, "bev_psnr": bev, "error": error}


def test_sweep_stops_each_stress_at_its_first_failure():
    from nerf2gs_bench.breaking_point import sweep

    seeds = [{"method": "m", "variant": f"seed {i}", "status": "ok", "street_psnr": 20.0, "bev_psnr": 15.0} for i in range(2)]
    outcomes = {("pose", 1): 19.0, ("pose", 2): 16.5, ("pose", 3): 18.0, ("views", 1): 19.5, ("views", 2): 19.0,
                ("exp", 1): "boom", ("exp", 2): 19.0, ("mask", 1): "unsupported", ("mask", 2): 19.0}
    cases = [(None, i) for i in range(2)] + [(s, lv) for s, lv in outcomes]
    ran = []

    def run_one(i, case):
        ran.append(case)
        stress, level = case
        if stress is None:
            return seeds[level]
        v = outcomes[case]
        if v == "boom":
            raise RuntimeError("kernel exploded\nsecond line")
        if v == "unsupported":
            return {"method": "m", "variant": "x", "stress": stress, "level": level, "status": "unsupported", "error": "unsupported: y"}
        return _level_row("m", stress, level, v)

    rows = sweep(cases, run_one, lambda c: ("m", c[0]) if c[0] else None)
    # pose breaks at level 2 (3.5 dB below), so level 3 is never run; views never breaks
    assert ("pose", 3) not in ran and ("views", 2) in ran and ("exp", 2) not in ran and ("mask", 2) not in ran
    assert len(rows) == len(ran) == 8  # 2 seeds, pose 1-2, views 1-2, exposure 1, masks 1
    err = next(r for r in rows if r.get("error_kind"))
    assert err["status"] == "error" and err["error"] == "RuntimeError: kernel exploded" and err["method"] == "m"

    from nerf2gs_bench.breaking_point import breaking_points

    err.update(stress="exp", level=1, level_label="L1")  # plain tuples carry no tags; real cases do
    points = breaking_points(rows)["m"]
    assert points["pose"] == {"level": "L2", "level_index": 2, "status": "collapse", "drop_db": pytest.approx(3.5),
                              "error": "street PSNR 3.50 dB below the unstressed mean"}
    assert points["views"] == "none up to L2"
    assert points["exp"]["status"] == "error" and points["exp"]["drop_db"] is None
    assert points["mask"] == "unsupported"


def test_breaking_points_table_json_and_chart(tmp_path):
    from nerf2gs_bench.breaking_point import breaking_markdown, breaking_points, level_chart

    rows = [{"method": m, "variant": f"seed {i}", "status": "ok", "street_psnr": 20.0 + i * 0.1, "bev_psnr": 16.0}
            for m in ("a", "a + NeRF views") for i in range(2)]
    rows += [_level_row("a", "pose noise", 1, 19.8), _level_row("a", "pose noise", 2, 19.0, bev=12.5),
             _level_row("a + NeRF views", "pose noise", 1, 19.9), _level_row("a + NeRF views", "pose noise", 2, 19.7),
             _level_row("a", "exposure", 1, None, None, status="nan", error="nan: non-finite PSNR/SSIM"),
             _level_row("a + NeRF views", "reference steps", 1, 18.0),
             _level_row("a + NeRF views", "exposure", 1, 19.0, status="collapse",
                        error="final PSNR 9.00 below the untrained model's 10.00 on the same images")]
    points = breaking_points(rows)
    assert points["a"]["pose noise"]["level"] == "L2" and points["a"]["pose noise"]["drop_db"] == pytest.approx(3.5)
    assert {k: v for k, v in points["a + NeRF views"].items() if k != "exposure"} == \
        {"pose noise": "none up to L2", "reference steps": "none up to L1"}
    assert points["a"]["exposure"]["status"] == "nan"
    json.dumps(points)  # JSON-ready
    md = breaking_markdown(points)
    assert "| method | pose noise | exposure | reference steps |" in md
    assert "| a | **L2** (collapse: 3.5 dB below) | **L1** (nan: nan) | not run |" in md
    assert "| a + NeRF views | none up to L2 | **L1** (collapse: below the untrained model) | none up to L1 |" in md
    level_chart(rows, tmp_path / "s.png", "t")
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG" and (tmp_path / "s.png").stat().st_size > 5000
    payload = bench_stability.write_outputs(rows, tmp_path / "out", "test", "street")
    assert payload["breaking_point"] == points and payload["levels"]["pose noise"][0] == "0.25deg/2.5cm"
    written = (tmp_path / "out" / "stability.md").read_text()
    assert "## Breaking points" in written and "## Outcomes" in written and (tmp_path / "out" / "stability.png").is_file()


def test_classify_and_summary_count_failures():
    good = {"results": {"street": {"psnr": 20.0, "ssim": 0.7}}}
    assert classify(good, None, 12.0, 20.0) == "ok"
    assert classify(good, None, 21.0, 20.0) == "collapse"
    assert classify({"results": {"street": {"psnr": float("nan"), "ssim": 0.1}}}, None, 12.0, 20.0) == "nan"
    assert classify(None, "TrainingDiverged: training diverged at step 5: non-finite loss", None, None) == "diverged"
    assert classify(None, "RuntimeError: out of memory", None, None) == "error"
    assert classify(None, "unsupported: needs the synthetic street", None, None) == "unsupported"
    rows = [{"method": "m", "variant": f"seed {i}", "status": "ok", "street_psnr": 20.0 + i, "bev_psnr": 15.0} for i in range(3)]
    rows += [{"method": "m", "variant": "pose", "status": "diverged", "error": "TrainingDiverged: x"},
             {"method": "m", "variant": "more", "status": "unsupported", "error": "unsupported: y"}]
    s = summarize(rows)["m"]
    assert s["failures"] == 1 and s["diverged"] == 1 and s["unsupported"] == 1 and s["cases"] == 5
    assert s["seed_street_mean"] == pytest.approx(21.0) and s["seed_street_std"] == pytest.approx(math.sqrt(2 / 3))
    md = bench_stability.markdown(rows, summarize(rows))
    assert "**DIVERGED**" in md and "| m | 21.00 +- 0.82 (n=3) | 15.00 +- 0.00 (n=3) | 1/4 | 1 | 0 | 0 | 0 | 1 |" in md


def test_a_quality_collapse_is_a_failure():
    """A case more than 3 dB below its method's unstressed seed mean (street or BEV) fails, even
    though it ends above the untrained model; 2.9 dB below does not."""
    from nerf2gs_bench.stability import mark_collapses

    rows = [{"method": "m", "variant": f"seed {i}", "status": "ok", "street_psnr": 22.0 + d, "bev_psnr": 19.0} for i, d in enumerate((-0.1, 0.0, 0.1))]
    rows += [{"method": "m", "variant": "random init", "status": "ok", "street_psnr": 17.0, "bev_psnr": 18.5, "error": None},
             {"method": "m", "variant": "no masks", "status": "ok", "street_psnr": 21.5, "bev_psnr": 16.1, "error": None},
             {"method": "m", "variant": "pose", "status": "ok", "street_psnr": 21.0, "bev_psnr": 15.9, "error": None},
             {"method": "other", "variant": "pose", "status": "ok", "street_psnr": 5.0, "bev_psnr": 5.0}]  # no seed runs: no baseline
    marked = mark_collapses(rows)
    assert [r["status"] for r in marked] == ["ok"] * 3 + ["collapse", "ok", "collapse", "ok"]
    assert "street PSNR 5.00 dB below the unstressed mean" in marked[3]["error"] and "bev PSNR 3.10 dB" in marked[5]["error"]
    s = summarize(marked)["m"]
    assert s["failures"] == 2 and s["collapse"] == 2
    assert rows[3]["status"] == "ok"  # the input rows are not modified
    # the per-run log line says what the table will say (it once printed "ok" for a collapse)
    assert bench_stability.log_line("m random init", rows[:4]).startswith("[stability] m random init: collapse (street PSNR 5.00")
    assert bench_stability.log_line("m seed 0", rows[:1]) == "[stability] m seed 0: ok"


def test_committed_stability_results_use_the_collapse_definition():
    """benchmarks/results/stability.json was regenerated with the > 3 dB collapse rule."""
    from pathlib import Path

    from nerf2gs_bench.stability import COLLAPSE_DB, mark_collapses

    d = json.loads((Path(__file__).resolve().parents[2] / "benchmarks/results/stability.json").read_text())
    assert d["collapse_db"] == COLLAPSE_DB
    assert [r["status"] for r in mark_collapses(d["rows"])] == [r["status"] for r in d["rows"]]
    assert summarize(d["rows"]) == d["summary"]
    if "breaking_point" in d:  # the sweep's format; the one-level bench's file has none
        from nerf2gs_bench.breaking_point import breaking_points

        assert breaking_points(d["rows"]) == d["breaking_point"]


def test_size_plan_and_smallest_within():
    plan = size_plan("default")
    labels = [s.label for s in plan]
    assert len(labels) == len(set(labels))
    assert "splatfacto max_gaussians=5000" in labels and "scaffold-gs max_anchors=2000" in labels and "2dgs densify_grad_thresh=0.0016" in labels
    assert "splatfacto prune_weight_fraction=0" in labels  # the unpruned model is one of the swept configurations
    assert "splatfacto pixel_steps_per_gaussian=108000" in labels and "scaffold-gs pixel_steps_per_anchor=20000" in labels  # the views budget
    assert "splatfacto pixel_steps_per_gaussian=0" in labels and "2dgs gaussians_per_sparse_point=0" in labels  # either term off
    assert "splatfacto pixel_steps_per_gaussian=54000" not in labels  # the default's own value
    assert "scaffold-gs anchor_growth=0" in labels  # Scaffold-GS's views term alone
    assert "scaffold-gs pixel_steps_per_anchor=0" in labels  # its growth term alone
    for spec in plan:
        apply_plain(get_method(spec.method).config, spec.overrides)  # valid fields and types
    own = next(s for s in plan if s.label == "splatfacto default")  # the registered default, the paper table's run
    assert "pipeline" not in own.overrides
    assert "splatfacto max_gaussians=60000" not in labels  # the default's own value is not run twice
    aug = size_plan("quick", ("splatfacto",), augment=True)
    assert aug[0].method == "streetnerf" and all(s.augment_from == "StreetNeRF" for s in aug[1:])
    with pytest.raises(ConfigError, match="no sweep for method 'nope'"):
        size_plan("quick", ("nope",))
    assert "2dgs prune_margin_db=0" in labels and "splatfacto prune_margin_db=6" in labels  # the prune read from the fit, off
    some = [s.label for s in size_plan("default", ("2dgs",), fields=("prune_margin_db", "prune_weight_fraction"))]
    assert some == ["2dgs default", "2dgs prune_weight_fraction=0", "2dgs prune_weight_fraction=0.05", "2dgs prune_weight_fraction=0.2",
                    "2dgs prune_margin_db=0", "2dgs prune_margin_db=6"]  # 2: the default's own value
    assert [s.label for s in size_plan("quick", ("2dgs",), fields=())] == ["2dgs default"]
    with pytest.raises(ConfigError, match="sweeps no field prune_margin for 2dgs"):
        size_plan("quick", ("2dgs",), fields=("prune_margin",))
    rows = [{"label": "a", "method": "m", "quality": 20.0, "primitives": 60000},
            {"label": "b", "method": "m", "quality": 19.6, "primitives": 15000},
            {"label": "c", "method": "m", "quality": 19.4, "primitives": 5000},
            {"label": "d", "method": "m", "error": "boom"}]
    pick = smallest_within(rows)["m"]
    assert pick["best"] == "a" and pick["smallest"] == "b" and pick["reduction"] == pytest.approx(4.0)
    assert pick["chosen_on"] == "test views" and "default" not in pick
    # with validation views the picks follow them, and the default is placed against the band
    val = [dict(rows[0], val_quality=19.0), dict(rows[1], val_quality=19.9, default=True), dict(rows[2], val_quality=19.5), rows[3]]
    pick = smallest_within(val)["m"]
    assert pick["chosen_on"] == "validation views" and pick["best"] == "b" and pick["smallest"] == "c"
    assert pick["default"]["label"] == "b" and pick["default_over_smallest"] == pytest.approx(3.0)
    assert pick["default_below_best_db"] == 0 and pick["target_met"] is False
    assert pick["smallest_within_0_5dB"] == {"label": "c", "primitives": 5000, "mean_psnr": 19.5}


def test_stability_and_size_end_to_end_on_plugin_method(tiny_scene, tmp_path, monkeypatch):
    """Tiny voxel-grid runs: an ok case, a view subset, an unsupported stress and a forced NaN
    divergence, all reported; a rerun reuses everything; then a size sweep over the grid resolution."""
    from ns2gs_example_method import VoxelGridModel

    from nerf2gs_plugin.utils import lpips as lpips_mod

    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)  # keep it fast: LPIPS n/a
    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    orig = VoxelGridModel.get_loss_dict

    def poisoned(self, outputs, batch, metrics):  # resolution 9 marks the run that diverges after its first checkpoint
        losses = orig(self, outputs, batch, metrics)
        self.calls = getattr(self, "calls", 0) + 1
        return {k: v * float("nan") for k, v in losses.items()} if self.config.resolution == 9 and self.calls > 8 else losses

    monkeypatch.setattr(VoxelGridModel, "get_loss_dict", poisoned)
    base = {"max_num_iterations": 12, "steps_per_save": 6, "steps_per_eval_image": 0, "seed": 0}
    grid = lambda r: {**base, "pipeline": {"model": {"resolution": r, "num_samples": 8}}}  # noqa: E731
    plan = [StressCase("voxel-grid", "seed 0", 0, None, 1, grid(16)),
            StressCase("voxel-grid", "half views", 0, Perturbation(keep_every=2), 1, grid(16)),
            StressCase("voxel-grid", "2x transients", 0, None, 2, grid(16)),
            StressCase("voxel-grid", "poisoned", 0, None, 1, grid(9))]
    out, runs = tmp_path / "results", tmp_path / "runs"
    payload = bench_stability.run(plan, tiny_scene, runs, out, "test", synthetic=False)
    status = {r["variant"]: r["status"] for r in payload["rows"]}
    assert status == {"seed 0": "ok", "half views": "ok", "2x transients": "unsupported", "poisoned": "diverged"}
    assert "last good checkpoint" in payload["rows"][3]["error"] and "step-000000005.ckpt" in payload["rows"][3]["error"]
    assert payload["summary"]["voxel-grid"]["failures"] == 1 and payload["summary"]["voxel-grid"]["unsupported"] == 1
    ok = payload["rows"][0]
    assert ok["final_psnr"] > ok["initial_psnr"] and ok["street_psnr"] > 5
    assert "-every2-" in payload["rows"][1]["data"]
    md = (out / "stability.md").read_text()
    assert "Machine:" in md and "**DIVERGED**" in md and "| 1/3 |" in md and (out / "stability.png").is_file()
    assert json.loads((out / "stability.json").read_text())["summary"]["voxel-grid"]["diverged"] == 1
    log = runs / "logs" / "stability.log"
    assert log.read_text().count("[stability]") == 4
    again = bench_stability.run(plan, tiny_scene, runs, out, "test", synthetic=False)  # reuses runs and the known failure
    assert [r["status"] for r in again["rows"]] == [r["status"] for r in payload["rows"]]
    assert "known failure" in log.read_text() and log.read_text().count("[bench] train ") == 3

    sizes = [RunSpec(f"voxel-grid r={r}", "voxel-grid", grid(r)) for r in (8, 16)]  # r=16 is reused
    res = bench_size.run(sizes, tiny_scene, runs, out, "test")
    assert [r["primitives"] for r in res["rows"]] == [8**3, 16**3]
    assert all(r["val_quality"] is None for r in res["rows"])  # no validation views here: chosen on the test views
    size_log = (runs / "logs" / "model_size.log").read_text()
    assert size_log.count("[bench] train ") == 1  # the validation pass reuses the runs it just trained
    pick = res["picks"]["voxel-grid"]
    assert pick["smallest_primitives"] <= pick["best_primitives"] and pick["chosen_on"] == "test views"
    assert (out / "model_size.png").is_file() and "smallest within 0.5 dB" in (out / "model_size.md").read_text()


def test_quick_scale_rescales_schedules_and_merges_extras(tmp_path):
    from nerf2gs_bench.paper import _overrides, ablation_plan, speed_quality_chart

    sf = apply_plain(get_method("splatfacto").config, _overrides("quick", "splatfacto"))
    default = get_method("splatfacto").config
    assert sf.max_num_iterations == 800 and sf.optimizers["means"].max_steps == 800
    assert sf.pipeline.model.strategy.stop_split_at < sf.max_num_iterations < default.pipeline.model.strategy.stop_split_at
    nerf = next(s for s in ablation_plan("quick") if s.label == "StreetNeRF w/o sky")
    cfg = apply_plain(get_method("streetnerf").config, nerf.overrides)
    assert cfg.pipeline.model.sky is False and cfg.max_num_iterations == 1500 and cfg.optimizers["fields"].max_steps == 1500
    assert _overrides("default", "2dgs") == {"steps_per_eval_image": 0}
    # a confidence row per mode, beside the plain "views from StreetNeRF" row it is compared with
    conf = [s for s in ablation_plan("quick", confidence=("consistency",)) if s.augment.get("confidence")]
    assert [(s.label, s.augment_from, s.augment) for s in conf] == [
        ("splatfacto + views from StreetNeRF (consistency confidence)", "StreetNeRF", {"confidence": "consistency"})]
    assert not any(s.augment.get("confidence") for s in ablation_plan("quick"))
    # a row per view family, each from StreetNeRF with the family's defaults
    fams = {s.label: s.augment["views"] for s in ablation_plan("quick") if "views" in s.augment}
    assert fams == {"splatfacto + views from StreetNeRF (lane-shift)": ["lane-shift"], "splatfacto + views from StreetNeRF (raise)": ["raise"],
                    "splatfacto + views from StreetNeRF (birds-eye lane-shift)": ["birds-eye", "lane-shift"]}
    assert all(s.augment_from == "StreetNeRF" for s in ablation_plan("quick") if "views" in s.augment)
    short = ablation_plan("quick", streetnerf_terms=False)
    assert [s.label for s in short] == [s.label for s in ablation_plan("quick") if " w/o " not in s.label] and len(short) == 7
    res = {"a": _result("a", "splatfacto", 30.0, 18.0, 20.0, 100, 1000, "/a"), "b": _result("b", "streetnerf", 0.2, 20.0, 21.0, 500, 0, "/b")}
    speed_quality_chart(res, tmp_path / "x_speed_quality.png", "t")
    assert (tmp_path / "x_speed_quality.png").read_bytes()[:4] == b"\x89PNG"




def test_case_dataset_reports_unsupported_stresses(tiny_scene, tmp_path):
    from nerf2gs_bench.stability import case_dataset

    colmap_like = tmp_path / "colmap"
    colmap_like.mkdir()
    with pytest.raises(DataError, match="unsupported: this stress writes a perturbed transforms.json"):
        case_dataset(StressCase("splatfacto", "no masks", perturbation=Perturbation(drop_masks=True)), colmap_like, tmp_path, True)
    with pytest.raises(DataError, match="unsupported: more transients"):
        case_dataset(StressCase("splatfacto", "2x transients", transients_factor=2), tiny_scene, tmp_path, False)
    assert case_dataset(StressCase("splatfacto", "seed 1"), tiny_scene, tmp_path, False) == tiny_scene
    copy = case_dataset(StressCase("splatfacto", "random init", perturbation=Perturbation(drop_points=True)), tiny_scene, tmp_path, False)
    assert copy.parent == tmp_path / "data" and "nopoints" in copy.name


def test_run_key_follows_the_resolved_config(monkeypatch):
    """A changed method default (not only a changed override) must retrain, never reuse a stale run."""
    import dataclasses

    from nerf2gs_bench import runs as bench_runs
    from nerf2gs_plugin import registry

    spec = RunSpec("sf", "splatfacto", {"max_num_iterations": 50})
    k0 = bench_runs.run_key("data", spec, None)
    assert k0 == bench_runs.run_key("data", RunSpec("other label", "splatfacto", {"max_num_iterations": 50}), None)
    assert k0 != bench_runs.run_key("data", RunSpec("sf", "splatfacto", {"max_num_iterations": 60}), None)
    real = registry.get_method("splatfacto")
    changed = dataclasses.replace(real.config, pipeline=dataclasses.replace(
        real.config.pipeline, model=dataclasses.replace(real.config.pipeline.model, sh_degree=1)))
    monkeypatch.setattr(registry, "get_method", lambda name: registry.MethodSpecification(changed, real.description))
    assert bench_runs.run_key("data", spec, None) != k0


def test_raster_bench_writes_tables_on_a_tiny_scale(tmp_path, monkeypatch):
    """Both backends time the same scenes; the files name the fast backend and the speedup is real."""
    from nerf2gs_bench import raster as bench_raster

    tiny = {"fwdbwd": [(300, 48, 32)], "fps": (300, 48, 32), "repeats": 1, "torch_max_pixels": 48 * 32,
            "torch_max_gaussians": 300, "surfels_fwdbwd": [(300, 48, 32)], "surfels_torch_max_pixels": 48 * 32}
    monkeypatch.setitem(bench_raster.SCALES, "tiny", tiny)
    r = bench_raster.run(tmp_path, "tiny")
    row = r["fwd_bwd"][0]
    assert r["fast_backend"] == "cpu" and row["visible"] > 0 and row["pairs"] > 0
    assert row["speedup"] == pytest.approx(row["torch_s"] / row["cpu_s"]) and row["speedup"] > 1.0  # the C++ kernel is faster
    assert r["surfels_fwd_bwd"][0]["torch_s"] > 0 and r["forward_fps"]["cpu_fps"] > 0
    md = (tmp_path / "raster.md").read_text()
    assert "cpu fwd+bwd (s)" in md and "## 2DGS surfels" in md
    assert (tmp_path / "raster.png").stat().st_size > 1000


def test_model_overrides_merge_nested_fields():
    from nerf2gs_bench.size import model_overrides

    assert model_overrides([]) == {}
    assert model_overrides(["strategy.max_gaussians=8000", "strategy.prune_weight_fraction=0.2", "depth_loss_weight=0"]) == {
        "pipeline": {"model": {"strategy": {"max_gaussians": 8000, "prune_weight_fraction": 0.2}, "depth_loss_weight": 0}}}


def test_a_bench_plans_an_augmented_run_at_its_step_factor():
    """The bench's progress bar counts the steps each run trains: a run with NeRF views trains longer."""
    from nerf2gs_bench.runner import planned_steps

    assert planned_steps("splatfacto", {"max_num_iterations": 700}) == 700
    assert planned_steps("splatfacto", {"max_num_iterations": 700}, {"delta_h": 3.0}) == 980
    assert planned_steps("splatfacto", {"max_num_iterations": 700}, {"step_factor": 1.0}) == 700
