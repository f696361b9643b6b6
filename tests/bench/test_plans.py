"""The validation plans: each names scripts that exist and results that are committed, every argument
resolves from options, the environment or a default, and no plan or run list names a machine's folder."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from nerf2gs_bench import plans
from nerf2gs_plugin.errors import ConfigError

MACHINE_PATH = re.compile(r"(?<![\w{}.])/(work|home|tmp|root|mnt)/")


@pytest.mark.parametrize("name", plans.plan_names())
def test_plan_resolves_and_its_results_are_committed(name):
    plan = plans.load_plan(name)
    assert plan.about and plan.results
    missing = [r for r in plan.results if not (plans.REPO / "benchmarks" / "results" / r).exists()]
    assert not missing, f"{name}: results not in benchmarks/results: {missing}"
    required = {k: f"/in/{k}" for k, spec in plan.inputs.items() if (spec or {}).get("default") is None}
    cmds = plans.commands(plan, required)
    assert len(cmds) == len(plan.steps)
    assert not any("{" in arg for cmd in cmds for arg in cmd), cmds


def test_no_plan_or_run_list_names_a_machine_folder():
    files = sorted(plans.PLANS.glob("*.yaml")) + sorted((plans.REPO / "benchmarks" / "validation").glob("*.json"))
    found = [f"{p.name}: {m.group(0)}" for p in files for m in MACHINE_PATH.finditer(p.read_text())]
    assert not found, found


def test_a_missing_input_names_the_option_and_the_variable(monkeypatch):
    monkeypatch.delenv("NS2GS_CASTLE_CAMERAS", raising=False)
    plan = plans.Plan("p", "about", ("x.md",), {"castle_cameras": {"about": "cameras"}},
                      ({"script": "benchmarks/validation/run_table.py", "args": ["{castle_cameras}"]},))
    with pytest.raises(ConfigError, match=r"plan p, step 1: no value for castle_cameras: pass --set castle_cameras=\.\.\. \(or NS2GS_CASTLE_CAMERAS\)"):
        plans.commands(plan, {})
    monkeypatch.setenv("NS2GS_CASTLE_CAMERAS", "/cams")
    assert plans.commands(plan, {})[0][2] == "/cams"
    assert plans.commands(plan, {"castle_cameras": "/other"})[0][2] == "/other"  # --set wins over the environment
    with pytest.raises(ConfigError, match="not one of its inputs"):
        plans.commands(plan, {"typo": "1"})


def test_run_plan_runs_each_step_with_the_roots_in_the_environment(tmp_path, monkeypatch):
    script = tmp_path / "step.py"
    script.write_text("import os, sys, pathlib\n"
                      "pathlib.Path(sys.argv[1]).write_text(os.environ['NS2GS_VAL_RUNS'] + ' ' + sys.argv[2])\n")
    out = tmp_path / "out.txt"
    plan = plans.Plan("p", "about", ("x.md",), {"label": {"default": "{val_runs}/a"}},
                      ({"script": str(script), "args": [str(out), "{label}"]},))
    plans.run_plan(plan, {"val_runs": str(tmp_path / "vr")})
    assert out.read_text() == f"{tmp_path / 'vr'} {tmp_path / 'vr'}/a"


def test_run_table_reads_runs_under_a_root(tmp_path, monkeypatch):
    """run_table.py expands ``{val_runs}`` in its run list from NS2GS_VAL_RUNS."""
    monkeypatch.setenv("NS2GS_VAL_RUNS", str(tmp_path / "runs"))
    assert plans.expand_roots("{val_runs}/data/splatfacto/abc") == f"{tmp_path / 'runs'}/data/splatfacto/abc"
    monkeypatch.delenv("NS2GS_VAL_RUNS")
    assert plans.expand_roots("{val_runs}/x") == str(plans.REPO / "outputs" / "validation" / "runs" / "x")


def test_cli_lists_the_plans(capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["plans", "list"])
    plans.main()
    out = capsys.readouterr().out
    assert all(name in out for name in plans.plan_names())


def test_validation_scripts_name_their_arguments():
    """Each study script parses its arguments (argparse: --help, a usage error naming what is missing)
    instead of reading sys.argv by position."""
    scripts = sorted((plans.REPO / "benchmarks" / "validation").glob("*.py"))
    assert scripts
    positional = [p.name for p in scripts if "sys.argv" in p.read_text()]
    assert positional == [], f"read sys.argv by position: {positional}"
