"""Undistortion and downscaling of a split's files, done once and cached in the dataset.

Why cache: the datamanagers (and every eval/augmentation pass) read plain pinhole images at the
training resolution with :func:`load_image`; undistorting or resizing on every read would be wasted
work and would make masks and images disagree on size.

Choices (documented for users):
  * **New camera matrix**: ``cv2.getOptimalNewCameraMatrix(alpha=0)`` at the same size: the output
    is zoomed so that every output pixel comes from inside the source image (no black borders),
    at the cost of cropping a few border pixels. The returned Cameras carry that K and zero
    distortion.
  * Images are remapped bilinearly; masks and depth with nearest neighbour (no invented labels or
    depths); borders replicate.
  * Downscaling happens after undistortion (area averaging, nearest for masks/depth), with the
    size rule of :func:`images.scaled_size`.
  * Pixel convention: ours (and nerfstudio's, COLMAP's) has the pixel centre at ``+0.5``; OpenCV's
    at ``0``. ``cx, cy`` are shifted by 0.5 on the way into and out of OpenCV.

Cache: ``<dataset>/.ns2gs_cache/`` (or ``$XDG_CACHE_HOME/nerf2gs/datasets/<hash>`` when the dataset is
read-only), or ``<cache dir>/<dataset name>-<hash>`` when a cache dir is set
(``--pipeline.datamanager.dataparser.cache-dir``, the parsers' ``cache_dir``, or ``$NS2GS_CACHE_DIR``). The first
file a command writes there prints where the cache is. A cached name depends on the source's path inside the dataset and the parameters only
(so a moved copy keeps names); a ``.src`` sidecar holds the source's size and mtime, and a stale
entry is rebuilt.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from nerf2gs_plugin.data import images as im
from nerf2gs_plugin.errors import DataError

CACHE_DIRNAME = ".ns2gs_cache"
CACHE_ENV = "NS2GS_CACHE_DIR"
_VERSION = "1"
_ANNOUNCED: set[Path] = set()


def cache_root(cache_dir: Optional[Path] = None) -> Optional[Path]:
    """The folder every dataset's processed files go under: ``cache_dir``, else ``$NS2GS_CACHE_DIR``,
    else None (next to the dataset)."""
    chosen = cache_dir if cache_dir is not None else os.environ.get(CACHE_ENV) or None
    return Path(chosen).expanduser().absolute() if chosen is not None else None


@dataclass
class Intrinsics:
    """One camera's raw intrinsics (our pixel convention) and OpenCV distortion (k1, k2, p1, p2, k3)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def distorted(self) -> bool:
        return any(abs(d) > 0 for d in self.dist)

    def K_cv(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx - 0.5], [0, self.fy, self.cy - 0.5], [0, 0, 1]], dtype=np.float64)


def undistorted_intrinsics(intr: Intrinsics) -> Intrinsics:
    """The pinhole camera the undistorted image has (alpha = 0, same size)."""
    if not intr.distorted:
        return intr
    K, _ = cv2.getOptimalNewCameraMatrix(intr.K_cv(), np.array(intr.dist, dtype=np.float64), (intr.width, intr.height), 0.0, (intr.width, intr.height))
    return Intrinsics(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]) + 0.5, float(K[1, 2]) + 0.5, intr.width, intr.height)


def output_intrinsics(intr: Intrinsics, downscale: float) -> Intrinsics:
    """Undistorted, then downscaled intrinsics: what the parser's Cameras hold."""
    u = undistorted_intrinsics(intr)
    if downscale == 1.0:
        return u
    w, h = im.scaled_size(u.width, u.height, downscale)
    sx, sy = w / u.width, h / u.height
    return Intrinsics(u.fx * sx, u.fy * sy, u.cx * sx, u.cy * sy, w, h)


