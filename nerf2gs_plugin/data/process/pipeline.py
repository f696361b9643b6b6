"""The ``ns2gs-data process`` pipeline: stages in order, each timed, reported and resumable."""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Optional

import numpy as np
import tyro

from nerf2gs_plugin.data.process.capture_check import cut_to_consistent, deregister
from nerf2gs_plugin.data.process.sfm import SfmOptions
from nerf2gs_plugin.utils.io import atomic_write_text

TIMES_FILE = "stage_seconds.json"
"""In ``DATA/colmap/``: each stage's time of the last ``process`` run."""
from nerf2gs_plugin.errors import DataError


@dataclass
class ProcessOptions:
    """Options shared by ``process images`` and ``process video``."""

    out: Path = Path("data/capture")
    """Output dataset folder (re-running reuses finished stages)."""
    sfm: tyro.conf.OmitArgPrefixes[SfmOptions] = field(default_factory=SfmOptions)
    camera_height: float = 1.5
    """Camera height above the road in metres (1.5: car-mounted; ~1.6 for a hand-held walk): sets the metric scale."""
    metres_per_unit: Optional[float] = None
    """Metres per SfM unit, when known (skips the camera-height scale; the ground plane still gives up)."""
    fov_deg: Optional[float] = None
    """Horizontal field of view of the camera in degrees, when known (a dashcam's spec, e.g. 90-120): the
    focal prior for the SfM (photos use their EXIF focal; without either COLMAP guesses ~45 deg and refines)."""
    max_size: int = 1600
    """Frames larger than this (longest side, px) are shrunk before the SfM (0: keep)."""
    crop_factor: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    """Share of each frame cut off before the SfM: top, bottom, left, right (as nerfstudio's). A dashcam that sees
    its bonnet: 0 0.15 0 0 (the bonnet moves with the camera, so the masks mark it as moving)."""
    min_registered_fraction: float = 0.5
    """Fewer registered frames than this fraction is an error."""
    broken_join: Literal["drop", "keep"] = "drop"
    """A reconstruction the capture check finds broken (SfM joined two stretches of the capture at different
    scales or in the wrong place): drop keeps the longest consistent stretch (up to 3 cuts) and drops the
    other frames, as COLMAP keeps its largest model; keep keeps every frame (the warning only)."""
    standing: Literal["drop", "keep"] = "keep"
    """Frames of a video (or sequential photos) where the camera stood still (a red light): drop keeps the
    first of each stop (the others repeat its view: training draws it as often); keep keeps them all (what
    crosses in front of a standing camera shows the street behind it)."""
    progress: bool = True

    @property
    def kept_width(self) -> float:
        """The share of each frame's width that --crop-factor keeps (focal priors are the uncropped frame's)."""
        return 1.0 - self.crop_factor[2] - self.crop_factor[3]


@dataclass
class ProcessReport:
    out: Path
    frames: int
    registered: int
    points: int
    matching: str
    metres_per_unit: float
    scale_source: str
    stage_seconds: dict[str, float]
    dropped_blurry: int = 0
    check: str = ""
    """The capture check's line (:func:`~.capture_check.check_reconstruction`)."""
    dropped_repeats: int = 0

    def lines(self) -> list[str]:
        t = ", ".join(f"{k} {v:.1f} s" for k, v in self.stage_seconds.items())
        return [
            f"registered {self.registered} of {self.frames} frames ({100.0 * self.registered / max(self.frames, 1):.0f}%), "
            f"{self.points} sparse points, matching {self.matching}"
            + (f"; {self.dropped_blurry} blurry frames dropped" if self.dropped_blurry else "")
            + (f"; {self.dropped_repeats} frames dropped that repeat the one before" if self.dropped_repeats else ""),
            f"metric scale: {self.metres_per_unit:.4g} metres per SfM unit ({self.scale_source}); stored in transforms.json",
            *([self.check] if self.check else []),
            f"time per stage: {t}",
            f"dataset: {self.out} (train with: ns2gs-train streetnerf --data {self.out})",
        ]


def check_options(opts: ProcessOptions) -> None:
    """Flags checked before anything is read or written."""
    from nerf2gs_plugin.errors import ConfigError

    if opts.fov_deg is not None and not 1.0 < opts.fov_deg < 179.0:
        raise ConfigError(f"--fov-deg must be in (1, 179), got {opts.fov_deg}", "--fov-deg")
    t, b, l, r = opts.crop_factor
    if not all(0.0 <= c < 1.0 for c in opts.crop_factor) or t + b > 0.9 or l + r > 0.9:
        raise ConfigError("--crop-factor: four shares of the frame (top bottom left right), each in [0, 1), at most 0.9 "
                          f"of the height (top + bottom) and of the width (left + right), got {' '.join(f'{c:g}' for c in opts.crop_factor)}",
                          "--crop-factor")


