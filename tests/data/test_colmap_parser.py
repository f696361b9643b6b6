"""COLMAP sparse models (built with pycolmap 4.x in the test, binary and text) over the synthetic
street's training images: poses agree with the nerfstudio parse, masks, points, splits, scale."""

from __future__ import annotations

import json

import pytest
import torch

from nerf2gs_plugin.data import ColmapDataParserConfig, list_splits, parse_dataset


@pytest.mark.parametrize("text", [False, True], ids=["binary", "text"])
def test_colmap_poses_match_nerfstudio(small_street, write_colmap, tmp_path, text):
    root = write_colmap(small_street, tmp_path / "colmap", text=text)
    ns = parse_dataset(small_street, "train")
    cm = ColmapDataParserConfig(data=root, holdout_every=0).parse("train")
    assert [p.name for p in cm.image_filenames] == [p.name for p in ns.image_filenames]
    assert torch.allclose(cm.cameras.camera_to_worlds, ns.cameras.camera_to_worlds, atol=1e-4)
    assert torch.allclose(cm.cameras.fx, ns.cameras.fx)
    assert set(cm.mask_filenames) == {"sky", "ground", "transient"}
    assert cm.points3D_xyz.shape == (200, 3) and cm.points3D_rgb.dtype == torch.uint8
    a, b = cm.points3D_xyz, ns.points3D_xyz[:200]  # same points, any order
    assert torch.allclose(a[a[:, 0].argsort()], b[b[:, 0].argsort()], atol=1e-4)


def test_colmap_holdout_splits_file_and_scale(small_street, write_colmap, tmp_path):
    root = write_colmap(small_street, tmp_path / "colmap")
    assert list_splits(root) == ["train", "test"]  # every 8th image (sorted by name) held out
    assert [p.name for p in parse_dataset(root, "test").image_filenames] == ["train_0000.png"]
    (root / "splits.json").write_text(json.dumps({"street": ["train_0001.png", "train_0004.png"]}))
    assert list_splits(root) == ["train", "street"]
    assert len(parse_dataset(root, "train")) == 4
    (root / "scene.json").write_text(json.dumps({"metres_per_unit": 2.0}))
    out = parse_dataset(root, "train")
    assert out.metres_per_unit == 2.0
    assert out.metres_to_world(2.0) == pytest.approx(out.dataparser_scale)


def test_colmap_opencv_camera_is_undistorted(small_street, write_colmap, tmp_path):
    root = write_colmap(small_street, tmp_path / "colmap", dist=[-0.05, 0.01, 0.0, 0.0])
    out = ColmapDataParserConfig(data=root, holdout_every=0).parse("train")
    assert not out.cameras.is_distorted
    assert ".ns2gs_cache" in str(out.image_filenames[0]) and out.image_filenames[0].is_file()


def test_model_in_plain_sparse_folder(small_street, write_colmap, tmp_path):
    root = write_colmap(small_street, tmp_path / "colmap", model_dir="sparse")
    assert len(parse_dataset(root, "train")) == 5
