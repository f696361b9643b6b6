"""The motion route's second pass, the part that trains and renders (the mask maths: ``masks/second_pass.py``):
the first reference continued for ``second_pass_steps`` steps on the dataset with the first pass's
transient masks (grown a little) excluded from its loss, then rendered where the first pass marked.

The continued run trains in a temporary folder beside the first reference and, when asked, stays there as
``<reference>-second-pass`` (:func:`kept_run_dir`): StreetNeRF goes on from it (``--warm-start``) without
training its steps again. The dataset it trains on is ``DATA/.ns2gs_second_pass`` (symlinks to the mask-less
view's entries and the first pass's transient masks), removed afterwards.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.masks.auto import FrameMasks, Renders
from nerf2gs_plugin.masks.maskless import SECOND_PASS_DIRNAME
from nerf2gs_plugin.masks.second_pass import render_pixels, second_pass_mask
from nerf2gs_plugin.utils.parallel import cpu_seconds, render_ahead

TRAIN_GROW = 0.025
"""The first pass's masks grow by this fraction of the shorter image side before they are excluded from
the loss: the mover's edge and shadow that the first pass cut off."""


def kept_run_dir(reference: Path) -> Path:
    """Where the second pass's run stays: beside the first reference's run folder (``reference``, or the run
    of a ``.ckpt`` in it), named after it."""
    from nerf2gs_plugin.engine.checkpoints import run_dir_of

    run_dir = run_dir_of(reference)
    return run_dir.parent / f"{run_dir.name}-second-pass"


def _repoint(run: Path, data: Path) -> None:
    """The kept run's ``config.yml`` names its own folder and ``data`` (the mask-less view, which stays) in place of
    the temporary folder and the masked view it trained in, both removed: ``ns2gs-eval`` / ``ns2gs-render`` take it as it is."""
    from nerf2gs_plugin.engine.config import load_config, save_config
    from nerf2gs_plugin.registry import get_method

    cfg = load_config(run / "config.yml", get_method("streetnerf").config)
    save_config(run / "config.yml", cfg.method_name, dataclasses.replace(cfg, data=Path(data), run_dir=Path(run)))


def masked_view(view: Path, transient: dict[str, Tensor]) -> Path:
    """``view``'s sibling ``.ns2gs_second_pass``: ``view``'s entries (the mask-less dataset) with
    ``masks/transient/<stem>.png`` from ``transient`` (stem -> bool mask, grown by :data:`TRAIN_GROW`)."""
    import cv2

    from nerf2gs_plugin.data.images import write_mask_atomic

    view = Path(view)
    out = view.parent / SECOND_PASS_DIRNAME
    shutil.rmtree(out, ignore_errors=True)  # masks of an earlier run must not survive
    out.mkdir()
    for item in view.iterdir():
        if item.name in ("masks", ".ns2gs_cache"):
            continue
        if item.name == "transforms.json":
            shutil.copyfile(item, out / item.name)
        else:
            (out / item.name).symlink_to(item.resolve())
    for stem, m in transient.items():
        r = max(1, int(round(TRAIN_GROW * min(m.shape))))
        grown = cv2.dilate(m.numpy().astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))) > 0
        write_mask_atomic(out / "masks" / "transient" / f"{stem}.png", grown)
    return out


def continue_reference(view: Path, first: Path, run: Path, steps: int, progress: bool, log: Callable[[str], None]) -> None:
    """``first`` (a run folder or checkpoint) continued for ``steps`` steps on ``view`` into ``run``."""
    from nerf2gs_plugin.engine.checkpoints import load_checkpoint, resolve_checkpoint
    from nerf2gs_plugin.engine.config import load_config
    from nerf2gs_plugin.masking.mask_reference import reference_config, train_reference
    from nerf2gs_plugin.registry import get_method

    run_dir, ckpt = resolve_checkpoint(first)
    done = int(load_checkpoint(ckpt, map_location="cpu")["step"]) + 1
    # the first reference's image size: the warm start takes only the same cameras
    downscale = load_config(run_dir / "config.yml", get_method("streetnerf").config).pipeline.datamanager.dataparser.downscale
    cfg = reference_config(view, run, done + steps, downscale, progress)
    cfg = dataclasses.replace(cfg, warm_start=Path(run_dir), steps_per_save=done + steps)
    log(f"masks: second pass: the reference continued for {steps} steps without the first pass's transient pixels")
    train_reference(cfg, done + steps, log)


