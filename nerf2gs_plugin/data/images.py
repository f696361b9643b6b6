"""The one image/mask/depth loader every module uses (OpenCV, no PIL).

Conventions:
  * images are float32 ``[H, W, 3]`` RGB in ``[0, 1]``; 16-bit PNGs are scaled by 1/65535;
  * an RGBA image is composited over a **white** background (nerfstudio's default for
    blender-style data); grey images are repeated to 3 channels;
  * ``downscale`` shrinks to ``(round(W / d), round(H / d))`` with area averaging, the same rounding
    the parsers use for the cameras;
  * masks are bool ``[H, W]``: a pixel is inside the mask when its value is nonzero (any colour
    channel; the alpha channel of an RGBA mask is ignored, it is usually 255 everywhere);
  * depth maps are ``.npy`` (or ``.npz`` with one array) float32 ``[H, W]`` metres, z-depth, ``0`` = no
    depth (sky).

Every failure is a :class:`DataError` naming the file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Optional, Union

import cv2
import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.errors import DataError

PathLike = Union[str, Path]


def scaled_size(width: int, height: int, downscale: float) -> tuple[int, int]:
    """``(w, h)`` after shrinking by ``downscale``; the one rounding rule used everywhere."""
    if downscale <= 0:
        raise DataError(f"downscale must be positive, got {downscale}")
    return max(1, int(round(width / downscale))), max(1, int(round(height / downscale)))


def read_raw(path: PathLike, what: str = "image") -> np.ndarray:
    """Decode a file with OpenCV, unchanged (any depth, any channel count); BGR(A) order."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{what} file does not exist", path)
    arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if arr is None or arr.size == 0:
        raise DataError(f"cannot read {what} (not a valid image file)", path)
    return arr


def _to_unit_float(arr: np.ndarray, path: Path) -> np.ndarray:
    if arr.dtype == np.uint8:
        return arr.astype(np.float32) / 255.0
    if arr.dtype == np.uint16:
        return arr.astype(np.float32) / 65535.0
    if arr.dtype in (np.float32, np.float64):
        return np.clip(arr.astype(np.float32), 0.0, 1.0)
    raise DataError(f"unsupported image pixel type {arr.dtype}", path)


def decode_rgb(arr: np.ndarray, path: Path) -> np.ndarray:
    """OpenCV array (grey, BGR or BGRA) -> float32 RGB ``[H, W, 3]`` in [0, 1], alpha over white."""
    img = _to_unit_float(arr, path)
    if img.ndim == 2:
        img = img[:, :, None]
    c = img.shape[2]
    if c == 1:
        return np.repeat(img, 3, axis=2)
    if c == 4:
        alpha = img[:, :, 3:4]
        img = img[:, :, :3] * alpha + (1.0 - alpha)
    elif c != 3:
        raise DataError(f"image has {c} channels (expected 1, 3 or 4)", path)
    return np.ascontiguousarray(img[:, :, ::-1])


def resize(arr: np.ndarray, size_wh: tuple[int, int], nearest: bool = False) -> np.ndarray:
    """Resize an ``[H, W(, C)]`` array; area averaging when shrinking, nearest for masks/depth."""
    if (arr.shape[1], arr.shape[0]) == tuple(size_wh):
        return arr
    shrinking = size_wh[0] < arr.shape[1]
    interp = cv2.INTER_NEAREST if nearest else (cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR)
    out = cv2.resize(arr, tuple(int(s) for s in size_wh), interpolation=interp)
    if arr.ndim == 3 and out.ndim == 2:
        out = out[:, :, None]
    return out


def load_image(path: PathLike, downscale: float = 1.0) -> Tensor:
    """Image file -> float32 ``[H, W, 3]`` RGB in ``[0, 1]`` (RGBA composited over white)."""
    path = Path(path)
    img = decode_rgb(read_raw(path), path)
    if downscale != 1.0:
        img = resize(img, scaled_size(img.shape[1], img.shape[0], downscale))
    return torch.from_numpy(np.ascontiguousarray(img))


def image_size(path: PathLike) -> tuple[int, int]:
    """``(width, height)`` of an image file (decodes it: PNGs of this size are cheap)."""
    arr = read_raw(path)
    return int(arr.shape[1]), int(arr.shape[0])


