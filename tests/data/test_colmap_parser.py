"""COLMAP sparse models (built with pycolmap 4.x in the test, binary and text) over the synthetic
street's training images: poses agree with the nerfstudio parse, masks, points, splits, scale."""

from __future__ import annotations

import json

import numpy as np
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


def _checker(x: np.ndarray, y: np.ndarray, square: float = 0.3) -> np.ndarray:
    """A checkerboard on the normalised image plane (x, y = camera-frame X/Z, Y/Z)."""
    return ((np.floor(x / square) + np.floor(y / square)) % 2).astype(np.float64)


def _pixel_grid(h: int, w: int, ss: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel sample positions (ss x ss per pixel, pixel centres at +0.5), shape [h, w, ss*ss]."""
    off = (np.arange(ss) + 0.5) / ss
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    ou, ov = np.meshgrid(off, off)
    return u[..., None] + ou.reshape(-1), v[..., None] + ov.reshape(-1)


def test_colmap_undistortion_by_pixels(small_street, write_colmap, tmp_path):
    """A checkerboard photographed by an OPENCV camera (rendered exactly: each sub-pixel sample's
    distorted ray undistorted with OpenCV's own solver), undistorted by the parser, equals the
    checkerboard rendered directly by the pinhole camera the parser reports."""
    import cv2

    from nerf2gs_plugin.data.images import load_image

    dist = np.array([-0.2, 0.05, 0.003, -0.002])
    root = write_colmap(small_street, tmp_path / "colmap", dist=list(dist))
    meta = json.loads((small_street / "transforms.json").read_text())
    h, w = meta["h"], meta["w"]
    K = np.array([[meta["fl_x"], 0, meta["cx"]], [0, meta["fl_y"], meta["cy"]], [0, 0, 1.0]])
    u, v = _pixel_grid(h, w)
    pts = np.stack([u.reshape(-1), v.reshape(-1)], -1)[:, None]  # K and points both in the +0.5 pixel-centre convention
    und = cv2.undistortPoints(pts, K, dist, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10))[:, 0]
    distorted = _checker(und[:, 0], und[:, 1]).reshape(h, w, -1).mean(-1)
    for img in (root / "images").iterdir():
        cv2.imwrite(str(img), np.repeat(np.round(distorted * 255)[..., None], 3, -1).astype(np.uint8))
    out = ColmapDataParserConfig(data=root, holdout_every=0).parse("train")
    assert not out.cameras.is_distorted
    fx, fy, cx, cy = (float(getattr(out.cameras, k)[0]) for k in ("fx", "fy", "cx", "cy"))
    pinhole = _checker((u - cx) / fx, (v - cy) / fy).mean(-1)
    got = load_image(out.image_filenames[0]).numpy().mean(-1)
    c = (slice(3, h - 3), slice(3, w - 3))
    err = np.abs(got[c] - pinhole[c]).mean()
    assert err < 0.05, err  # what is left: bilinear resampling across the squares' edges
    assert err < 0.35 * np.abs(distorted[c] - pinhole[c]).mean()  # far closer than the distorted photo
    # a half-pixel error in the principal point (the classic OpenCV convention slip) would be caught
    shifted = _checker((u - cx + 0.5) / fx, (v - cy + 0.5) / fy).mean(-1)
    assert np.abs(got[c] - shifted[c]).mean() > 2 * err


def test_model_in_plain_sparse_folder(small_street, write_colmap, tmp_path):
    root = write_colmap(small_street, tmp_path / "colmap", model_dir="sparse")
    assert len(parse_dataset(root, "train")) == 5
