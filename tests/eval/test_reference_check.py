"""Before a target trains on a reference, the log says (with the measured numbers)
whether the reference is weaker than the target's baseline; the same line goes into the run folder."""

import dataclasses
import json
from pathlib import Path

import pytest

from nerf2gs_plugin.eval.reference_check import CHECK_FILE, ReferenceCheck, compare_runs, held_out, measured_eval, reference_report


def _eval(folder: Path, name: str = "eval.json", **splits) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"results": {s: {"psnr": p, "ssim": 0.5, "num_images": n} for s, (p, n) in splits.items()}}
    (folder / name).write_text(json.dumps(doc))
    return folder


def test_compare_runs_signs_views_and_split(tmp_path):
    ref = _eval(tmp_path / "ref", test=(19.8, 5), bev_1=(30.0, 4))
    base = _eval(tmp_path / "base", "bench_eval.json", test=(22.5, 5))
    check = compare_runs(ref, base)
    assert isinstance(check, ReferenceCheck)
    assert check.split == "test" and check.views == 5 and check.weaker
    assert check.delta_db == pytest.approx(-2.7)
    line = check.line()
    assert "2.70 dB BELOW" in line and "5 held-out views" in line and "19.80" in line and "22.50" in line
    assert "--augment.birds-eye-share 0.25" in line  # the measured lever, named where it matters
    above = compare_runs(base, ref)
    assert not above.weaker and "2.70 dB above" in above.line() and "birds-eye-share" not in above.line()


def test_compare_runs_says_why_not(tmp_path):
    ref = _eval(tmp_path / "ref", test=(20.0, 5))
    assert "no measured held-out metrics" in compare_runs(ref, tmp_path / "none")
    assert "different views" in compare_runs(ref, _eval(tmp_path / "b4", test=(21.0, 4)))
    assert "not evaluated on the reference's held-out split 'test'" in compare_runs(ref, _eval(tmp_path / "bs", street=(21.0, 5)))
    assert "not evaluated on a held-out split" in compare_runs(_eval(tmp_path / "bev", bev_1=(20.0, 5)), ref)


def test_newest_evaluation_wins_and_street_is_a_held_out_split(tmp_path):
    import os

    run = _eval(tmp_path / "run", street=(18.0, 2))
    _eval(run, "bench_eval.json", street=(21.0, 2))
    os.utime(run / "eval.json", (1, 1))
    assert measured_eval(run)["eval_file"].endswith("bench_eval.json")
    assert held_out(measured_eval(run)) == ("street", 21.0, 2)
    line, doc = reference_report(run / "step-000010.ckpt", None)  # a checkpoint names its run folder
    assert "21.00 dB PSNR on 2 held-out views (street)" in line and "--baseline" in line and doc["baseline"] is None


def _voxel(data, out, steps):
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("voxel-grid").config, data=data, output_dir=out, max_num_iterations=steps,
                              steps_per_save=steps, steps_per_eval_image=0, progress=False, timestamp="run")
    t = Trainer(cfg)
    t.setup()
    return t.train()


def test_train_cli_logs_and_writes_the_check_on_a_tiny_scene(tiny_scene, tmp_path, capsys):
    """Reference (2 steps: weak) and baseline (12 steps) evaluated by ns2gs-eval's code on the tiny
    scene's held-out street views; ``ns2gs-train --augment-from REF --baseline BASE`` logs the
    difference of the two measured PSNRs before training and writes it into the new run folder (the one
    the run takes: the check must not create ``<stamp>`` and push the run into ``<stamp>-1``)."""
    from nerf2gs_plugin.cli.train import pop_baseline, train
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.eval.evaluate import evaluate_run
    from nerf2gs_plugin.registry import get_method

    runs = {}
    for name, steps in (("ref", 2), ("base", 12)):
        run = _voxel(tiny_scene, tmp_path / name, steps)
        res = evaluate_run(load_run(run), ["street"], fps_repeats=1, lpips_model=lambda pred, gt: 0.0)  # no AlexNet: speed
        (run / "eval.json").write_text(json.dumps(res))
        runs[name] = (run, res["results"]["street"]["psnr"])
    argv, baseline = pop_baseline(["voxel-grid", "--baseline", str(runs["base"][0]), "--data", str(tiny_scene)])
    assert argv == ["voxel-grid", "--data", str(tiny_scene)] and baseline == runs["base"][0]
    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path / "tgt", max_num_iterations=2,
                              steps_per_eval_image=0, progress=False, augment_from=runs["ref"][0])  # default stamp
    cfg = dataclasses.replace(cfg, augment=dataclasses.replace(cfg.augment, delta_h=2.0, min_coverage=0.0))
    capsys.readouterr()
    train(cfg, baseline)
    out = capsys.readouterr().out
    delta = runs["ref"][1] - runs["base"][1]
    assert f"{abs(delta):.2f} dB {'BELOW' if delta < 0 else 'above'} the baseline on 2 held-out views" in out
    assert out.index("held-out views") < out.index("run saved to")  # said before training, not after
    check = next((tmp_path / "tgt").rglob(CHECK_FILE))
    doc = json.loads(check.read_text())
    # the check lands in the run's own folder, and no empty folder is left beside it (<stamp> vs <stamp>-1)
    assert (check.parent / "config.yml").is_file() and [p.name for p in check.parent.parent.iterdir()] == [check.parent.name]
    assert doc["delta_db"] == pytest.approx(delta) and doc["views"] == 2 and doc["split"] == "street"


def test_pop_baseline_forms_and_errors():
    from nerf2gs_plugin.cli.train import pop_baseline
    from nerf2gs_plugin.errors import ConfigError

    assert pop_baseline(["splatfacto", "--baseline=runs/b", "--x", "1"]) == (["splatfacto", "--x", "1"], Path("runs/b"))
    assert pop_baseline(["splatfacto"]) == (["splatfacto"], None)
    with pytest.raises(ConfigError, match="--baseline needs a run folder"):
        pop_baseline(["splatfacto", "--baseline"])
