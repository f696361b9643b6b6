from pathlib import Path

import pytest
import yaml

from nerf2gs_plugin.engine.config import load_config, save_config

from nerf2gs_plugin.utils.config import to_plain
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.engine.optimizers import OptimizerConfig
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.registry import get_method


def _default():
    return get_method("voxel-grid").config


def test_config_round_trip(tmp_path):
    import dataclasses

    cfg = _default()
    cfg = dataclasses.replace(cfg, data=Path("/some/data"), max_num_iterations=77, augment_from=Path("/a/reference"),
                              optimizers={"grid": OptimizerConfig(lr=0.5, lr_final=0.01)})
    save_config(tmp_path / "config.yml", cfg.method_name, cfg)
    text = (tmp_path / "config.yml").read_text()
    assert "!!python" not in text  # safe YAML, plain values only
    loaded = load_config(tmp_path / "config.yml", _default())
    assert loaded.max_num_iterations == 77 and loaded.data == Path("/some/data")
    assert isinstance(loaded.augment_from, Path) and loaded.augment_from == Path("/a/reference")  # Optional[Path]
    assert loaded.optimizers["grid"].lr == 0.5 and loaded.optimizers["grid"].lr_final == 0.01
    assert loaded.pipeline.model.resolution == cfg.pipeline.model.resolution


@pytest.mark.parametrize(
    "content, message",
    [
        ("method_name: [unclosed", "malformed YAML"),
        ("- just\n- a list\n", "not an nerf2gs config"),
        ("format_version: 99\nmethod_name: voxel-grid\nconfig: {}\n", "format version"),
        ("format_version: 1\nmethod_name: voxel-grid\nconfig: {no_such_field: 1}\n", "unknown field 'no_such_field'"),
        ("format_version: 1\nmethod_name: voxel-grid\nconfig: {max_num_iterations: lots}\n", "expected a number"),
    ],
)
def test_bad_config_is_one_clear_error(tmp_path, content, message):
    path = tmp_path / "config.yml"
    path.write_text(content)
    with pytest.raises(ConfigError) as e:
        load_config(path, _default())
    assert message in str(e.value) and str(path) in str(e.value)
    assert "\n" not in str(e.value)


def test_atomic_write_leaves_old_file_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "f.txt"
    atomic_write_text(path, "old")

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr("os.replace", boom)
    with pytest.raises(OSError):
        atomic_write_text(path, "new")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.txt"]  # no temp file left


def test_optimizer_schedule():
    cfg = OptimizerConfig(lr=1e-2, lr_final=1e-4, max_steps=100, warmup_steps=10)
    assert cfg.lr_at(0) == pytest.approx(1e-2 * 0.1)
    assert cfg.lr_at(100) == pytest.approx(1e-4)
    assert cfg.lr_at(50) == pytest.approx(1e-3, rel=1e-6)


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_atomic_write_follows_umask(tmp_path, umask, mode):
    """Files follow the umask, not tempfile.mkstemp's 0600."""
    import os
    import stat

    old = os.umask(umask)
    try:
        atomic_write_text(tmp_path / "f.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "f.txt").stat().st_mode) == mode


def test_a_section_cut_off_to_nothing_is_a_config_error(tmp_path):
    """A config.yml truncated after ``datamanager:`` reads that section as null: it used to become
    ``None`` in the config and end in an AttributeError traceback when the run was built."""
    cfg = _default()
    save_config(tmp_path / "config.yml", cfg.method_name, cfg)
    doc = yaml.safe_load((tmp_path / "config.yml").read_text())
    doc["config"]["pipeline"]["datamanager"] = None
    atomic_write_text(tmp_path / "config.yml", yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match="datamanager: expected a mapping"):
        load_config(tmp_path / "config.yml", _default())


def _cut_at_line(path, keep):
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:keep]))
    return len(lines)


@pytest.mark.parametrize("keep", [-1, -3, 12])
def test_a_config_cut_at_a_line_boundary_is_refused(tmp_path, keep):
    """YAML reads a file cut short at a line boundary as valid: the missing fields silently took
    their defaults (eval exit 0 on the wrong config). The end marker's absence gives it away."""
    cfg = _default()
    path = tmp_path / "config.yml"
    save_config(path, cfg.method_name, cfg)
    n = _cut_at_line(path, keep)
    assert 4 < (keep % n) < n
    with pytest.raises(ConfigError, match="cut short") as e:
        load_config(path, _default())
    assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_an_older_config_without_the_marker_loads_and_names_what_it_lacks(tmp_path):
    """A config written before the marker (or by hand) still loads; fields it lacks take their
    defaults with one warning naming them (it cannot tell a newer field from a lost one)."""
    from nerf2gs_plugin.warn import Nerf2gsWarning

    cfg = _default()
    path = tmp_path / "config.yml"
    doc = {"format_version": 1, "method_name": cfg.method_name, "config": to_plain(cfg)}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", Nerf2gsWarning)
        assert load_config(path, _default()) == cfg  # complete: no warning
    dm = doc["config"]["pipeline"]["datamanager"]
    dm["downscale"] = dm["dataparser"].pop("downscale")  # where a config saved before the move has it: not missing
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with warnings.catch_warnings():
        warnings.simplefilter("error", Nerf2gsWarning)
        load_config(path, _default())
    del doc["config"]["max_num_iterations"], doc["config"]["pipeline"]["model"]
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.warns(Nerf2gsWarning, match=r"no end marker.*max_num_iterations.*pipeline\.model") as w:
        loaded = load_config(path, _default())
    assert str(path) in str(w[0].message)
    assert loaded.max_num_iterations == cfg.max_num_iterations
