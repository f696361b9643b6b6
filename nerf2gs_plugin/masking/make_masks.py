"""``ns2gs-data masks DATA --segmenter auto|onnx:PATH``: write ``masks/{sky,ground,transient}/<image>.png``
for every frame of a dataset, the layout the parsers already read, so StreetNeRF's sky, ground and
transient terms and the augmentation's composites work on real captures unchanged.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional

import torch
import torch.nn.functional as F
import tyro

from nerf2gs_plugin.masks.motion import MotionOptions
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.masks.auto import AutoOptions
from nerf2gs_plugin.masks.maskless import maskless_view, strip_mask_keys
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_plugin.utils.io import atomic_write_text, remove_dead_staging


@dataclass
class MasksConfig:
    """Estimate sky / ground / transient masks for a dataset (a real capture has none)."""

    data: tyro.conf.Positional[Path]
    """Dataset folder (transforms.json or a COLMAP model)."""
    segmenter: str = "auto"
    """"auto": from the capture itself through a first reference NeRF trained without masks (no
    weights needed); "onnx:PATH": an ONNX semantic-segmentation model (see --class-map)."""
    class_map: Optional[str] = None
    """onnx: "cityscapes", "ade20k" or a JSON file {sky|ground|transient: [class ids or names]};
    default: from the model's metadata or its class count (19 / 150)."""
    reference: Optional[Path] = None
    """auto: the reference run (directory or .ckpt); trained here when absent
    (default outputs/<dataset>/masks-reference)."""
    reference_steps: int = 1000
    """auto: training steps of a new reference."""
    downscale: float = 1.0
    """auto: image downscale of a new reference (renders are upsampled to the image size)."""
    render_downscale: int = 2
    """auto: the reference renders every d-th pixel per side of each frame for the mask maths (d^2 fewer
    rays; the masks are upsampled to the image size; the motion route measures flow on the full-size
    frames with the renders upsampled). At 2 the masks held on two synthetic streets and KITTI's labelled
    frames (docs/speed.md); 1: every pixel."""
    auto: AutoOptions = field(default_factory=AutoOptions)
    motion: MotionOptions = field(default_factory=MotionOptions)
    """auto: moving objects from optical flow against the static scene's (docs/masks-motion.md)."""
    splits: tuple[str, ...] = ()
    """Only these splits (default: every split; "train" is what StreetNeRF's mask terms use)."""
    overwrite: bool = False
    """Replace masks that already exist."""
    progress: bool = True


def _with_neighbours(data: Path, groups: dict, all_groups: dict, motion: MotionOptions, log: Callable[[str], None]) -> list[str]:
    """The splits the auto route computes: ``groups``' and, on a sequence the motion route runs on, "train" as
    well. The route compares each frame with its neighbours in the video; held-out frames alone (every 8th)
    are seconds apart, and their masks would come from those gaps. Only ``groups``' masks are written; the
    held-out frames never become the training frames' neighbours unless asked for."""
    from nerf2gs_plugin.masks.motion import is_sequence

    names = list(groups)
    if "train" in names or "train" not in all_groups or not motion.enabled:
        return names
    meta = json.loads((data / "transforms.json").read_text()) if (data / "transforms.json").is_file() else {}
    if motion.sequences_only and not is_sequence(meta):
        return names
    log(f"masks: {', '.join(names)} with the training frames as the motion route's neighbours (their masks are not written)")
    return ["train", *names]


def _parser_groups(data: Path):
    """Every split's raw frames (original image paths, sizes, distortion), as the parser lists them."""
    from nerf2gs_plugin.data import dataparser_config

    return dataparser_config(data).raw_frames()


def _existing_masks(data: Path, groups) -> list[str]:
    found = [k for k in MASK_KINDS if (data / "masks" / k).is_dir() and any((data / "masks" / k).iterdir())]
    meta = data / "transforms.json"
    if meta.is_file() and any(f"{k}_mask_path" in meta.read_text() for k in MASK_KINDS):
        found.append("transforms.json mask paths")
    return found