def mask_channels(arr: np.ndarray) -> np.ndarray:
    """A decoded mask file -> ``[H, W]``: the max over its colour channels (alpha ignored)."""
    if arr.ndim == 3:
        arr = arr[:, :, :3].max(axis=2) if arr.shape[2] == 4 else arr.max(axis=2)
    return arr


def load_mask(path: PathLike, expected_hw: Optional[tuple[int, int]] = None) -> Tensor:
    """Mask file -> bool ``[H, W]`` (nonzero = inside). A size other than ``expected_hw`` is a DataError."""
    path = Path(path)
    arr = mask_channels(read_raw(path, "mask"))
    if expected_hw is not None and tuple(arr.shape[:2]) != tuple(expected_hw):
        h, w = expected_hw
        raise DataError(f"mask is {arr.shape[1]}x{arr.shape[0]} but its image is {w}x{h}", path)
    return torch.from_numpy(arr > 0)


def load_depth(path: PathLike, expected_hw: Optional[tuple[int, int]] = None, unit_scale: float = 1e-3) -> Tensor:
    """Depth ``.npy``/``.npz`` (metres) or 16-bit PNG (times ``unit_scale``, nerfstudio's millimetres)
    -> float32 ``[H, W]`` metres (z-depth, 0 = unknown)."""
    path = Path(path)
    if not path.is_file():
        raise DataError("depth file does not exist", path)
    if path.suffix.lower() not in (".npy", ".npz"):
        raw = read_raw(path, "depth")
        data = (raw[:, :, 0] if raw.ndim == 3 else raw).astype(np.float32) * unit_scale
    else:
        try:
            data = np.load(path, allow_pickle=False)
            if isinstance(data, np.lib.npyio.NpzFile):
                data = data[data.files[0]]
        except Exception as e:  # numpy raises several types for corrupt files
            raise DataError(f"cannot read depth file ({type(e).__name__}: {e})", path) from None
    arr = np.asarray(data, dtype=np.float32)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.ndim != 2:
        raise DataError(f"depth must be a 2-D array, got shape {arr.shape}", path)
    if expected_hw is not None and tuple(arr.shape) != tuple(expected_hw):
        h, w = expected_hw
        raise DataError(f"depth is {arr.shape[1]}x{arr.shape[0]} but its image is {w}x{h}", path)
    return torch.from_numpy(np.ascontiguousarray(arr))


def _atomic_write(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    from nerf2gs_plugin.utils.io import default_file_mode

    os.fchmod(fd, default_file_mode())  # mkstemp's 0600 -> what the umask gives
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _to_uint8(image: Union[Tensor, np.ndarray]) -> np.ndarray:
    arr = image.detach().cpu().numpy() if isinstance(image, Tensor) else np.asarray(image)
    if arr.dtype == np.bool_:
        return arr.astype(np.uint8) * 255
    if arr.dtype != np.uint8:
        arr = (np.clip(arr.astype(np.float32), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return arr


def write_image_atomic(path: PathLike, image: Union[Tensor, np.ndarray]) -> None:
    """Write ``[H, W, 3]`` RGB (float in [0,1] or uint8), ``[H, W]`` grey or a bool mask, atomically
    (temp file + ``os.replace``) so a crash never leaves a half-written PNG in a cache."""
    path = Path(path)
    arr = _to_uint8(image)
    if arr.ndim == 3 and arr.shape[2] == 3:
        arr = np.ascontiguousarray(arr[:, :, ::-1])
    elif arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]

    def write(tmp: str) -> None:
        if not cv2.imwrite(tmp, arr):
            raise DataError("cannot write image", path)

    _atomic_write(path, write)


def write_mask_atomic(path: PathLike, mask: Union[Tensor, np.ndarray]) -> None:
    """Bool ``[H, W]`` mask -> 0/255 PNG, atomically."""
    m = mask.detach().cpu().numpy() if isinstance(mask, Tensor) else np.asarray(mask)
    write_image_atomic(path, m.astype(bool))


def write_depth_atomic(path: PathLike, depth: Union[Tensor, np.ndarray]) -> None:
    """float32 ``[H, W]`` metres -> ``.npy``, atomically."""
    arr = depth.detach().cpu().numpy() if isinstance(depth, Tensor) else np.asarray(depth)
    path = Path(path)

    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            np.save(f, arr.astype(np.float32))

    _atomic_write(path, write)
