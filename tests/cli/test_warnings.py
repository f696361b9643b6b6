"""Warnings are one plain line each, ``warning: <what>: <consequence>``, once per command; data
without masks or sparse points says so (random initialisation included), and eval does not repeat it."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from nerf2gs_plugin.warn import Nerf2gsWarning, install_plain_warnings, quiet, warn

_LINE = re.compile(r"^warning: [^:]+: \S.*$")


def test_plain_line_once_per_text(monkeypatch):
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)
    monkeypatch.setattr("nerf2gs_plugin.warn._PRINTED", set())
    out = io.StringIO()
    with warnings.catch_warnings():
        install_plain_warnings(out)
        for _ in range(3):
            warn("the dataset has no sky masks", "training without the sky loss")
        warn("no sparse points", "starting from 5000 random Gaussians")
        with quiet():
            warn("said at training time", "not again")
    assert out.getvalue().splitlines() == [
        "warning: the dataset has no sky masks: training without the sky loss",
        "warning: no sparse points: starting from 5000 random Gaussians",
    ]
    with pytest.warns(Nerf2gsWarning, match="no sky masks"):  # still a real warning for library users
        warn("the dataset has no sky masks", "x")


@pytest.fixture(scope="module")
def bare_scene(tmp_path_factory) -> Path:
    """The tiny scene without masks and without sparse points."""
    from tiny_scene import write_tiny_scene

    root = write_tiny_scene(tmp_path_factory.mktemp("bare") / "data")
    shutil.rmtree(root / "masks")
    (root / "points.ply").unlink()
    meta = json.loads((root / "transforms.json").read_text())
    meta.pop("ply_file_path")
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


def _train(method: str, data: Path, out: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.train", method, "--data", str(data), "--output-dir", str(out),
                           "--max-num-iterations", "2", "--steps-per-eval-image", "0", "--progress", "False"],
                          capture_output=True, text=True, env=env, timeout=600)


def _warning_lines(stderr: str) -> list[str]:
    return [l for l in stderr.splitlines() if l.startswith("warning:")]


def test_streetnerf_on_bare_data_warns_once_each(bare_scene, tmp_path):
    proc = _train("streetnerf", bare_scene, tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = _warning_lines(proc.stderr)
    assert "UserWarning" not in proc.stderr and "populate_modules" not in proc.stderr
    for kind in ("sky", "ground", "transient"):
        assert sum(f"no {kind} masks" in l for l in lines) == 1, lines
    assert sum("no sparse points" in l for l in lines) == 1, lines
    assert len(lines) == len(set(lines)) and all(_LINE.match(l) for l in lines), lines


def test_splatfacto_random_init_is_said(bare_scene):
    """In-process (the subprocess test above shows the CLI's form): the model says it starts random."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.methods.splatfacto.config import splatfacto_method

    train = parse_dataset(bare_scene, "train")
    assert train.points3D_xyz is None
    with pytest.warns(Nerf2gsWarning, match="^no sparse points: starting from 5000 random Gaussians"):
        splatfacto_method.config.pipeline.model.setup(train_data=train)