def _write(data: Path, image: Path, masks: dict[str, torch.Tensor], size: tuple[int, int]) -> None:
    """Masks at any resolution -> PNGs at the image's ``(w, h)`` (nearest)."""
    from nerf2gs_plugin.data.images import write_mask_atomic

    w, h = size
    for kind, m in masks.items():
        if tuple(m.shape) != (h, w):
            m = F.interpolate(m.float()[None, None], size=(h, w), mode="nearest")[0, 0] > 0.5
        write_mask_atomic(data / "masks" / kind / f"{image.stem}.png", m)


def make_masks(cfg: MasksConfig, log: Callable[[str], None] = print) -> dict:
    """Write the masks; returns a summary (also written to ``DATA/masks/masks.json``)."""
    data = Path(cfg.data)
    if not data.is_dir():
        raise DataError("dataset folder does not exist", data)
    t0 = time.perf_counter()
    groups = all_groups = _parser_groups(data)
    if cfg.splits:
        unknown = [s for s in cfg.splits if s not in groups]
        if unknown:
            raise ConfigError(f"--splits: unknown split '{unknown[0]}' (this dataset has: {', '.join(groups)})")
        groups = {s: groups[s] for s in groups if s in cfg.splits}
    existing = _existing_masks(data, groups)
    if existing and not cfg.overwrite:
        raise ConfigError(f"the dataset already has masks ({', '.join(existing)}); pass --overwrite to replace them", data / "masks")
    frames, seen = [], set()
    for split, fs in groups.items():
        for f in fs:
            if f.image.resolve() not in seen:
                seen.add(f.image.resolve())
                frames.append((split, f))
    stems = [f.image.stem for _, f in frames]
    if len(set(stems)) != len(stems):
        dup = next(s for s in stems if stems.count(s) > 1)
        raise DataError(f"two images share the file name stem '{dup}'; masks/<kind>/<stem>.png would collide", data)
    if cfg.overwrite:
        strip_mask_keys(data)
    summary: dict = {"segmenter": cfg.segmenter, "images": len(frames)}
    coverage = {k: [0, 0] for k in MASK_KINDS}

    def count(ms: dict[str, torch.Tensor]) -> None:
        for k, m in ms.items():
            coverage[k][0] += int(m.sum())
            coverage[k][1] += m.numel()

    # every mask goes to a staging folder first and into masks/ only once all of them are made: a
    # bad image or model halfway leaves no partial set (that a re-run would call "already has masks")
    staging = data / f".masks-{os.getpid()}.tmp"
    shutil.rmtree(staging, ignore_errors=True)
    stale = remove_dead_staging(data, ".masks-")
    if stale:
        log(f"removed {len(stale)} staging folder(s) left in {data} by a masks run that was killed")
    try:
        _segment(cfg, data, frames, groups, staging, summary, count, log, all_groups)
        _install(staging / "masks", data / "masks")
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    summary["coverage"] = {k: round(a / b, 4) if b else 0.0 for k, (a, b) in coverage.items()}
    summary["seconds"] = round(time.perf_counter() - t0, 1)
    atomic_write_text(data / "masks" / "masks.json", json.dumps(summary, indent=1, default=str))
    log(f"wrote masks for {len(frames)} images to {data / 'masks'} in {summary['seconds']:.1f} s; "
        + ", ".join(f"{k} {100 * v:.1f}%" for k, v in summary["coverage"].items()) + " of the pixels")
    if summary.get("reference"):
        # the reference (continued by the second pass, when it ran) is StreetNeRF's first steps on these frames
        log(f"next: ns2gs-train streetnerf --data {data} --warm-start {summary.get('second_pass_run') or summary['reference']} "
            f"(continues that reference: its steps are not trained again; same frames and downscale)")
    return summary


