"""The motion-mask benches' first reference is keyed on the model code (nerf2gs_bench/motion_product.py)."""

from pathlib import Path

import nerf2gs_bench.code_version as cv
import nerf2gs_bench.motion_product as mp
import nerf2gs_plugin.masking.mask_reference as mr


def _fake_training(monkeypatch, trained: list) -> None:
    def train(data, run, steps, downscale=1.0, progress=True, log=print):
        trained.append(Path(run))
        Path(run).mkdir(parents=True, exist_ok=True)
        (Path(run) / "config.yml").write_text("trained\n")
        return Path(run)

    monkeypatch.setattr(mr, "ensure_reference", train)
    monkeypatch.setattr(mp, "_config_difference", lambda ref: None)


def test_reference_is_retrained_for_other_model_code(tmp_path, monkeypatch):
    trained: list = []
    _fake_training(monkeypatch, trained)
    ref = tmp_path / "reference"
    monkeypatch.setattr(cv, "model_code_hash", lambda root=None: "code-a")
    assert mp.ensure_keyed_reference(tmp_path, ref) == {"code": "code-a", "today": "code-a", "stale": False}
    assert mp.ensure_keyed_reference(tmp_path, ref)["stale"] is False and len(trained) == 1  # same code: kept

    monkeypatch.setattr(cv, "model_code_hash", lambda root=None: "code-b")
    kept = mp.ensure_keyed_reference(tmp_path, ref, reuse_stale=True)
    assert kept == {"code": "code-a", "today": "code-b", "stale": True} and len(trained) == 1
    assert mp.ensure_keyed_reference(tmp_path, ref) == {"code": "code-b", "today": "code-b", "stale": False}
    assert len(trained) == 2


def test_reference_without_a_key_is_stale_and_another_config_always_retrains(tmp_path, monkeypatch):
    trained: list = []
    _fake_training(monkeypatch, trained)
    monkeypatch.setattr(cv, "model_code_hash", lambda root=None: "code-a")
    ref = tmp_path / "reference"
    ref.mkdir()
    (ref / "config.yml").write_text("an older run\n")
    assert mp.ensure_keyed_reference(tmp_path, ref, reuse_stale=True) == {"code": None, "today": "code-a", "stale": True}
    assert trained == []
    monkeypatch.setattr(mp, "_config_difference", lambda r: "pipeline.model.num_levels (12 there, 16 here)")
    assert mp.ensure_keyed_reference(tmp_path, ref, reuse_stale=True)["stale"] is False
    assert trained == [ref]
