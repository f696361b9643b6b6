"""Corrupt COLMAP binaries are bounds-checked before pycolmap allocates anything."""

from __future__ import annotations

import struct
import time

import pycolmap
import pytest

from nerf2gs_plugin.data import ColmapDataParserConfig
from nerf2gs_plugin.errors import DataError


@pytest.fixture
def colmap_root(small_street, write_colmap, tmp_path):
    return write_colmap(small_street, tmp_path / "colmap")


def _parse(root):
    return ColmapDataParserConfig(data=root, holdout_every=0).parse("train")


def test_truncated_points3d_is_a_fast_clean_error(colmap_root):
    """A truncated points3D.bin took 173 s and a 17 GB peak before std::bad_alloc."""
    f = colmap_root / "sparse/0/points3D.bin"
    data = f.read_bytes()
    for cut in (7, 8 + 20, len(data) // 2, len(data) - 1):
        f.write_bytes(data[:cut])
        t0 = time.perf_counter()
        with pytest.raises(DataError, match=r"points3D.bin: corrupt COLMAP binary \((truncated|point count declares)"):
            _parse(colmap_root)
        assert time.perf_counter() - t0 < 5
    # a huge declared count in a small file: refused without allocating
    f.write_bytes(struct.pack("<Q", 1 << 60) + data[8:])
    with pytest.raises(DataError, match="declares 1152921504606846976 records"):
        _parse(colmap_root)


def test_cameras_bin_missing_its_last_bytes_is_an_error(colmap_root):
    """Missing its last 10 bytes it trained silently with the principal point read as (38, 38)."""
    f = colmap_root / "sparse/0/cameras.bin"
    f.write_bytes(f.read_bytes()[:-10])
    with pytest.raises(DataError, match=r"cameras.bin: corrupt COLMAP binary \(truncated: camera 1 parameters"):
        _parse(colmap_root)


def test_images_bin_truncated_or_padded(colmap_root):
    f = colmap_root / "sparse/0/images.bin"
    data = f.read_bytes()
    f.write_bytes(data[:-3])
    with pytest.raises(DataError, match="images.bin: corrupt COLMAP binary"):
        _parse(colmap_root)
    f.write_bytes(data + b"\0\0")
    with pytest.raises(DataError, match="2 trailing bytes"):
        _parse(colmap_root)


def test_principal_point_outside_the_image_is_an_error(colmap_root):
    model = colmap_root / "sparse/0"
    rec = pycolmap.Reconstruction(str(model))
    cam = rec.cameras[1]
    cam.params = [cam.params[0], cam.params[1], 100.0, 16.0]  # cx beyond the 48 px width
    rec.write(str(model))
    with pytest.raises(DataError, match=r"principal point \(100, 16\) is outside the 48x32 image"):
        _parse(colmap_root)
