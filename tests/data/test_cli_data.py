"""ns2gs-data front end: synth-street writes a readable dataset and prints the coverage summary;
preview writes a PNG contact sheet; the augmented-data subcommands are wired in."""

from __future__ import annotations

import json
import sys

import cv2
import pytest

from nerf2gs_plugin.cli import data as data_cli
from nerf2gs_plugin.data import list_splits


def _run(monkeypatch, *args: str) -> None:
    monkeypatch.setattr(sys, "argv", ["ns2gs-data", *args])
    data_cli.entrypoint()


def test_synth_street_cli(tmp_path, monkeypatch, capsys):
    out = tmp_path / "street"
    _run(monkeypatch, "synth-street", str(out), "--seed", "3", "--width", "40", "--height", "24", "--num-train", "4",
         "--num-street", "1", "--num-bev", "2", "--num-val-street", "1", "--num-val-bev", "2", "--spp", "1",
         "--num-points", "100", "--no-progress")
    text = capsys.readouterr().out
    assert "wrote" in text and "bev_1" in text and "within 15 deg" in text
    assert list_splits(out) == ["train", "street", "bev_1", "bev_2", "val_street", "val_bev", "lane_1", "lane_2", "lane_4",
                               "val_lane"]
    meta = json.loads((out / "transforms.json").read_text())
    assert meta["w"] == 40 and meta["h"] == 24 and meta["synthetic_street"]["seed"] == 3
    assert cv2.imread(str(out / meta["frames"][0]["file_path"])).shape == (24, 40, 3)
    stats = json.loads((out / "synth_stats.json").read_text())
    assert stats["ground_coverage"]["bev_2"]["ground_pixels"] > 0


def test_preview_png(small_street, tmp_path, monkeypatch, capsys):
    png = tmp_path / "sheet.png"
    _run(monkeypatch, "preview", str(small_street), "--out", str(png), "--rows", "2")
    assert str(png) in capsys.readouterr().out
    img = cv2.imread(str(png))
    assert img is not None and img.shape[0] > 300 and img.shape[1] > 600
    assert img.std() > 20  # not blank


def test_augmented_subcommands_are_registered(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ns2gs-data", "--help"])
    with pytest.raises(SystemExit) as e:
        data_cli.entrypoint()
    assert e.value.code == 0
    helptext = capsys.readouterr().out
    for sub in ("synth-street", "preview", "export-augmented", "preview-augmented"):
        assert sub in helptext


def test_preview_colmap_dataset(small_street, write_colmap, tmp_path, monkeypatch, capsys):
    root = write_colmap(small_street, tmp_path / "colmap")
    _run(monkeypatch, "preview", str(root), "--rows", "1")
    assert (root / "preview.png").is_file()
    assert cv2.imread(str(root / "preview.png")) is not None
