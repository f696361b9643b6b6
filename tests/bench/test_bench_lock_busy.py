"""A run another bench holds the lock of is waited for, never remembered as the run's failure."""

from __future__ import annotations

from pathlib import Path

import pytest

import nerf2gs_bench.runner as runner_mod
from nerf2gs_bench.runner import BenchRunner
from nerf2gs_bench.runs import IN_USE, RunSpec
from nerf2gs_plugin.errors import ConfigError


def _runner(tmp_path: Path, monkeypatch, error: Exception) -> BenchRunner:
    def busy(*args, **kwargs):
        raise error

    monkeypatch.setattr(runner_mod, "train_or_reuse", busy)
    r = BenchRunner(tmp_path / "runs", log=lambda m: None, device="cpu")
    monkeypatch.setattr(r, "key", lambda spec, data, reference=None: "k123")
    monkeypatch.setattr(r, "fingerprint", lambda data: "ds")
    return r


def test_a_busy_lock_is_not_remembered_as_a_known_failure(tmp_path, monkeypatch):
    r = _runner(tmp_path, monkeypatch, ConfigError(f"{IN_USE} (pid 1); choose another --timestamp", tmp_path))
    out = r.run(RunSpec("a", "splatfacto"), tmp_path / "data")
    assert out.error and IN_USE in out.error
    assert not list((tmp_path / "runs").rglob("failures/*.json"))


def test_a_user_error_is_remembered(tmp_path, monkeypatch):
    r = _runner(tmp_path, monkeypatch, ConfigError("bad flag", tmp_path))
    r.run(RunSpec("a", "splatfacto"), tmp_path / "data")
    assert len(list((tmp_path / "runs").rglob("failures/*.json"))) == 1


@pytest.mark.parametrize("where", ["setup", "train"])
@pytest.mark.parametrize("tries", [1, 3])
def test_train_or_reuse_tries_again_while_the_lock_is_busy(tmp_path, monkeypatch, tries, where):
    """The trainer takes the lock when training starts, after the setup's renders: a collision there is retried too."""
    import nerf2gs_bench.runs as runs_mod

    calls = []

    class BusyTrainer:
        step_hooks: list = []

        def __init__(self, cfg):
            pass

        def _busy(self, stage):
            if stage == where:
                calls.append(1)
                raise ConfigError(f"{IN_USE} (pid 1)", tmp_path)

        def setup(self):
            self._busy("setup")

        def train(self):
            self._busy("train")

    monkeypatch.setattr(runs_mod, "Trainer", BusyTrainer)
    monkeypatch.setattr(runs_mod.time, "sleep", lambda s: None)
    with pytest.raises(ConfigError, match="in use"):
        runs_mod.train_or_reuse(RunSpec("a", "splatfacto", {"max_num_iterations": 2}), tmp_path / "data", tmp_path / "runs",
                                "ds", log=lambda m: None, device="cpu", _lock_tries=tries)
    assert len(calls) == tries