def run_process(frames_fn, opts: ProcessOptions, is_video: bool, focal_px_fn=None, size_hint: tuple[int, float] = (0, 0.0)) -> ProcessReport:
    """``frames_fn(frame_dir, progress) -> FrameReport`` makes the frames; the rest is shared. ``size_hint``:
    (frames, bytes per frame) expected, for the free-space check (:mod:`.output`)."""
    from nerf2gs_plugin.data.process import sfm
    from nerf2gs_plugin.data.process.output import LOGS, claimed_output, estimate_bytes, expected_pairs, silence_colmap
    from nerf2gs_plugin.progress import make_progress

    check_options(opts)
    root = Path(opts.out)
    frames_n, frame_bytes = size_hint
    pairs = expected_pairs(frames_n, sfm.choose_matching(opts.sfm, frames_n, is_video), opts.sfm)
    with claimed_output(root, estimate_bytes(frames_n, frame_bytes, opts.sfm.max_features, pairs)) as claim:
        frame_dir = claim.work / "frames"
        times: dict[str, float] = {}
        with make_progress(enabled=opts.progress) as progress:
            t = time.perf_counter()
            fr = frames_fn(frame_dir, progress)
            times["frames"] = time.perf_counter() - t
            claim.keep()  # frames made and checked: worth resuming from here on
            silence_colmap(claim.work / LOGS)
            for p in frame_dir.iterdir():  # frames of an earlier run with other options
                if p.is_file() and p.name not in set(fr.names):
                    p.unlink()
            method, mapped = _sfm_stages(claim.work, fr.names, opts, is_video, focal_px_fn, progress, times)
            if mapped.registered < opts.min_registered_fraction * len(fr.names):
                raise DataError(f"registration failed: only {mapped.registered} of {len(fr.names)} frames registered (fewer than "
                                f"{opts.min_registered_fraction:.0%}); try {'' if method == 'exhaustive' else '--matching exhaustive, '}"
                                "more overlap, or less blur", root)
            scale, check_line = _export_stages(root, mapped, method, len(fr.names), opts, is_video, progress, times)
    return ProcessReport(root, len(fr.names), mapped.registered, mapped.points, method, scale.metres_per_unit, scale.source, times,
                         fr.dropped_blurry, check_line, fr.dropped_repeats)


def _sfm_stages(work: Path, names: list[str], opts: ProcessOptions, is_video: bool, focal_px_fn, progress, times: dict):
    """Features, matching and mapping of the frames in ``work/frames``, each reused only for the same
    frame content: (matching method, :class:`~.sfm.MapResult`)."""
    from nerf2gs_plugin.data.process import sfm
    from nerf2gs_plugin.data.process.output import LOGS
    from nerf2gs_plugin.data.process.sfm_worker import run_sfm_stages

    frame_dir = work / "frames"
    hashes = frame_hashes(frame_dir, names)
    content = sfm.content_key(hashes)
    focal = focal_px_fn(frame_dir, names) if focal_px_fn else None
    if opts.fov_deg is not None:
        from nerf2gs_plugin.data.images import image_size

        focal = 0.5 * image_size(frame_dir / names[0])[0] / opts.kept_width / np.tan(np.radians(opts.fov_deg) / 2)
    method = sfm.choose_matching(opts.sfm, len(names), is_video)
    mapped, stage_times = run_sfm_stages(work, names, opts.sfm, focal, hashes, content, method, work / LOGS, progress,
                                         check=opts, ordered=is_video or method == "sequential")
    times.update(stage_times)
    return method, mapped


def _export_stages(root: Path, mapped, method: str, frames: int, opts: ProcessOptions, is_video: bool, progress, times: dict):
    """Undistortion and the dataset layout (:mod:`.export`) with the capture check: (metric scale, check line)."""
    import pycolmap

    from nerf2gs_plugin.data.process import export

    work = root / "colmap"
    t = time.perf_counter()
    und = export.undistort(mapped.model_dir, work / "frames", work / "undistorted", progress)
    export.install_images(und / "images", root)
    dst = root / "sparse" / "0"
    shutil.rmtree(dst, ignore_errors=True)
    dst.parent.mkdir(parents=True, exist_ok=True)
    os.replace(und / "sparse", dst)
    shutil.rmtree(und, ignore_errors=True)  # the images left there are those already in place
    times["undistort"] = time.perf_counter() - t
    t = time.perf_counter()
    rec = pycolmap.Reconstruction(str(root / "sparse" / "0"))
    reg_names, c2w, scale, check = checked_reconstruction(root, rec, opts, is_video or method == "sequential", frames)
    check_line = check.pop("line")
    export.write_downscaled(root, reg_names, progress)
    times["export"] = time.perf_counter() - t
    extra = {"process": {"source": "video" if is_video else "images", "frames": frames, "registered": mapped.registered,
                         "kept": len(reg_names),
                         "matching": method, "camera_height_m": opts.camera_height, "scale_source": scale.source,
                         "capture_check": check, **({"crop_factor": list(opts.crop_factor)} if any(opts.crop_factor) else {})}}
    if scale.plane is not None:
        extra["ground_plane"] = scale.plane.to_json()
    export.write_transforms(root, rec, scale.metres_per_unit, scale.up, extra)
    # beside, not in, transforms.json: runs fingerprint the files they read, and times change every run
    atomic_write_text(work / TIMES_FILE, json.dumps({k: round(v, 2) for k, v in times.items()}, indent=1))
    return scale, check_line