def _install(src: Path, dst: Path) -> None:
    """Move every staged ``<kind>/<stem>.png`` into ``dst`` (each file replaced atomically)."""
    for kind_dir in sorted(p for p in src.iterdir() if p.is_dir()) if src.is_dir() else []:
        (dst / kind_dir.name).mkdir(parents=True, exist_ok=True)
        for f in kind_dir.iterdir():
            os.replace(f, dst / kind_dir.name / f.name)


def _segment(cfg: MasksConfig, data: Path, frames: list, groups: dict, out: Path, summary: dict,
             count: Callable[[dict[str, torch.Tensor]], None], log: Callable[[str], None], all_groups: dict) -> None:
    """Masks of every frame of ``groups`` into ``out/masks/<kind>/<stem>.png`` (onnx or auto; ``all_groups``:
    every split, of which auto takes the training frames as neighbours, below)."""
    if cfg.segmenter.startswith("onnx:"):
        from nerf2gs_plugin.data.images import load_image
        from nerf2gs_plugin.masks.onnx_segmenter import OnnxSegmenter
        from nerf2gs_plugin.progress import make_progress

        seg = OnnxSegmenter(cfg.segmenter[len("onnx:"):], cfg.class_map)
        with make_progress(cfg.progress) as prog:
            task = prog.add_task("masks: onnx", total=len(frames), stats="")
            for _, f in frames:
                img = load_image(f.image)
                ms = seg.masks(img)
                count(ms)
                _write(out, f.image, ms, (img.shape[1], img.shape[0]))
                prog.advance(task)
        summary["class_ids"] = seg._ids
    elif cfg.segmenter == "auto":
        from nerf2gs_plugin.masking.auto_masks import auto_masks
        from nerf2gs_plugin.masking.mask_reference import ensure_reference

        if cfg.render_downscale < 1 or cfg.render_downscale != int(cfg.render_downscale):  # before a reference is trained for nothing
            raise ConfigError(f"--render-downscale must be a whole number >= 1, got {cfg.render_downscale}")
        m = cfg.motion
        if not 0 <= m.persist <= 1:
            raise ConfigError(f"--motion.persist must be a share within [0, 1] (0: off), got {m.persist}")
        if m.persist > 0 and m.persist_ring <= 0:
            raise ConfigError(f"--motion.persist-ring must be > 0 (a fraction of the shorter image side), got {m.persist_ring}")
        if m.second_pass_steps < 0:
            raise ConfigError(f"--motion.second-pass-steps must be >= 0 (0: off), got {m.second_pass_steps}")
        distorted = [f.image.name for _, f in frames if f.intr.distorted]
        if distorted:
            raise DataError(f"--segmenter auto needs undistorted (pinhole) images; {distorted[0]} has distortion "
                            "(ns2gs-data process undistorts; or use --segmenter onnx:PATH)", data)
        t_ref = time.perf_counter()
        ref = ensure_reference(data, cfg.reference, cfg.reference_steps, cfg.downscale, cfg.progress, log)
        summary["reference"] = str(ref)
        summary["reference_seconds"] = round(time.perf_counter() - t_ref, 1)
        t_m = time.perf_counter()
        timings: dict = {}
        computed = _with_neighbours(data, groups, all_groups, cfg.motion, log)
        result = auto_masks(maskless_view(data), ref, computed, cfg.auto, log, cfg.progress, motion=cfg.motion,
                            render_downscale=cfg.render_downscale, stats=timings, keep_second_pass=True)
        summary.update(timings)
        for split, fs in groups.items():
            for f, m in zip(fs, result[split]):
                ms = {"sky": m.sky, "ground": m.ground, "transient": m.transient}
                count(ms)
                _write(out, f.image, ms, (f.intr.width, f.intr.height))
        summary["render_downscale"] = cfg.render_downscale
        summary["auto"] = asdict(cfg.auto)
        summary["motion"] = asdict(cfg.motion)
        summary["mask_seconds"] = round(time.perf_counter() - t_m, 1)
    else:
        raise ConfigError(f"--segmenter must be 'auto' or 'onnx:PATH', got {cfg.segmenter!r}")
