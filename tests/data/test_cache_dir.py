"""The undistorted / resized image cache: its location is said once and can be moved."""

from __future__ import annotations

from pathlib import Path

import pytest

from nerf2gs_plugin.data import parse_dataset
from nerf2gs_plugin.data import undistort


@pytest.fixture(autouse=True)
def _reset(monkeypatch):
    monkeypatch.setattr(undistort, "_ANNOUNCED", set())
    monkeypatch.delenv(undistort.CACHE_ENV, raising=False)


def _scene(tmp_path: Path) -> Path:
    from tiny_scene import write_tiny_scene

    return write_tiny_scene(tmp_path / "scene", n_train=3)


def test_default_cache_is_in_the_dataset_and_said_once(tmp_path, capsys):
    data = _scene(tmp_path)
    out = parse_dataset(data, "train", downscale=2.0)
    parse_dataset(data, "street", downscale=2.0)
    assert all(p.is_relative_to(data / undistort.CACHE_DIRNAME) for p in out.image_filenames)
    notes = [l for l in capsys.readouterr().err.splitlines() if l.startswith("note: undistorted/resized")]
    assert len(notes) == 1 and str(data / undistort.CACHE_DIRNAME) in notes[0]


def test_cache_dir_moves_it(tmp_path, capsys):
    data = _scene(tmp_path)
    out = parse_dataset(data, "train", downscale=2.0, cache_dir=tmp_path / "elsewhere")
    assert all(p.is_relative_to(tmp_path / "elsewhere") for p in out.image_filenames)
    assert not (data / undistort.CACHE_DIRNAME).exists()
    assert str(tmp_path / "elsewhere") in capsys.readouterr().err


def test_cache_dir_is_per_call_not_per_process(tmp_path):
    """A cache dir given to one parse leaves the next parse (another dataset, another DataManager) alone."""
    data = _scene(tmp_path)
    parse_dataset(data, "train", downscale=2.0, cache_dir=tmp_path / "elsewhere")
    out = parse_dataset(data, "street", downscale=2.0)
    assert all(p.is_relative_to(data / undistort.CACHE_DIRNAME) for p in out.image_filenames)


def test_env_var_moves_it(tmp_path, monkeypatch):
    data = _scene(tmp_path)
    monkeypatch.setenv(undistort.CACHE_ENV, str(tmp_path / "env"))
    assert parse_dataset(data, "train", downscale=2.0).image_filenames[0].is_relative_to(tmp_path / "env")
    out = parse_dataset(data, "train", downscale=2.0, cache_dir=tmp_path / "flag")  # the flag wins
    assert out.image_filenames[0].is_relative_to(tmp_path / "flag")


def test_datamanager_flag_sets_it(tmp_path):
    from nerf2gs_plugin.data import DataParserConfig
    from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig

    data = _scene(tmp_path)
    cfg = FullImageDataManagerConfig(dataparser=DataParserConfig(downscale=2.0, cache_dir=tmp_path / "c"))
    dm = cfg.setup(data=data)
    assert dm.train_data.image_filenames[0].is_relative_to(tmp_path / "c")
    assert dm.eval_split("street")[0].image_filenames[0].is_relative_to(tmp_path / "c")
