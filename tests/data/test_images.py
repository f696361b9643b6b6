"""The shared image/mask/depth loader: conventions and errors."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from nerf2gs_plugin.data.images import load_depth, load_image, load_mask, write_depth_atomic, write_image_atomic, write_mask_atomic
from nerf2gs_plugin.data.ply import read_ply_points, write_ply_points
from nerf2gs_plugin.errors import DataError


def test_rgba_mask_ignores_alpha(tmp_path):
    m = np.zeros((6, 5, 4), np.uint8)
    m[..., 3] = 255  # opaque everywhere: only the colour decides
    m[2, 3, :3] = 255
    cv2.imwrite(str(tmp_path / "m.png"), m)
    mask = load_mask(tmp_path / "m.png", (6, 5))
    assert mask.sum() == 1 and bool(mask[2, 3])


def test_rgba_image_over_white_and_16_bit(tmp_path):
    img = np.zeros((4, 4, 4), np.uint8)
    img[..., 2] = 255  # red (BGR order on disk)
    img[:, :2, 3] = 255  # left half opaque, right half transparent
    cv2.imwrite(str(tmp_path / "a.png"), img)
    rgb = load_image(tmp_path / "a.png")
    assert torch.allclose(rgb[0, 0], torch.tensor([1.0, 0.0, 0.0]))
    assert torch.allclose(rgb[0, 3], torch.ones(3))
    cv2.imwrite(str(tmp_path / "b.png"), np.full((3, 3), 65535, np.uint16))
    assert torch.allclose(load_image(tmp_path / "b.png"), torch.ones(3, 3, 3))


def test_round_trips_and_downscale(tmp_path):
    rgb = torch.rand(8, 12, 3)
    write_image_atomic(tmp_path / "i.png", rgb)
    assert (load_image(tmp_path / "i.png") - rgb).abs().max() <= 0.5 / 255 + 1e-6
    assert load_image(tmp_path / "i.png", downscale=2).shape == (4, 6, 3)
    mask = torch.rand(8, 12) > 0.5
    write_mask_atomic(tmp_path / "m.png", mask)
    assert torch.equal(load_mask(tmp_path / "m.png"), mask)
    depth = torch.rand(8, 12) * 30
    write_depth_atomic(tmp_path / "d.npy", depth)
    assert torch.equal(load_depth(tmp_path / "d.npy", (8, 12)), depth)
    with pytest.raises(DataError, match="d.npy: depth is 12x8 but its image is 10x8"):
        load_depth(tmp_path / "d.npy", (8, 10))
    xyz, col = np.random.rand(20, 3).astype(np.float32), (np.random.rand(20, 3) * 255).astype(np.uint8)
    write_ply_points(tmp_path / "p.ply", xyz, col)
    x2, c2 = read_ply_points(tmp_path / "p.ply")
    assert np.array_equal(x2, xyz) and np.array_equal(c2, col)


def test_ascii_ply_and_bad_ply(tmp_path):
    (tmp_path / "a.ply").write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 1 2\n3 4 5\n")
    xyz, rgb = read_ply_points(tmp_path / "a.ply")
    assert xyz.tolist() == [[0, 1, 2], [3, 4, 5]] and (rgb == 128).all()
    (tmp_path / "b.ply").write_text("hello")
    with pytest.raises(DataError, match="b.ply: not a PLY file"):
        read_ply_points(tmp_path / "b.ply")
    write_ply_points(tmp_path / "c.ply", np.zeros((10, 3), np.float32), np.zeros((10, 3), np.uint8))
    raw = (tmp_path / "c.ply").read_bytes()
    (tmp_path / "c.ply").write_bytes(raw[:-20])  # the last vertices cut off
    with pytest.raises(DataError, match=r"c.ply: PLY file is truncated \(10 vertices declared, 8 present\)"):
        read_ply_points(tmp_path / "c.ply")


def test_written_png_follows_umask(tmp_path):
    """PNGs follow the umask, not the temp file's 0600."""
    import os
    import stat

    old = os.umask(0o022)
    try:
        write_image_atomic(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.png").stat().st_mode) == 0o644