def undistort_array(arr: np.ndarray, intr: Intrinsics, nearest: bool = False) -> np.ndarray:
    """Remap an ``[H, W(, C)]`` array taken by the distorted camera ``intr`` to its undistorted camera."""
    new = undistorted_intrinsics(intr)
    m1, m2 = cv2.initUndistortRectifyMap(intr.K_cv(), np.array(intr.dist, dtype=np.float64), None, new.K_cv(), (intr.width, intr.height), cv2.CV_32FC1)
    out = cv2.remap(arr, m1, m2, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if arr.ndim == 3 and out.ndim == 2:
        out = out[:, :, None]
    return out


class SplitCache:
    """Where a dataset's processed files go; see the module docstring."""

    def __init__(self, root: Path, cache_dir: Optional[Path] = None) -> None:
        self.root = Path(root).resolve()
        self.dir = self.root / CACHE_DIRNAME
        chosen = cache_root(cache_dir)
        if chosen is not None:
            self.dir = chosen / f"{self.root.name}-{hashlib.sha1(str(self.root).encode()).hexdigest()[:12]}"
            self.dir.mkdir(parents=True, exist_ok=True)
            return
        try:
            self.dir.mkdir(exist_ok=True)
            if not os.access(self.dir, os.W_OK):
                raise PermissionError
        except OSError:
            base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "nerf2gs" / "datasets"
            self.dir = base / hashlib.sha1(str(self.root).encode()).hexdigest()[:16]
            self.dir.mkdir(parents=True, exist_ok=True)

    def _name(self, src: Path, kind: str, params: str, suffix: str) -> Path:
        try:
            rel = str(src.resolve().relative_to(self.root))
        except ValueError:
            rel = str(src.resolve())
        key = hashlib.sha1(f"{_VERSION}|{kind}|{rel}|{params}".encode()).hexdigest()[:12]
        return self.dir / kind / f"{src.stem}_{key}{suffix}"

    def _announce(self) -> None:
        """Say once per command where undistorted / resized copies go (they can be large)."""
        if self.dir in _ANNOUNCED:
            return
        _ANNOUNCED.add(self.dir)
        import sys

        print(f"note: undistorted/resized copies of the dataset's images are cached in {self.dir} "
              f"(--pipeline.datamanager.dataparser.cache-dir DIR or ${CACHE_ENV} to put them elsewhere)",
              file=sys.stderr, flush=True)

    @staticmethod
    def _signature(src: Path) -> str:
        st = src.stat()
        return f"{st.st_size}:{st.st_mtime_ns}"

    def get(self, src: Path, kind: str, params: str, suffix: str, make) -> Path:
        """Cached file for ``src`` (built with ``make(src, dst)`` when missing or stale)."""
        if not src.is_file():
            raise DataError(f"{kind} file does not exist", src)
        dst = self._name(src, kind, params, suffix)
        side = dst.with_name(dst.name + ".src")
        sig = self._signature(src)
        if dst.is_file() and side.is_file() and side.read_text() == sig:
            return dst
        self._announce()
        make(src, dst)
        tmp = side.with_name(side.name + f".{os.getpid()}.tmp")
        tmp.write_text(sig)
        os.replace(tmp, side)
        return dst


def _params(intr: Intrinsics, downscale: float) -> str:
    return f"{intr.fx:.6f},{intr.fy:.6f},{intr.cx:.6f},{intr.cy:.6f},{intr.width}x{intr.height},{','.join(f'{d:.8f}' for d in intr.dist)},d{downscale:.6f}"


def _check_size(arr: np.ndarray, intr: Intrinsics, src: Path, what: str, image_path: Optional[Path] = None) -> None:
    if (arr.shape[1], arr.shape[0]) != (intr.width, intr.height):
        ref = f"its image {image_path.name} is" if image_path is not None else "the camera says"
        raise DataError(f"{what} is {arr.shape[1]}x{arr.shape[0]} but {ref} {intr.width}x{intr.height}", src)


def process_image(cache: SplitCache, src: Path, intr: Intrinsics, downscale: float) -> Path:
    """Undistorted (and downscaled) copy of an image; the source when nothing needs doing."""
    if not intr.distorted and downscale == 1.0:
        if not src.is_file():
            raise DataError("image file does not exist", src)
        return src
    out = output_intrinsics(intr, downscale)

    def make(s: Path, d: Path) -> None:
        rgb = im.decode_rgb(im.read_raw(s), s)
        _check_size(rgb, intr, s, "image")
        if intr.distorted:
            rgb = undistort_array(rgb, intr)
        im.write_image_atomic(d, im.resize(rgb, (out.width, out.height)))

    return cache.get(src, "images", _params(intr, downscale), ".png", make)


def process_mask(cache: SplitCache, src: Path, intr: Intrinsics, downscale: float, image_path: Path) -> Path:
    """Undistorted/downscaled copy of a mask (nearest); a wrong-size mask is a DataError."""
    if not intr.distorted and downscale == 1.0:
        if not src.is_file():
            raise DataError("mask file does not exist", src)
        return src
    out = output_intrinsics(intr, downscale)

    def make(s: Path, d: Path) -> None:
        m = im.read_raw(s, "mask")
        m = im.mask_channels(m) > 0
        _check_size(m, intr, s, "mask", image_path)
        m = m.astype(np.uint8) * 255
        if intr.distorted:
            m = undistort_array(m, intr, nearest=True)
        im.write_image_atomic(d, im.resize(m, (out.width, out.height), nearest=True) > 0)

    return cache.get(src, "masks", _params(intr, downscale), ".png", make)


def process_depth(cache: SplitCache, src: Path, intr: Intrinsics, downscale: float, image_path: Path, png_scale: float = 1e-3) -> Path:
    """Undistorted/downscaled ``.npy`` (metres) copy of a depth map (nearest); 16-bit PNG depth
    (nerfstudio style, times ``png_scale`` = metres) is always converted."""
    if not intr.distorted and downscale == 1.0 and src.suffix.lower() in (".npy", ".npz"):
        if not src.is_file():
            raise DataError("depth file does not exist", src)
        return src
    out = output_intrinsics(intr, downscale)

    def make(s: Path, d: Path) -> None:
        dep = im.load_depth(s, unit_scale=png_scale).numpy()
        _check_size(dep, intr, s, "depth", image_path)
        if intr.distorted:
            dep = undistort_array(dep, intr, nearest=True)
        im.write_depth_atomic(d, im.resize(dep, (out.width, out.height), nearest=True))

    return cache.get(src, "depth", _params(intr, downscale) + f",s{png_scale:g}", ".npy", make)
