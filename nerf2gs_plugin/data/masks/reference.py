"""The first reference that ``--segmenter auto`` derives masks from: a short StreetNeRF trained
WITHOUT masks (a plain NeRF with a direction-only sky model), reused when it exists.

Why without masks: the masks are what we are estimating; a reference trained on stale or partial
masks would only reproduce them. The dataset may already hold masks (a second run with
``--overwrite``), so the reference trains on a *mask-less view* of it: a sibling folder of
symlinks to everything but ``masks/`` (and, for ``transforms.json``, a copy without the per-frame
mask keys). Training images are the same files, so the dataset fingerprint is the same.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from pathlib import Path
from typing import Callable, Optional

from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.engine.config import atomic_write_text
from nerf2gs_plugin.errors import ConfigError

VIEW_DIRNAME = ".ns2gs_maskless"
DEFAULT_STEPS = 1000
_SKIP = {"masks", ".ns2gs_cache", VIEW_DIRNAME}


def maskless_view(data: Path) -> Path:
    """``DATA/.ns2gs_maskless``: the dataset without its masks (symlinks; rebuilt every call)."""
    data = Path(data).resolve()
    view = data / VIEW_DIRNAME
    view.mkdir(exist_ok=True)
    for item in data.iterdir():
        if item.name in _SKIP or item.name == "transforms.json":
            continue
        link = view / item.name
        if link.is_symlink() or link.exists():
            if link.is_symlink() and os.readlink(link) == str(item):
                continue
            link.unlink()
        link.symlink_to(item)
    meta_file = data / "transforms.json"
    if meta_file.is_file():
        meta = json.loads(meta_file.read_text())
        keys = {f"{k}_mask_path" for k in MASK_KINDS}

        def strip(fr: object) -> object:
            return {k: v for k, v in fr.items() if k not in keys} if isinstance(fr, dict) else fr

        meta["frames"] = [strip(f) for f in meta.get("frames", [])]
        if isinstance(meta.get("eval_splits"), dict):
            meta["eval_splits"] = {k: [strip(f) for f in v] if isinstance(v, list) else v for k, v in meta["eval_splits"].items()}
        atomic_write_text(view / "transforms.json", json.dumps(meta, indent=1))
    return view


def default_reference_dir(data: Path) -> Path:
    return Path("outputs") / Path(data).resolve().name / "masks-reference"


def ensure_reference(data: Path, run: Optional[Path], steps: int = DEFAULT_STEPS, downscale: float = 1.0,
                     progress: bool = True, log: Callable[[str], None] = print) -> Path:
    """An existing run (directory or ``.ckpt``) is used as is; otherwise a StreetNeRF of ``steps``
    steps is trained on the mask-less view of ``data`` into ``run`` (resumed when partial)."""
    from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
    from nerf2gs_plugin.engine.config import apply_plain
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.eval.bench_paper import step_overrides
    from nerf2gs_plugin.registry import get_method

    run = Path(run) if run is not None else default_reference_dir(data)
    if run.is_file():
        return run
    if steps < 1:
        raise ConfigError(f"--reference-steps must be >= 1, got {steps}")
    ckpts = list_checkpoints(run) if run.is_dir() else []
    if ckpts and (run / "config.yml").is_file():
        done = int(load_checkpoint(ckpts[-1])["step"])
        from nerf2gs_plugin.engine.config import read_config_doc

        target = int(read_config_doc(run / "config.yml")["config"].get("max_num_iterations", steps))
        if done >= target - 1:
            log(f"masks: reusing reference {run} (step {done})")
            return run
    overrides = {**step_overrides("streetnerf", steps), "steps_per_eval_image": 0, "steps_per_save": max(1, steps // 4)}
    cfg = apply_plain(get_method("streetnerf").config, overrides, where="masks reference")
    dm = dataclasses.replace(cfg.pipeline.datamanager, downscale=downscale) if hasattr(cfg.pipeline.datamanager, "downscale") else cfg.pipeline.datamanager
    cfg = dataclasses.replace(cfg, data=maskless_view(data), progress=progress, timestamp="masks-reference",
                              pipeline=dataclasses.replace(cfg.pipeline, datamanager=dm),
                              load_checkpoint=ckpts[-1] if ckpts else None)
    log(f"masks: training a {steps}-step StreetNeRF reference without masks -> {run}")
    trainer = Trainer(cfg)
    trainer.run_dir = run
    with warnings.catch_warnings():  # "the dataset has no sky masks": intended here, not news
        warnings.filterwarnings("ignore", message="StreetNeRF: the dataset has no .* masks")
        trainer.setup()
    if not progress:  # a line every tenth of the run instead of the bar
        every = max(1, steps // 10)
        trainer.step_hooks.append(lambda step, *_: log(f"masks: reference step {step + 1}/{steps}") if (step + 1) % every == 0 else None)
    trainer.train()
    return run
