"""nerfstudio transforms.json parsing on generated data: intrinsics (shared, per frame, PINHOLE,
OPENCV with distortion, instant-ngp style), splits, ply points, normalisation and metric scale."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from nerf2gs_plugin.cameras import undistort_normalized
from nerf2gs_plugin.data import NerfstudioDataParserConfig, list_splits, parse_dataset
from nerf2gs_plugin.data.images import load_image, load_mask
from nerf2gs_plugin.data.normalize import DataparserTransform
from nerf2gs_plugin.data.ply import read_ply_points


def _meta(root: Path) -> dict:
    return json.loads((root / "transforms.json").read_text())


def _save(root: Path, meta: dict) -> None:
    (root / "transforms.json").write_text(json.dumps(meta))


def test_shared_intrinsics_and_ply(small_street):
    meta = _meta(small_street)
    out = parse_dataset(small_street, "train")
    assert torch.allclose(out.cameras.fx, torch.full((6,), meta["fl_x"]))
    assert torch.allclose(out.cameras.cx, torch.full((6,), meta["cx"]))
    assert not out.cameras.is_distorted
    xyz, rgb = read_ply_points(small_street / meta["ply_file_path"])
    tf = DataparserTransform(out.dataparser_transform, out.dataparser_scale)
    assert torch.allclose(out.points3D_xyz, tf.apply_points(torch.from_numpy(xyz)), atol=1e-5)
    assert torch.equal(out.points3D_rgb, torch.from_numpy(rgb))
    # the scene box holds the cameras and most points
    lo, hi = out.scene_box
    inside = ((out.points3D_xyz >= lo) & (out.points3D_xyz <= hi)).all(1).float().mean()
    assert inside > 0.95


def test_per_frame_intrinsics(street_copy):
    meta = _meta(street_copy)
    for k in ("fl_x", "fl_y", "cx", "cy"):
        v = meta.pop(k)
        for i, fr in enumerate(meta["frames"] + [f for s in meta["eval_splits"].values() for f in s]):
            fr[k] = v * (1.0 + 0.1 * i) if k.startswith("fl") else v
    _save(street_copy, meta)
    out = parse_dataset(street_copy, "train")
    expected = torch.tensor([meta["frames"][i]["fl_x"] for i in range(6)], dtype=torch.float32)
    assert torch.allclose(out.cameras.fx, expected)
    assert float(out.cameras.fx[5]) == pytest.approx(1.5 * float(out.cameras.fx[0]))
    assert float(parse_dataset(street_copy, "street").cameras.fx[1]) == pytest.approx(1.7 * meta["frames"][0]["fl_x"])


def _distort_image(img: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """What an OPENCV camera with ``dist`` would have recorded of the pinhole image ``img``."""
    h, w = img.shape[:2]
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    xd = torch.from_numpy((u + 0.5 - K[0, 2]) / K[0, 0])
    yd = torch.from_numpy((v + 0.5 - K[1, 2]) / K[1, 1])
    x, y = undistort_normalized(xd.reshape(-1), yd.reshape(-1), torch.tensor(dist, dtype=torch.float32).expand(h * w, 4))
    mx = (x.numpy() * K[0, 0] + K[0, 2] - 0.5).reshape(h, w).astype(np.float32)
    my = (y.numpy() * K[1, 1] + K[1, 2] - 0.5).reshape(h, w).astype(np.float32)
    return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def test_opencv_distortion_is_undistorted(street_copy):
    meta = _meta(street_copy)
    K = np.array([[meta["fl_x"], 0, meta["cx"]], [0, meta["fl_y"], meta["cy"]], [0, 0, 1.0]])
    dist = np.array([-0.12, 0.02, 0.002, -0.001])
    originals = {}
    for fr in meta["frames"]:
        p = street_copy / fr["file_path"]
        img = cv2.imread(str(p))
        originals[fr["file_path"]] = img
        cv2.imwrite(str(p), _distort_image(img, K, dist))
    meta.update(camera_model="OPENCV", k1=dist[0], k2=dist[1], p1=dist[2], p2=dist[3])
    _save(street_copy, meta)
    out = parse_dataset(street_copy, "train")
    assert not out.cameras.is_distorted
    assert float(out.cameras.fx[0]) != pytest.approx(meta["fl_x"])  # the undistorted camera zooms (alpha = 0)
    assert ".ns2gs_cache" in str(out.image_filenames[0])
    fx, fy, cx, cy = (float(getattr(out.cameras, k)[0]) for k in ("fx", "fy", "cx", "cy"))
    h, w = 32, 48
    for i, fr in enumerate(meta["frames"][:3]):
        und = load_image(out.image_filenames[i]).numpy()
        assert und.shape == (h, w, 3)
        # expected: the original pinhole image resampled to the new pinhole camera
        v, u = np.mgrid[0:h, 0:w].astype(np.float32)
        mx = ((u + 0.5 - cx) / fx * K[0, 0] + K[0, 2] - 0.5).astype(np.float32)
        my = ((v + 0.5 - cy) / fy * K[1, 1] + K[1, 2] - 0.5).astype(np.float32)
        expected = cv2.remap(originals[fr["file_path"]], mx, my, cv2.INTER_LINEAR)[:, :, ::-1] / 255.0
        distorted = cv2.imread(str(street_copy / fr["file_path"]))[:, :, ::-1] / 255.0
        c = (slice(4, h - 4), slice(4, w - 4))
        err = np.abs(und[c] - expected[c]).mean()
        assert err < 0.05
        assert err < 0.6 * np.abs(distorted[c] - expected[c]).mean()
    # masks go through the same remap and keep the image size
    m = load_mask(out.mask_filenames["ground"][0], (h, w))
    assert m.any() and m.shape == (h, w)


def test_instant_ngp_style(street_copy):
    meta = _meta(street_copy)
    fov = 2 * np.arctan(0.5 * meta["w"] / meta["fl_x"])
    ngp = {"camera_angle_x": fov, "frames": [{"file_path": fr["file_path"][:-4], "transform_matrix": fr["transform_matrix"]} for fr in meta["frames"]]}
    _save(street_copy, ngp)
    assert list_splits(street_copy) == ["train", "test"]  # every 8th frame held out
    out = parse_dataset(street_copy, "train")
    assert len(out) == 5 and len(parse_dataset(street_copy, "test")) == 1
    assert float(out.cameras.fx[0]) == pytest.approx(meta["fl_x"], rel=1e-5)
    assert int(out.cameras.width[0]) == 48 and int(out.cameras.height[0]) == 32
    assert out.image_filenames[0].suffix == ".png"
    # the folder convention still finds the masks
    assert out.mask_filenames["sky"][0] == street_copy / "masks" / "sky" / out.image_filenames[0].name


def test_train_val_test_filenames(street_copy):
    meta = _meta(street_copy)
    meta.pop("eval_splits")
    names = [fr["file_path"] for fr in meta["frames"]]
    meta.update(train_filenames=names[:4], val_filenames=names[4:5], test_filenames=names[5:])
    _save(street_copy, meta)
    assert list_splits(street_copy) == ["train", "val", "test"]
    assert [p.name for p in parse_dataset(street_copy, "val").image_filenames] == ["train_0004.png"]
    assert len(parse_dataset(street_copy, "train")) == 4


def test_eval_splits_referencing_frames(street_copy):
    meta = _meta(street_copy)
    meta["eval_splits"] = {"holdout": [meta["frames"][2]["file_path"], meta["frames"][3]["file_path"]]}
    _save(street_copy, meta)
    assert list_splits(street_copy) == ["train", "holdout"]
    assert len(parse_dataset(street_copy, "train")) == 4
    assert [p.name for p in parse_dataset(street_copy, "holdout").image_filenames] == ["train_0002.png", "train_0003.png"]


def test_eval_split_poses_share_the_train_normalisation(small_street):
    train, bev = parse_dataset(small_street, "train"), parse_dataset(small_street, "bev_1")
    assert torch.equal(train.dataparser_transform, bev.dataparser_transform)
    assert train.dataparser_scale == bev.dataparser_scale
    assert float(train.cameras.centers.abs().max()) == pytest.approx(1.0, abs=1e-5)  # unit box


def test_metric_scale_survives(street_copy):
    """Two cameras a known number of metres apart are that far apart in metres_to_world units,
    whatever unit the file uses."""
    meta = _meta(street_copy)
    pos = np.array([np.array(fr["transform_matrix"])[:3, 3] for fr in meta["frames"]])
    metres = float(np.linalg.norm(pos[0] - pos[3]))
    out = parse_dataset(street_copy, "train")
    world = float((out.cameras.centers[0] - out.cameras.centers[3]).norm())
    assert world == pytest.approx(out.metres_to_world(metres), rel=1e-4)
    # the same street stored in decimetres (poses x10) with metres_per_unit = 0.1
    for fr in meta["frames"] + [f for s in meta["eval_splits"].values() for f in s]:
        m = np.array(fr["transform_matrix"])
        m[:3, 3] *= 10
        fr["transform_matrix"] = m.tolist()
    meta["metres_per_unit"] = 0.1
    meta.pop("ply_file_path")
    _save(street_copy, meta)
    out_dm = parse_dataset(street_copy, "train")
    world_dm = float((out_dm.cameras.centers[0] - out_dm.cameras.centers[3]).norm())
    assert world_dm == pytest.approx(out_dm.metres_to_world(metres), rel=1e-4)
    assert out_dm.world_to_metres(1.0) == pytest.approx(out.world_to_metres(1.0), rel=1e-4)


def test_downscale_caches_half_size(small_street):
    out = parse_dataset(small_street, "train", downscale=2.0)
    assert int(out.cameras.width[0]) == 24 and int(out.cameras.height[0]) == 16
    assert float(out.cameras.fx[0]) == pytest.approx(_meta(small_street)["fl_x"] / 2, rel=1e-5)
    assert load_image(out.image_filenames[0]).shape == (16, 24, 3)
    assert load_mask(out.mask_filenames["transient"][0], (16, 24)).shape == (16, 24)
    again = parse_dataset(small_street, "train", downscale=2.0)
    assert again.image_filenames == out.image_filenames


def test_config_object(small_street):
    cfg = NerfstudioDataParserConfig(data=small_street / "transforms.json")
    assert cfg.splits() == ["train", "street", "bev_1", "bev_2", "val_street", "val_bev", "lane_1", "lane_2", "lane_4", "val_lane"]
    assert len(cfg.parse("street")) == 2
