"""Dataparsers come from one registry: built-ins plus the ``nerf2gs.dataparsers`` entry points
(tests/plugins/example_dataparser, installed by ``make setup``)."""

from __future__ import annotations

import csv
import json
import shutil
from importlib.metadata import EntryPoint

import torch

from nerf2gs_plugin.data import list_splits, parse_dataset, registry
from nerf2gs_plugin.utils import plugins


def test_builtins_and_the_example_plugin_are_registered():
    registry.discover_dataparsers.cache_clear()
    disc = registry.discover_dataparsers()
    assert list(disc.parsers)[:2] == ["nerfstudio", "colmap"]
    assert "poses-csv" in disc.parsers, f"example dataparser plugin not installed ({disc.failures})"


def _as_poses_csv(src, dst):
    """The tiny nerfstudio scene rewritten as the example plugin's format (no transforms.json)."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("transforms.json", "*.ply"))
    meta = json.loads((src / "transforms.json").read_text())
    rows = []
    for split, frames in [("train", meta["frames"]), *meta["eval_splits"].items()]:
        for fr in frames:
            c2w = [v for row in fr["transform_matrix"][:3] for v in row]
            rows.append([split, fr["file_path"], meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"], meta["w"], meta["h"], *c2w])
    with open(dst / "poses.csv", "w", newline="") as f:
        csv.writer(f).writerows(rows)
    return meta


def test_the_example_plugin_parses_a_dataset(tiny_scene, tmp_path):
    registry.discover_dataparsers.cache_clear()
    meta = _as_poses_csv(tiny_scene, tmp_path / "csv_scene")
    assert list_splits(tmp_path / "csv_scene") == ["train", "street", "bev_1"]
    out = parse_dataset(tmp_path / "csv_scene", "train")
    ref = parse_dataset(tiny_scene, "train")  # the same frames through the built-in nerfstudio parser
    assert [p.name for p in out.image_filenames] == [p.name for p in ref.image_filenames]
    assert len(out) == len(meta["frames"]) and set(out.mask_filenames) == {"sky", "ground", "transient"}
    assert torch.allclose(out.cameras.fx, ref.cameras.fx) and torch.equal(out.cameras.width, ref.cameras.width)
    # both normalisations are similarities of the same poses: camera distances agree up to one scale
    d_out = torch.cdist(out.cameras.camera_to_worlds[:, :, 3], out.cameras.camera_to_worlds[:, :, 3])
    d_ref = torch.cdist(ref.cameras.camera_to_worlds[:, :, 3], ref.cameras.camera_to_worlds[:, :, 3])
    ratio = d_out[d_ref > 1e-6] / d_ref[d_ref > 1e-6]
    assert float(ratio.std() / ratio.mean()) < 1e-4
    assert len(parse_dataset(tmp_path / "csv_scene", "bev_1")) == len(meta["eval_splits"]["bev_1"])


def test_a_broken_plugin_is_reported_by_name_and_skipped(monkeypatch, tiny_scene, capsys):
    broken = EntryPoint(name="broken-format", value="no_such_module_anywhere:spec", group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(plugins, "entry_points", lambda group: [broken])
    registry.discover_dataparsers.cache_clear()
    try:
        disc = registry.discover_dataparsers()
        assert "broken-format" in disc.failures and "broken-format" not in disc.parsers
        assert "dataparser plugin 'broken-format' failed to load and is skipped" in capsys.readouterr().err
        assert len(parse_dataset(tiny_scene, "train")) > 0  # the built-ins still work
    finally:
        registry.discover_dataparsers.cache_clear()
