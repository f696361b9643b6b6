"""A small synthetic street shared by the data tests (tests/street_fixtures.py) and COLMAP copies of it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pycolmap
import pytest
import torch

from nerf2gs_plugin.cameras import opengl_c2w_to_opencv_w2c
from nerf2gs_plugin.data.ply import read_ply_points
from street_fixtures import make_config, small_street, street_copy  # noqa: F401  (shared with tests/masks)


def _write_colmap(street: Path, root: Path, text: bool = False, model_dir: str = "sparse/0", dist=None) -> Path:
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


@pytest.fixture(scope="session")
def write_colmap():
    """``write_colmap(street, root, text=False, model_dir="sparse/0", dist=None)``: a COLMAP dataset
    (pycolmap 4.x model, images, masks, points) of the street's training views."""
    return _write_colmap
