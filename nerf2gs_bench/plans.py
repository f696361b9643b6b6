"""Validation studies as plans: one YAML file per study under ``benchmarks/plans/``, one runner.

A plan says what the study asks (``about``), which results it made (``results``, under
``benchmarks/results/``), what it needs (``inputs``: a dataset, a finished run...) and the calls that
make it (``steps``: a script of ``benchmarks/validation/`` and its arguments). Arguments name folders
by ``{placeholder}`` only, never by a machine's path: each comes from ``--set NAME=VALUE``, else the
environment (``NS2GS_<NAME>``), else the plan's default, else the runner's roots below.

    python -m nerf2gs_bench.plans list
    python -m nerf2gs_bench.plans show sh_degree
    python -m nerf2gs_bench.plans run sh_degree --set street=PATH [--dry-run]
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import tyro
import yaml

from nerf2gs_plugin.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
PLANS = REPO / "benchmarks" / "plans"
ROOTS: dict[str, str] = {
    "results": "benchmarks/results",
    "bench_runs": "benchmarks/runs",  # where ns2gs-bench keeps its trained runs (its --runs)
    "val_runs": "outputs/validation/runs",  # runs trained by the studies themselves
    "work": "outputs/validation/{study}",
}
"""Folders every plan may name; relative ones are under the repository."""
PLACEHOLDER = re.compile(r"\{([a-z_][a-z0-9_]*)\}")


def env_name(name: str) -> str:
    return "NS2GS_" + name.upper()


def expand(text: str, values: dict[str, str], where: str) -> str:
    """``text`` with every ``{name}`` replaced (values may name others); a name without a value is an error."""
    for _ in range(8):  # values refer to one another a few levels deep at most
        names = PLACEHOLDER.findall(text)
        if not names:
            return text
        missing = sorted({n for n in names if n not in values})
        if missing:
            hint = ", ".join(f"--set {n}=... (or {env_name(n)})" for n in missing)
            raise ConfigError(f"{where}: no value for {', '.join(missing)}: pass {hint}")
        text = PLACEHOLDER.sub(lambda m: values[m.group(1)], text)
    raise ConfigError(f"{where}: placeholders refer to each other in a loop: {text}")


def expand_roots(text: str) -> str:
    """``text`` with the runner's roots (and their ``NS2GS_*`` overrides) filled in: for a study's own
    input files, such as the run lists of ``run_table.py``."""
    return expand(text, root_values({}), "run list")


def root_values(sets: dict[str, str]) -> dict[str, str]:
    """The runner's roots, each overridden by ``--set`` or the environment, as absolute paths where relative."""
    out = {}
    for name, default in ROOTS.items():
        value = sets.get(name) or os.environ.get(env_name(name)) or default
        out[name] = value if value.startswith("{") or Path(value).is_absolute() else str(REPO / value)
    return out


@dataclass(frozen=True)
class Plan:
    name: str
    about: str
    results: tuple[str, ...]
    inputs: dict[str, dict[str, str]]
    steps: tuple[dict[str, Any], ...]
    status: str = "current"


def plan_path(name: str) -> Path:
    return PLANS / f"{name}.yaml"


def load_plan(name: str) -> Plan:
    path = plan_path(name)
    if not path.is_file():
        raise ConfigError(f"no plan '{name}' ({path} does not exist; `python -m nerf2gs_bench.plans list` names them)")
    doc = yaml.safe_load(path.read_text()) or {}
    if not isinstance(doc, dict) or not doc.get("steps"):
        raise ConfigError(f"{path}: a plan needs 'steps' (a list of {{script, args}})")
    for i, step in enumerate(doc["steps"]):
        if not isinstance(step, dict) or "script" not in step:
            raise ConfigError(f"{path}: step {i + 1} has no 'script'")
    return Plan(name=name, about=str(doc.get("about", "")).strip(), results=tuple(doc.get("results", ())),
                inputs=dict(doc.get("inputs") or {}), steps=tuple(doc["steps"]), status=str(doc.get("status", "current")))


