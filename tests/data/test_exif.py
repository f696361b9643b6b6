"""EXIF focal without PIL: a JPEG with FocalLengthIn35mmFilm gives the focal in pixels."""

import struct

import cv2
import numpy as np

from nerf2gs_plugin.data.process.exif import exif_focal_px


def _jpeg_with_f35(path, f35: int, w=64, h=48):
    ok, enc = cv2.imencode(".jpg", np.zeros((h, w, 3), np.uint8))
    body = enc.tobytes()[2:]  # without SOI
    # TIFF (little endian): IFD0 at 8 with one entry (ExifIFD pointer -> 26); Exif IFD with 0xA405 SHORT.
    ifd0 = struct.pack("<H", 1) + struct.pack("<HHII", 0x8769, 4, 1, 26) + struct.pack("<I", 0)
    exif = struct.pack("<H", 1) + struct.pack("<HHIHH", 0xA405, 3, 1, f35, 0) + struct.pack("<I", 0)
    tiff = b"II" + struct.pack("<HI", 42, 8) + ifd0 + exif
    app1 = b"Exif\x00\x00" + tiff
    path.write_bytes(b"\xff\xd8" + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + body)
    return path


def test_exif_focal_35mm(tmp_path):
    p = _jpeg_with_f35(tmp_path / "a.jpg", 28)
    assert cv2.imread(str(p)) is not None  # still a valid JPEG
    assert abs(exif_focal_px(p, 64, 48) - 28 / 36 * 64) < 1e-9
    q = tmp_path / "b.jpg"
    cv2.imwrite(str(q), np.zeros((8, 8, 3), np.uint8))
    assert exif_focal_px(q, 8, 8) is None
    r = tmp_path / "c.png"
    cv2.imwrite(str(r), np.zeros((8, 8, 3), np.uint8))
    assert exif_focal_px(r, 8, 8) is None


def test_exif_focal_of_cropped_frames_is_the_photos_focal(tmp_path):
    """Photos cut at the sides (--crop-factor) keep their lens: the focal in pixels is the photo's, scaled only
    by the shrink, not by the narrower frame."""
    from nerf2gs_plugin.data.process.frames import collect_images
    from nerf2gs_plugin.data.process.pipeline import ProcessOptions, exif_focal_for

    src = tmp_path / "photos"
    src.mkdir()
    photos = [_jpeg_with_f35(src / f"p{i}.jpg", 28) for i in range(5)]
    opts = ProcessOptions(crop_factor=(0.0, 0.0, 0.25, 0.25))
    rep = collect_images(src, tmp_path / "f", 0, crop=opts.crop_factor)
    assert cv2.imread(str(tmp_path / "f" / rep.names[0])).shape[1] == 32
    assert abs(exif_focal_for(photos, tmp_path / "f", rep.names, opts.kept_width) - 28 / 36 * 64) < 1e-9
