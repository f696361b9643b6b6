"""COLMAP sparse models (built with pycolmap 4.x in the test, binary and text) over the synthetic
street's training images: poses agree with the nerfstudio parse, masks, points, splits, scale."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pycolmap
import pytest
import torch

from nerf2gs_plugin.cameras import opengl_c2w_to_opencv_w2c
from nerf2gs_plugin.data import ColmapDataParserConfig, list_splits, parse_dataset
from nerf2gs_plugin.data.ply import read_ply_points


def write_colmap(street: Path, root: Path, text: bool = False, model_dir: str = "sparse/0", dist=None) -> Path:
    """A COLMAP dataset at ``root`` holding the street's training views (poses from transforms.json)."""
    meta = json.loads((street / "transforms.json").read_text())
    rec = pycolmap.Reconstruction()
    if dist is None:
        cam = pycolmap.Camera(model="PINHOLE", width=meta["w"], height=meta["h"], params=[meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"]], camera_id=1)
    else:
        cam = pycolmap.Camera(model="OPENCV", width=meta["w"], height=meta["h"], params=[meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"], *dist], camera_id=1)
    rec.add_camera_with_trivial_rig(cam)
    (root / "images").mkdir(parents=True)
    for i, fr in enumerate(meta["frames"]):
        name = Path(fr["file_path"]).name
        shutil.copy(street / fr["file_path"], root / "images" / name)
        for kind in ("sky", "ground", "transient"):
            (root / "masks" / kind).mkdir(parents=True, exist_ok=True)
            shutil.copy(street / fr[f"{kind}_mask_path"], root / "masks" / kind / name)
        c2w = torch.tensor(fr["transform_matrix"], dtype=torch.float64)[None, :3]
        w2c = opengl_c2w_to_opencv_w2c(c2w)[0, :3].numpy()
        rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=1, image_id=i + 1), pycolmap.Rigid3d(w2c))
    xyz, rgb = read_ply_points(street / meta["ply_file_path"])
    for p, c in zip(xyz[:200].astype(np.float64), rgb[:200]):
        rec.add_point3D(p, pycolmap.Track(), c)
    out = root / model_dir
    out.mkdir(parents=True)
    rec.write_text(str(out)) if text else rec.write(str(out))
    return root


@pytest.mark.parametrize("text", [False, True], ids=["binary", "text"])
def test_colmap_poses_match_nerfstudio(small_street, tmp_path, text):
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


def test_colmap_holdout_splits_file_and_scale(small_street, tmp_path):
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


def test_colmap_opencv_camera_is_undistorted(small_street, tmp_path):
    root = write_colmap(small_street, tmp_path / "colmap", dist=[-0.05, 0.01, 0.0, 0.0])
    out = ColmapDataParserConfig(data=root, holdout_every=0).parse("train")
    assert not out.cameras.is_distorted
    assert ".ns2gs_cache" in str(out.image_filenames[0]) and out.image_filenames[0].is_file()


def test_model_in_plain_sparse_folder(small_street, tmp_path):
    root = write_colmap(small_street, tmp_path / "colmap", model_dir="sparse")
    assert len(parse_dataset(root, "train")) == 5