def plan_names() -> list[str]:
    return sorted(p.stem for p in PLANS.glob("*.yaml"))


def values_for(plan: Plan, sets: dict[str, str]) -> dict[str, str]:
    """Every placeholder's value for ``plan``: ``--set``, then ``NS2GS_<NAME>``, then the plan's default."""
    unknown = sorted(set(sets) - set(plan.inputs) - set(ROOTS))
    if unknown:
        raise ConfigError(f"plan {plan.name}: --set {', '.join(unknown)}: not one of its inputs "
                          f"({', '.join(sorted(plan.inputs)) or 'none'}) or roots ({', '.join(ROOTS)})")
    values = {"study": plan.name, **root_values(sets)}
    for name, spec in plan.inputs.items():
        value = sets.get(name) or os.environ.get(env_name(name)) or (spec or {}).get("default")
        if value is not None:
            values[name] = str(value)
    return values


def commands(plan: Plan, sets: dict[str, str]) -> list[list[str]]:
    """The calls of ``plan``, every argument filled in."""
    values = values_for(plan, sets)
    out = []
    for i, step in enumerate(plan.steps):
        where = f"plan {plan.name}, step {i + 1}"
        script = REPO / step["script"]
        if not script.is_file():
            raise ConfigError(f"{where}: script {step['script']} does not exist")
        out.append([sys.executable, str(script)] + [expand(str(a), values, where) for a in step.get("args", ())])
    return out


def run_plan(plan: Plan, sets: dict[str, str], dry_run: bool = False) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    for name, value in root_values(sets).items():
        env[env_name(name)] = value.replace("{study}", plan.name)  # the scripts' own run lists read the same roots
    for cmd in commands(plan, sets):
        print("[plan] " + shlex.join(cmd[1:]), flush=True)
        if not dry_run:
            subprocess.run(cmd, cwd=REPO, env=env, check=True)


def _parse_sets(pairs: tuple[str, ...]) -> dict[str, str]:
    out = {}
    for pair in pairs:
        name, eq, value = pair.partition("=")
        if not eq or not name:
            raise ConfigError(f"--set {pair}: expected NAME=VALUE")
        out[name] = value
    return out


@dataclass
class List:
    """The plans, with their status and the results they made."""

    def main(self) -> None:
        for name in plan_names():
            plan = load_plan(name)
            print(f"{name:28s} {plan.status:10s} {', '.join(plan.results)}")


@dataclass
class Show:
    """One plan: what it asks, what it needs, and its calls as they would run."""

    study: tyro.conf.Positional[str]
    set: tuple[str, ...] = ()
    """NAME=VALUE for an input or a root (also read from NS2GS_<NAME>)."""

    def main(self) -> None:
        plan = load_plan(self.study)
        print(plan.about, "\n")
        for name, spec in plan.inputs.items():
            print(f"input {name}: {(spec or {}).get('about', '')} (default: {(spec or {}).get('default', 'none')})")
        print("results: " + ", ".join(plan.results))
        try:
            for cmd in commands(plan, _parse_sets(self.set)):
                print("  " + shlex.join(cmd[1:]))
        except ConfigError as err:
            print(f"  (not runnable yet: {err})")


@dataclass
class Run:
    """Run one plan's calls in order (each a script of benchmarks/validation/); stops at the first failure."""

    study: tyro.conf.Positional[str]
    set: tuple[str, ...] = ()
    """NAME=VALUE for an input or a root (also read from NS2GS_<NAME>)."""
    dry_run: bool = False
    """Print the calls without running them."""

    def main(self) -> None:
        run_plan(load_plan(self.study), _parse_sets(self.set), self.dry_run)


def main() -> None:
    cmd: Union[List, Show, Run] = tyro.extras.subcommand_cli_from_dict({"list": List, "show": Show, "run": Run},
                                                                      description=__doc__)
    cmd.main()


def entrypoint() -> None:
    from nerf2gs_plugin.cli.common import run_cli

    run_cli(main)


if __name__ == "__main__":
    entrypoint()