def second_pass(view: Path, reference: Path, full: Renders, result: dict[str, list[FrameMasks]], steps: int, margin: float,
                log: Callable[[str], None] = print, progress: bool = True, render_step: int = 1, keep: bool = False) -> dict:
    """Replace ``result``'s transient masks (the first pass: residual route and motion route, at the
    size of ``full``'s views) by the second pass's (``masks/second_pass.py``), its reference rendering
    every ``render_step``-th pixel per side of the regions (the first reference's ``render_downscale``);
    returns its seconds (and, with ``keep``, ``second_pass_run``: the continued run, kept at :func:`kept_run_dir`)."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.progress import make_progress
    from nerf2gs_plugin.runs.load import load_run

    t0, c0 = time.perf_counter(), cpu_seconds()  # with the render workers'
    train_names = [v["name"] for v in full.views.get("train", [])]
    firsts = {Path(n).stem: m.transient for n, m in zip(train_names, result.get("train", []))}
    mview = masked_view(view, firsts)
    reference = Path(reference)
    tmp = Path(tempfile.mkdtemp(prefix="second-pass-", dir=reference.parent))
    try:
        continue_reference(mview, reference, tmp / "run", steps, progress, log)
        t_train = time.perf_counter() - t0
        with warnings.catch_warnings():  # trained with transient masks only: no sky / ground masks on purpose
            warnings.filterwarnings("ignore", message="StreetNeRF: the dataset has no .* masks")
            run = load_run(tmp / "run", device="cpu", data=mview)
        parser = run.config.pipeline.datamanager.dataparser
        data = {s: run.pipeline.datamanager.train_data if s == "train" else parse_dataset(mview, s, downscale=parser.downscale, cache_dir=parser.cache_dir)
                for s in full.views}
        def size(s: str, i: int) -> tuple[int, int]:
            cam = data[s].cameras[i : i + 1]
            return int(cam.height[0]), int(cam.width[0])

        todo = [(s, i) for s, views in full.views.items() for i in range(len(views))
                if bool(result[s][i].transient.any()) and size(s, i) == tuple(result[s][i].transient.shape)]

        def mask(si: tuple[str, int]) -> Tensor:
            """The frame's second-pass mask: its regions rendered, then the maths, both in one worker."""
            s, i = si
            m, v = result[s][i], full.views[s][i]
            pixels, sample = render_pixels(m.transient, render_step)
            rgb = run.model.render_camera(data[s].cameras[i : i + 1], pixels=pixels)["rgb"].cpu()
            return second_pass_mask(m.transient, v["image"], v["rgb"], rgb, pixels, sample, m.sky, margin)

        with make_progress(progress) as prog, torch.no_grad():
            task = prog.add_task("masks: second pass", total=len(todo), stats="")
            # views side by side (utils/parallel.py), each one's mask made where it was rendered
            for (s, i), m in zip(todo, render_ahead(mask, todo)):
                result[s][i].transient = m
                prog.advance(task)
        kept = kept_run_dir(reference) if keep else None
        if kept is not None:
            shutil.rmtree(kept, ignore_errors=True)
            os.replace(tmp / "run", kept)
            _repoint(kept, view)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(mview, ignore_errors=True)
    seconds, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    log(f"masks: second pass in {seconds:.1f} s (its reference {t_train:.1f} s)")
    took = {"second_pass_seconds": round(seconds, 1), "second_pass_cpu_seconds": round(cpu, 1),
            "second_pass_train_seconds": round(t_train, 1)}
    return took | ({"second_pass_run": str(kept)} if kept is not None else {})
