"""Stage 1: the frames the SfM sees. A video is decoded once (OpenCV): one frame per time window,
the sharpest of its window, then frames much blurrier than their neighbours are dropped; a photo
folder is copied in name order. Written atomically; file names keep the capture order.
"""

from __future__ import annotations

import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from nerf2gs_plugin.errors import DataError

IMAGE_EXTS = (".jpg", ".jpeg", ".png")
MIN_FRAMES = 5


def sharpness(bgr: np.ndarray, width: int = 320) -> float:
    """Variance of the Laplacian of the grey image at ~``width`` px (scale-stable, cheap)."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY) if bgr.ndim == 3 else bgr
    if grey.shape[1] > width:
        grey = cv2.resize(grey, (width, max(1, round(grey.shape[0] * width / grey.shape[1]))), interpolation=cv2.INTER_AREA)
    return float(cv2.Laplacian(grey, cv2.CV_64F).var())


def relative_blur_drop(scores: np.ndarray, ratio: float, radius: int = 3) -> np.ndarray:
    """Bool keep-mask: a frame is dropped when its sharpness is below ``ratio`` x the median of its
    ``radius`` neighbours on each side (relative, so a dark or low-texture scene is not all dropped)."""
    n = len(scores)
    if n == 0 or ratio <= 0:
        return np.ones(n, dtype=bool)
    idx = np.arange(n)[:, None] + np.arange(-radius, radius + 1)[None]
    valid = (idx >= 0) & (idx < n) & (idx != np.arange(n)[:, None])
    neigh = np.where(valid, scores[np.clip(idx, 0, n - 1)], np.nan)
    med = np.nanmedian(neigh, axis=1) if n > 1 else scores
    return ~(scores < ratio * np.nan_to_num(med, nan=0.0))


def _write_atomic(path: Path, bgr: np.ndarray, jpeg_quality: int) -> None:
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if path.suffix == ".jpg" else []
    if not cv2.imwrite(str(tmp), bgr, params):
        raise DataError("cannot write frame", path)
    os.replace(tmp, path)


def _fit(bgr: np.ndarray, max_size: int) -> np.ndarray:
    h, w = bgr.shape[:2]
    if max_size > 0 and max(h, w) > max_size:
        s = max_size / max(h, w)
        bgr = cv2.resize(bgr, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
    return bgr


@dataclass
class FrameReport:
    names: list[str]
    candidates: int  # frames considered (video: windows; images: files)
    dropped_blurry: int
    video_frames: int = 0
    video_fps: float = 0.0


def extract_video_frames(video: Path, out_dir: Path, fps: Optional[float], num_frames: Optional[int], blur_ratio: float,
                         max_size: int, ext: str = ".jpg", progress=None) -> FrameReport:
    """One frame per window of ``video_fps / fps`` (or ``total / num_frames``) frames, the sharpest
    of its window; then :func:`relative_blur_drop`. Writes ``frame_<index>.<ext>`` into ``out_dir``."""
    video = Path(video)
    if not video.is_file():
        raise DataError("video file does not exist", video)
    cap = cv2.VideoCapture(str(video))
    ok, first = cap.read() if cap.isOpened() else (False, None)
    if not ok or first is None:
        cap.release()
        raise DataError("cannot read video (not a video file, or a codec OpenCV lacks)", video)
    vfps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
    total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    if total <= 0:
        total = 1 << 31  # unknown: windows by fps only
    if num_frames is not None and num_frames > 0 and total < (1 << 31):
        step = max(1.0, total / num_frames)
    else:
        step = max(1.0, vfps / fps) if fps and fps > 0 else max(1.0, vfps / 2.0)
    out_dir.mkdir(parents=True, exist_ok=True)
    task = progress.add_task("frames: decode + pick sharpest", total=total if total < (1 << 31) else None, stats="") if progress else None
    picked: list[tuple[int, float]] = []  # (frame index, sharpness)
    best: tuple[float, int, Optional[np.ndarray]] = (-1.0, -1, None)
    window, i, frame = 0, 0, first
    while frame is not None:
        w = int(i // step)
        if w != window and best[2] is not None:
            picked.append((best[1], best[0]))
            _write_atomic(out_dir / f"frame_{best[1]:06d}{ext}", _fit(best[2], max_size), 95)
            best = (-1.0, -1, None)
        window = w
        s = sharpness(frame)
        if s > best[0]:
            best = (s, i, frame)
        if task is not None:
            progress.update(task, advance=1, stats=f"{len(picked)} frames kept")
        i += 1
        ok, frame = cap.read()
        if not ok:
            frame = None
    cap.release()
    if best[2] is not None:
        picked.append((best[1], best[0]))
        _write_atomic(out_dir / f"frame_{best[1]:06d}{ext}", _fit(best[2], max_size), 95)
    if task is not None:
        progress.update(task, total=i, completed=i)
    keep = relative_blur_drop(np.array([s for _, s in picked]), blur_ratio)
    names = []
    for (idx, _), k in zip(picked, keep):
        name = f"frame_{idx:06d}{ext}"
        if k:
            names.append(name)
        else:
            (out_dir / name).unlink(missing_ok=True)
    if len(names) < MIN_FRAMES:
        raise DataError(f"too few frames: {len(names)} usable of {i} decoded (need at least {MIN_FRAMES}; "
                        "raise --num-frames/--fps or lower --blur-ratio)", video)
    return FrameReport(names, len(picked), int((~keep).sum()), i, vfps)


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def list_images(folder: Path) -> list[Path]:
    """JPEG/PNG files directly in ``folder``, in natural name order (``img2`` before ``img10``)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError("image folder does not exist", folder)
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTS and not p.name.startswith(".")]
    return sorted(files, key=lambda p: _natural_key(p.name))


def collect_images(folder: Path, out_dir: Path, max_size: int, progress=None) -> FrameReport:
    """Copy (or, above ``max_size``, shrink) every readable image of ``folder`` into ``out_dir``."""
    files = list_images(folder)
    out_dir.mkdir(parents=True, exist_ok=True)
    names: list[str] = []
    unreadable = 0
    task = progress.add_task("frames: collect images", total=len(files), stats="") if progress else None
    for p in files:
        dst = out_dir / p.name
        if not dst.is_file():
            head = cv2.imread(str(p), cv2.IMREAD_COLOR)
            if head is None:
                unreadable += 1
                if task is not None:
                    progress.update(task, advance=1)
                continue
            if max_size > 0 and max(head.shape[:2]) > max_size:
                _write_atomic(dst, _fit(head, max_size), 95)
            else:
                tmp = dst.with_name(f".{dst.name}.tmp")
                shutil.copyfile(p, tmp)
                os.replace(tmp, dst)
        names.append(p.name)
        if task is not None:
            progress.update(task, advance=1, stats=f"{unreadable} unreadable" if unreadable else "")
    if len(names) < MIN_FRAMES:
        raise DataError(f"too few images: {len(names)} readable JPEG/PNG files (need at least {MIN_FRAMES})", folder)
    return FrameReport(names, len(files), 0)
