"""Bounds checks of COLMAP binary models before pycolmap reads them.

pycolmap trusts the counts inside ``cameras.bin``/``images.bin``/``points3D.bin``: a truncated or
corrupt file can make it allocate gigabytes (a 17 GB peak, then ``std::bad_alloc``) or read
garbage silently (a principal point from the wrong bytes). Here every record is walked with
``struct`` over the raw bytes: each declared count must fit in what is left of the file and the
records must end exactly at its end. Cost: one pass, no allocation beyond the file itself.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

from nerf2gs_plugin.errors import DataError

# COLMAP camera model id -> (name, number of parameters)
CAMERA_MODELS: dict[int, tuple[str, int]] = {
    0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5), 4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5), 8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12), 11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
}
MAX_IMAGE_SIDE = 1 << 20
MAX_NAME = 4096


class _Reader:
    def __init__(self, path: Path) -> None:
        self.path = path
        self.buf = path.read_bytes()
        self.pos = 0

    def fail(self, what: str) -> DataError:
        return DataError(f"corrupt COLMAP binary ({what} at byte {self.pos} of {len(self.buf)})", self.path)

    def need(self, n: int, what: str) -> None:
        if n < 0 or self.pos + n > len(self.buf):
            raise self.fail(f"truncated: {what} needs {n} bytes")

    def take(self, fmt: str, what: str) -> tuple:
        size = struct.calcsize(fmt)
        self.need(size, what)
        out = struct.unpack_from(fmt, self.buf, self.pos)
        self.pos += size
        return out

    def count(self, what: str, min_record: int) -> int:
        """A declared count that must fit in the rest of the file at ``min_record`` bytes each."""
        (n,) = self.take("<Q", what)
        left = len(self.buf) - self.pos
        if n * max(min_record, 1) > left:
            raise self.fail(f"{what} declares {n} records but only {left} bytes follow")
        return n

    def done(self) -> None:
        if self.pos != len(self.buf):
            raise self.fail(f"{len(self.buf) - self.pos} trailing bytes after the declared records")


def check_cameras_bin(path: Path) -> dict[int, tuple[str, int, int, list[float]]]:
    """camera id -> (model name, width, height, params); raises DataError on any inconsistency."""
    r = _Reader(path)
    cams = {}
    for _ in range(r.count("camera count", 24)):
        cam_id, model_id, w, h = r.take("<iiQQ", "camera header")
        if model_id not in CAMERA_MODELS:
            raise r.fail(f"camera {cam_id} has unknown model id {model_id}")
        name, n_params = CAMERA_MODELS[model_id]
        params = list(r.take(f"<{n_params}d", f"camera {cam_id} parameters"))
        if not (0 < w <= MAX_IMAGE_SIDE and 0 < h <= MAX_IMAGE_SIDE):
            raise r.fail(f"camera {cam_id} has an impossible size {w}x{h}")
        cams[cam_id] = (name, w, h, params)
    r.done()
    return cams


def check_images_bin(path: Path) -> int:
    """Number of images; raises DataError on any inconsistency."""
    r = _Reader(path)
    n = r.count("image count", 64 + 1 + 8)
    for _ in range(n):
        (image_id,) = r.take("<I", "image id")
        r.take("<7dI", f"image {image_id} pose")
        end = r.buf.find(b"\0", r.pos, r.pos + MAX_NAME + 1)
        if end < 0:
            raise r.fail(f"image {image_id} name is not terminated")
        r.pos = end + 1
        n2d = r.count(f"image {image_id} 2-D point count", 24)
        r.need(24 * n2d, f"image {image_id} 2-D points")
        r.pos += 24 * n2d
    r.done()
    return n


def check_points3d_bin(path: Path) -> int:
    """Number of 3-D points; raises DataError on any inconsistency."""
    r = _Reader(path)
    n = r.count("point count", 51)
    head = struct.Struct("<Q3d3BdQ")
    buf, size = r.buf, len(r.buf)
    pos = r.pos
    for i in range(n):  # a Python loop, but over records, not pixels
        if pos + head.size > size:
            r.pos = pos
            raise r.fail(f"truncated: point {i} of {n}")
        track = head.unpack_from(buf, pos)[-1]
        pos += head.size + 8 * track
        if pos > size:
            r.pos = pos - 8 * track
            raise r.fail(f"truncated: point {i} declares a track of {track} entries")
    r.pos = pos
    r.done()
    return n


def check_rigs_bin(path: Path) -> int:
    """COLMAP >= 3.12 ``rigs.bin``: per rig an id, a sensor count, the reference sensor, then the
    other sensors (type, id, has-pose flag, optional 7-double pose)."""
    r = _Reader(path)
    n = r.count("rig count", 8)
    for _ in range(n):
        rig_id, n_sensors = r.take("<II", "rig header")
        if n_sensors * 9 > len(r.buf) - r.pos + 8:
            raise r.fail(f"rig {rig_id} declares {n_sensors} sensors")
        if n_sensors > 0:
            r.take("<iI", f"rig {rig_id} reference sensor")
        for _ in range(max(n_sensors - 1, 0)):
            _, _, has_pose = r.take("<iIB", f"rig {rig_id} sensor")
            if has_pose:
                r.take("<7d", f"rig {rig_id} sensor pose")
    r.done()
    return n


def check_frames_bin(path: Path) -> int:
    """COLMAP >= 3.12 ``frames.bin``: per frame ids, a 7-double pose and its (sensor, data id) list."""
    r = _Reader(path)
    n = r.count("frame count", 68)
    for _ in range(n):
        (frame_id,) = r.take("<I", "frame id")
        r.take("<I7d", f"frame {frame_id} rig and pose")
        (n_data,) = r.take("<I", f"frame {frame_id} data count")
        r.need(16 * n_data, f"frame {frame_id} data ids")
        r.pos += 16 * n_data
    r.done()
    return n


CHECKS = {"cameras.bin": check_cameras_bin, "images.bin": check_images_bin, "points3D.bin": check_points3d_bin,
          "rigs.bin": check_rigs_bin, "frames.bin": check_frames_bin}


def check_model_dir(model_dir: Path) -> None:
    """Validate whichever binary files ``model_dir`` holds (text models are parsed safely by pycolmap)."""
    model_dir = Path(model_dir)
    for name, check in CHECKS.items():
        if (model_dir / name).is_file():
            check(model_dir / name)


def check_intrinsics_inside(intr: Any, what: str, where: Path) -> None:
    """Positive finite focal lengths and a principal point inside the image (a corrupt model's
    garbage intrinsics would otherwise train silently)."""
    w, h = intr.width, intr.height
    vals = (intr.fx, intr.fy, intr.cx, intr.cy)
    if not all(math.isfinite(v) for v in vals) or intr.fx <= 0 or intr.fy <= 0:
        raise DataError(f"{what}: focal lengths must be positive and finite, got fx={intr.fx:g} fy={intr.fy:g}", where)
    if not all(math.isfinite(v) for v in intr.dist):
        raise DataError(f"{what}: non-finite distortion coefficients {intr.dist}", where)
    if not (0 < intr.cx < w and 0 < intr.cy < h):
        raise DataError(f"{what}: principal point ({intr.cx:g}, {intr.cy:g}) is outside the {w}x{h} image", where)
