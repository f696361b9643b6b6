"""Render one or several runs along one camera path into a video or PNG frames (``ns2gs-render``)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_plugin.render.frames import check_outputs, render_outputs, side_by_side, tile
from nerf2gs_plugin.render.measures import PathMeasures, floater_distance, height_above_capture
from nerf2gs_plugin.render.paths import PathOptions, make_path
from nerf2gs_plugin.render.scene import PathContext, context_from_run_model
from nerf2gs_plugin.render.writer import FrameWriter, OutputFormat
from nerf2gs_plugin.utils.io import atomic_write_text


@dataclass
class OutputOptions:
    output_format: OutputFormat = "video"
    """video: one MP4 (OpenCV, mp4v); images: a folder of numbered PNGs."""
    rendered_output_names: tuple[str, ...] = ("rgb",)
    """Outputs to render, placed left to right: rgb, depth (colour-mapped), accumulation (what the method has)."""
    downscale: float = 1.0
    """Divide the path cameras' resolution by this."""
    fps: float = 10.0
    """Frames per second of the video."""
    measure: bool = False
    """Also measure holes from above and near-camera floaters on this path (printed, and written beside the output)."""


def load_runs(paths: Sequence[Path], device: torch.device | str = "cpu") -> list:
    """Each run's model (a run folder or ``.ckpt``); a missing one is a clear error naming it."""
    from nerf2gs_plugin.runs.model import load_run_model

    for p in paths:
        if not Path(p).exists():
            raise DataError("run directory or checkpoint does not exist", p)
    return [load_run_model(Path(p), device=device) for p in paths]


def check_same_dataset(runs: Sequence, paths: Sequence[Path]) -> None:
    """Runs compared on one path must have been trained on one dataset (their checkpoints' image fingerprints)."""
    first, cams = runs[0].dataset, runs[0].train_cameras
    for run, p in zip(runs[1:], paths[1:]):
        if run.dataset != first or len(run.train_cameras) != len(cams):
            raise ConfigError(f"was trained on another dataset than {paths[0]} (training images differ): "
                              "runs compared side by side must share a dataset", p)
        if not torch.allclose(run.train_cameras.camera_to_worlds.cpu(), cams.camera_to_worlds.cpu(), atol=1e-4):
            raise ConfigError(f"has the same images as {paths[0]} but other normalised poses (other dataparser "
                              "options): the same cameras would show different places", p)


def path_context(runs: Sequence) -> PathContext:
    """The context the path is built from: the first run whose augmentation trained bird's-eye views
    (so a baseline and its augmented twin are seen from those same views), else the first run."""
    contexts = [context_from_run_model(r) for r in runs]
    return next((c for c in contexts if c.augment_views is not None), contexts[0])


def path_cameras(ctx: PathContext, kind: str, opts: PathOptions, downscale: float = 1.0) -> Cameras:
    if opts.camera_path_file is not None:
        kind = "camera-path"
    if downscale <= 0:
        raise ConfigError(f"--downscale {downscale}: must be positive")
    cams = make_path(kind, ctx, opts)
    return cams.scaled(1.0 / downscale) if downscale != 1.0 else cams


def render_runs(runs: Sequence, labels: Optional[Sequence[str]], cameras: Cameras, ctx: PathContext, output: Path,
                out: OutputOptions, description: str = "render") -> list[dict]:
    """Write every frame (runs side by side under ``labels``, or one run alone); with ``out.measure``
    the measures per run, also written to ``<output>.measures.json``."""
    from nerf2gs_plugin.progress import make_progress

    names = list(out.rendered_output_names)
    for run in runs:
        check_outputs(run.model, cameras[0], names)
    heights = height_above_capture(cameras, ctx.train, ctx.up)
    measures = [PathMeasures() for _ in runs]
    with make_progress() as progress, FrameWriter(output, out.output_format, out.fps) as writer, torch.no_grad():
        task = progress.add_task(description, total=len(cameras), stats="")
        streams = [render_outputs(run.model, cameras) for run in runs]
        for i in range(len(cameras)):
            tiles = []
            for k, stream in enumerate(streams):
                o = next(stream)
                if out.measure:
                    measures[k].add(o, floater_distance(float(heights[i]), ctx.units_per_metre))
                tiles.append(tile(o, names))
            writer.write(side_by_side(tiles, labels) if labels is not None else tiles[0])
            progress.advance(task)
    results = [{"run": str(r.run_dir), "label": (labels[k] if labels else r.method_name), **m.result()}
               for k, (r, m) in enumerate(zip(runs, measures))]
    if out.measure:
        atomic_write_text(Path(f"{output}.measures.json"), json.dumps(results, indent=1))
    return results
