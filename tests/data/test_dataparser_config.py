"""The dataparser config nested in the DataManager config: new and old flags, old config.yml files,
and the parser contract (a config dataclass, or the older callable)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from nerf2gs_plugin.cli.train import parse_args
from nerf2gs_plugin.data import DataParserConfig, NerfstudioDataParserConfig, parser_config, registry
from nerf2gs_plugin.data.parser_config import build_parser
from nerf2gs_plugin.data.registry import DataParserSpecification
from nerf2gs_plugin.engine.config import load_config, save_config
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.registry import get_method


@pytest.mark.parametrize("prefix", ["--pipeline.datamanager.dataparser.", "--pipeline.datamanager."])
def test_new_and_old_flags_set_the_nested_config(prefix, tmp_path):
    cfg, _ = parse_args(["voxel-grid", f"{prefix}downscale", "2", f"{prefix}holdout-every", "3",
                         f"{prefix}metres_per_unit", "0.5", f"{prefix}camera-height", "1.5", f"{prefix}cache-dir", str(tmp_path)])
    assert cfg.pipeline.datamanager.dataparser == DataParserConfig(2.0, 3, 0.5, 1.5, tmp_path)


def test_help_names_the_nested_flags(capsys):
    with pytest.raises(SystemExit):
        parse_args(["splatfacto", "--help"])
    out = capsys.readouterr().out
    assert "--pipeline.datamanager.dataparser.downscale" in out and "--pipeline.datamanager.dataparser.cache-dir" in out


def _saved_config(tmp_path: Path, datamanager: dict) -> Path:
    path = tmp_path / "config.yml"
    save_config(path, "voxel-grid", get_method("voxel-grid").config)
    doc = yaml.safe_load(path.read_text())
    doc["config"]["pipeline"]["datamanager"] = datamanager
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_config_saved_before_the_nesting_loads(tmp_path):
    old = {"rays_per_batch": 512, "downscale": 2.0, "holdout_every": 4, "metres_per_unit": None, "camera_height": 1.5,
           "cache_dir": str(tmp_path / "c")}
    cfg = load_config(_saved_config(tmp_path, old), get_method("voxel-grid").config)
    assert cfg.pipeline.datamanager.rays_per_batch == 512
    assert cfg.pipeline.datamanager.dataparser == DataParserConfig(2.0, 4, None, 1.5, tmp_path / "c")


def test_an_option_at_both_places_is_refused(tmp_path):
    both = {"downscale": 2.0, "dataparser": {"downscale": 4.0}}
    with pytest.raises(ConfigError, match="'downscale' moved to 'dataparser.downscale'"):
        load_config(_saved_config(tmp_path, both), get_method("voxel-grid").config)


def test_options_reach_the_detected_parser(tiny_scene, tmp_path):
    parser = DataParserConfig(downscale=2.0, holdout_every=3, cache_dir=tmp_path).setup(tiny_scene)
    assert isinstance(parser, NerfstudioDataParserConfig)
    assert (parser.downscale, parser.holdout_every, parser.cache_dir, parser.metres_per_unit) == (2.0, 3, tmp_path, None)
    assert DataParserConfig().setup(tiny_scene).holdout_every == 8  # unset: the parser's own default


@dataclasses.dataclass
class _Minimal:
    data: Path
    downscale: float = 1.0


def test_an_option_the_parser_lacks_is_named():
    assert build_parser("mini", _Minimal, Path("x"), DataParserConfig(downscale=2.0)) == _Minimal(Path("x"), 2.0)
    with pytest.raises(ConfigError, match="dataparser 'mini' takes no option holdout_every"):
        build_parser("mini", _Minimal, Path("x"), DataParserConfig(holdout_every=2))


def test_a_plugin_of_the_older_callable_contract_still_works(tiny_scene, tmp_path, monkeypatch):
    calls = []

    def old_style(data, downscale, **options):
        calls.append((data, downscale, options))
        return NerfstudioDataParserConfig(data=data, downscale=downscale, **options)

    spec = DataParserSpecification(detect=lambda d: True, config=old_style, description="old")
    monkeypatch.setattr(parser_config, "discover_dataparsers", lambda: registry.DataParserDiscovery({"old": spec}, {}))
    out = DataParserConfig(downscale=2.0, holdout_every=0, cache_dir=tmp_path).setup(tiny_scene).parse("train")
    assert calls == [(tiny_scene, 2.0, {"holdout_every": 0})]  # no cache_dir: the older contract has none
    assert len(out) > 0