def frame_hashes(frame_dir: Path, names: list[str]) -> dict[str, str]:
    """Content hash of each frame: the SfM stages reuse their work only for the same content."""
    from nerf2gs_plugin.data.fingerprint import file_sha1

    return {n: file_sha1(frame_dir / n) for n in names}


def checked_reconstruction(root: Path, rec, opts: ProcessOptions, ordered: bool, frames: int):
    """(names, c2w, metric scale, capture check) of the undistorted model ``rec`` (in ``root/sparse/0``),
    without the frames where an ordered capture's camera stood (``--standing drop``), after ``--broken-join
    drop`` kept its longest consistent stretch (both written back over ``root``)."""
    from nerf2gs_plugin.data.process import model_arrays
    from nerf2gs_plugin.data.process.scale_check import standing_frames
    from nerf2gs_plugin.warn import warn

    standing: list[str] = []
    if ordered and opts.standing == "drop":
        names, c2w, _ = model_arrays.camera_arrays(rec)
        standing = standing_frames(c2w, names)
        deregister(rec, set(standing))
    names, c2w, scale, check, dropped = cut_to_consistent(rec, opts, ordered)
    if dropped:
        _check_kept(root, len(names), frames - len(standing), opts.min_registered_fraction)
        warn(f"kept the longest consistent stretch of the broken reconstruction: {len(names)} of {frames - len(standing)} frames",
             f"dropped {len(dropped)} ({min(dropped)} .. {max(dropped)}); --broken-join keep keeps them", stacklevel=2)
        check["line"] += f"; kept the longest consistent stretch, {len(names)} frames ({len(dropped)} dropped)"
    if standing:
        check["line"] += f"; {len(standing)} frames where the camera stood dropped (--standing drop)"
    if dropped or standing:
        _write_kept(root, rec, dropped + standing)
    check["dropped"] = sorted(dropped)
    check["standing"] = sorted(standing)
    return names, c2w, scale, check


def _check_kept(root: Path, kept: int, frames: int, min_fraction: float) -> None:
    """An error when the longest consistent stretch holds fewer than ``min_fraction`` of the frames."""
    if kept < min_fraction * frames:
        raise DataError(f"the reconstruction is broken (see the capture check above) and its longest consistent stretch holds only "
                        f"{kept} of {frames} frames (fewer than {min_fraction:.0%}): process the stretches separately, or pass "
                        "--broken-join keep to keep every frame", root)


def _write_kept(root: Path, rec, removed: list[str]) -> None:
    """Write the cut reconstruction over ``root/sparse/0`` (temp folder, then renamed) and remove the
    ``removed`` frames' images."""
    tmp = root / "sparse" / "0.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    rec.write(str(tmp))
    shutil.rmtree(root / "sparse" / "0")
    os.replace(tmp, root / "sparse" / "0")
    for n in removed:
        (root / "images" / n).unlink(missing_ok=True)


def exif_focal_for(sources: list[Path], frame_dir: Path, names: list[str], crop_width: float = 1.0) -> Optional[float]:
    """The shared EXIF focal (px, at the copied frames' size) when the first photos agree on one; ``crop_width``:
    the share of each photo's width the frames keep (--crop-factor)."""
    from nerf2gs_plugin.data.images import image_size
    from nerf2gs_plugin.data.process.exif import exif_focal_px

    by_name = {p.name: p for p in sources}
    vals = []
    for n in names[:5]:
        src = by_name.get(n)
        if src is None:
            return None
        w, h = image_size(src)
        f = exif_focal_px(src, w, h)
        if f is None:
            return None
        vals.append(f * image_size(frame_dir / n)[0] / (w * crop_width))
    return float(np.median(vals)) if vals else None


ProcessKind = Literal["images", "video"]
