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


Crop = tuple[float, float, float, float]
"""Shares of a frame cut off: top, bottom, left, right."""
NO_CROP: Crop = (0.0, 0.0, 0.0, 0.0)


def _fit(bgr: np.ndarray, max_size: int, crop: Crop = NO_CROP) -> np.ndarray:
    """``bgr`` cropped (shares of its sides), then shrunk to ``max_size`` on its longest side."""
    h, w = bgr.shape[:2]
    if any(crop):
        t, b, l, r = crop
        bgr = bgr[int(round(h * t)): h - int(round(h * b)), int(round(w * l)): w - int(round(w * r))]
        h, w = bgr.shape[:2]
    if max_size > 0 and max(h, w) > max_size:
        s = max_size / max(h, w)
        bgr = cv2.resize(bgr, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
    return bgr


def _cut_off(last: np.ndarray, prev: np.ndarray, index: int, declared: int) -> str:
    """Why the last decoded frame (``index``) of a video looks cut off, or "": the stream stopped before
    its header's frame count, or its bottom rows are exactly the previous frame's while those above
    differ (what a decoder leaves where the data ran out; a constant bar, e.g. letterboxing, is not)."""
    if declared and index + 1 < declared:
        return f"it ends after {index + 1} of the {declared} frames its header declares"
    if last.shape != prev.shape:
        return ""
    rows = (last == prev).reshape(last.shape[0], -1).all(axis=1)
    if rows.all():
        return ""  # a repeated frame
    same = last.shape[0] - int(np.flatnonzero(~rows)[-1]) - 1  # identical rows at the bottom
    tail = last[last.shape[0] - same:]
    if same >= max(8, last.shape[0] // 16) and float(tail.std()) > 2.0:
        return f"the bottom {same} rows of its last frame are the previous frame's"
    return ""


@dataclass
class FrameReport:
    names: list[str]
    candidates: int  # frames considered (video: windows; images: files)
    dropped_blurry: int
    video_frames: int = 0
    video_fps: float = 0.0
    dropped_repeats: int = 0  # video: a window's frame that repeats the frame kept before it


REPEAT_GREY = 0.5
"""A video frame whose 1/8-size grey image differs from the last frame kept by less than this (mean absolute, grey
levels) repeats it and is dropped: a frame-rate conversion's copies (0) or a stop with nothing moving (sensor
noise, about 0.3). Frames of a drive differ by 10-50, a stop with people crossing by 7 or more, a car creeping at
2 Hz key frames by 1.2 or more. A copy shows nothing new and costs the SfM and every stage after it a frame."""


def _thumb(bgr: np.ndarray) -> np.ndarray:
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    return cv2.resize(grey, (max(1, grey.shape[1] // 8), max(1, grey.shape[0] // 8)), interpolation=cv2.INTER_AREA)


def extract_video_frames(video: Path, out_dir: Path, fps: Optional[float], num_frames: Optional[int], blur_ratio: float,
                         max_size: int, ext: str = ".jpg", progress=None, crop: Crop = NO_CROP) -> FrameReport:
    """One frame per window of ``video_fps / fps`` (or ``total / num_frames``) frames, the sharpest
    of its window unless it repeats the frame kept before it (:data:`REPEAT_GREY`); then
    :func:`relative_blur_drop`. Writes ``frame_<index>.<ext>`` into ``out_dir`` (cropped by ``crop`` and
    shrunk to ``max_size``)."""
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
    last: Optional[np.ndarray] = None  # the thumbnail of the last frame kept
    repeats = 0

    def keep_best() -> None:
        nonlocal last, repeats
        thumb = _thumb(best[2])
        if last is not None and float(np.abs(thumb - last).mean()) < REPEAT_GREY:
            repeats += 1
            return
        last = thumb
        picked.append((best[1], best[0]))
        _write_atomic(out_dir / f"frame_{best[1]:06d}{ext}", _fit(best[2], max_size, crop), 95)

    known = total < (1 << 31)
    window, i, frame, prev = 0, 0, first, first
    while frame is not None:
        # read one ahead: the last frame of a cut-off file is decoded only down to the cut, the rest
        # left as the previous frame's pixels (a chimera the SfM cannot place: it retried the mapping
        # for minutes), so it is dropped
        ok, ahead = cap.read()
        ahead = ahead if ok else None
        if ahead is None and i > 0:
            why = _cut_off(frame, prev, i, total if known else 0)
            if why:
                from nerf2gs_plugin.warn import warn

                warn(f"{video} is truncated ({why})", f"its last frame (index {i}) is half-decoded and dropped")
                break
        prev = frame
        w = int(i // step)
        if w != window and best[2] is not None:
            keep_best()
            best = (-1.0, -1, None)
        window = w
        s = sharpness(frame)
        if s > best[0]:
            best = (s, i, frame)
        if task is not None:
            progress.update(task, advance=1, stats=f"{len(picked)} frames kept")
        i += 1
        frame = ahead
    cap.release()
    if best[2] is not None:
        keep_best()
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
    return FrameReport(names, len(picked), int((~keep).sum()), i, vfps, repeats)


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def list_images(folder: Path) -> list[Path]:
    """JPEG/PNG files directly in ``folder``, in natural name order (``img2`` before ``img10``)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError("image folder does not exist", folder)
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTS and not p.name.startswith(".")]
    return sorted(files, key=lambda p: _natural_key(p.name))


SOURCES_SUFFIX = ".sources.json"
"""Beside the frames folder: each copied photo's source content hash, --max-size and frame size."""


def collect_images(folder: Path, out_dir: Path, max_size: int, progress=None, crop: Crop = NO_CROP) -> FrameReport:
    """Copy (or, above ``max_size`` or with a ``crop``, crop and shrink) every readable image of ``folder`` into ``out_dir``.

    A frame is reused only when its photo's content (hash), ``max_size`` and ``crop`` are those it was made from:
    a photo replaced under the same name is copied again. Unreadable photos are named in a warning;
    photos of more than one size are an error (:func:`check_one_size`)."""
    import json

    from nerf2gs_plugin.data.fingerprint import file_sha1
    from nerf2gs_plugin.utils.io import atomic_write_text

    files = list_images(folder)
    out_dir.mkdir(parents=True, exist_ok=True)
    record_path = out_dir.with_name(out_dir.name + SOURCES_SUFFIX)
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError):
        record = {}
    names: list[str] = []
    unreadable: list[str] = []
    sizes: dict[str, tuple[int, int]] = {}
    done: dict[str, list] = {}
    task = progress.add_task("frames: collect images", total=len(files), stats="") if progress else None
    for p in files:
        dst = out_dir / p.name
        try:
            digest = file_sha1(p)
        except OSError:  # no read permission: as unreadable as a broken file
            digest = None
        old = record.get(p.name)
        made = [digest, max_size] + ([list(crop)] if any(crop) else [])
        if digest is not None and dst.is_file() and isinstance(old, list) and len(old) == len(made) + 2 and old[:-2] == made:
            sizes[p.name] = (int(old[-2]), int(old[-1]))
        else:
            head = cv2.imread(str(p), cv2.IMREAD_COLOR) if digest is not None else None
            if head is None:
                unreadable.append(p.name)
                if task is not None:
                    progress.update(task, advance=1, stats=f"{len(unreadable)} unreadable")
                continue
            if any(crop) or (max_size > 0 and max(head.shape[:2]) > max_size):
                head = _fit(head, max_size, crop)
                _write_atomic(dst, head, 95)
            else:
                tmp = dst.with_name(f".{dst.name}.tmp")
                shutil.copyfile(p, tmp)
                os.replace(tmp, dst)
            sizes[p.name] = (int(head.shape[1]), int(head.shape[0]))
        done[p.name] = [*made, *sizes[p.name]]
        names.append(p.name)
        if task is not None:
            progress.update(task, advance=1, stats=f"{len(unreadable)} unreadable" if unreadable else "")
    atomic_write_text(record_path, json.dumps(done, indent=0))
    if unreadable:
        from nerf2gs_plugin.warn import warn

        shown = ", ".join(unreadable[:10]) + (f" and {len(unreadable) - 10} more" if len(unreadable) > 10 else "")
        warn(f"{len(unreadable)} unreadable photos skipped: {shown}", f"not JPEG/PNG images OpenCV decodes (in {folder})")
    if len(names) < MIN_FRAMES:
        raise DataError(f"too few images: {len(names)} readable JPEG/PNG files (need at least {MIN_FRAMES})", folder)
    check_one_size(sizes, folder)
    return FrameReport(names, len(files), 0)


def check_one_size(sizes: dict[str, tuple[int, int]], folder: Path) -> None:
    """Photos of more than one frame size: a :class:`DataError` naming the sizes. The SfM gives the whole
    capture one camera (one focal prior, steadier mapping), and COLMAP's single-camera reader refuses an
    image of another size, so those photos never registered and the error blamed the matching."""
    by_size: dict[tuple[int, int], list[str]] = {}
    for name, wh in sizes.items():
        by_size.setdefault(wh, []).append(name)
    if len(by_size) < 2:
        return
    groups = sorted(by_size.items(), key=lambda kv: -len(kv[1]))
    parts = [f"{len(n)} of {w}x{h} ({', '.join(n) if len(n) <= 2 else n[0] + ', ...'})" for (w, h), n in groups]
    raise DataError(f"photos of {len(groups)} sizes: {', '.join(parts)}; the SfM shares one camera between all photos, so "
                    "process each size as its own capture, or bring them to one size (a rotated photo: rotate it back)", folder)


def video_size_hint(video: Path, fps: Optional[float], num_frames: Optional[int], max_size: int) -> tuple[int, float]:
    """(frames, bytes per frame) a video will give, about (JPEG at ~1 byte per pixel); (0, 0) when
    OpenCV cannot open it (the frame stage then says so)."""
    cap = cv2.VideoCapture(str(video))
    try:
        if not cap.isOpened():
            return 0, 0.0
        w, h = cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)
        vfps, total = cap.get(cv2.CAP_PROP_FPS) or 30.0, max(cap.get(cv2.CAP_PROP_FRAME_COUNT), 0)
    finally:
        cap.release()
    n = num_frames if num_frames else total / vfps * (fps or 2.0)
    s = min(1.0, max_size / max(w, h, 1)) if max_size > 0 else 1.0
    return int(min(n, total)), float(w * h * s * s)


def images_size_hint(files: list[Path], max_size: int) -> tuple[int, float]:
    """(frames, bytes per frame) a photo folder will give, about (a shrunk photo: ~1 byte per pixel as JPEG, 3 as PNG)."""
    if not files:
        return 0, 0.0
    sizes = []
    for p in files:
        size = p.stat().st_size
        if max_size > 0:
            size = min(size, int(max_size * max_size * 0.75 * (3 if p.suffix.lower() == ".png" else 1)))
        sizes.append(size)
    return len(files), float(sum(sizes)) / len(files)
