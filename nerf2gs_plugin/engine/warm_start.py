"""``--warm-start RUN``: a new run whose first steps are another run's, e.g. StreetNeRF continuing from
the masks stage's first reference (the same method trained on the same frames without masks) instead
of training those steps again.

It is taken only where the other run is the same model on the same data: the same method, the same
training images (fingerprint), the same training cameras (order, poses in the normalised frame,
intrinsics, image size: so the same downscale and normalisation), the same model configuration except
loss weights and render-time settings, and the same parameter shapes. Anything else is refused with
the first difference named; nothing falls back silently to a cold start.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import torch

from nerf2gs_plugin.cameras import Cameras

RENDER_ONLY = frozenset({"eval_chunk", "render_min_weight", "eval_appearance", "encoding_backend", "expect_masks",
                         "render_nerf_samples"})
"""Model settings that change no trained parameter (rendering, kernels, warnings): free to differ."""


def free_to_differ(key: str) -> bool:
    """Loss weights (``*_weight``) shape the training from here on, not what was learnt so far."""
    return key.endswith("_weight") or key in RENDER_ONLY


def config_difference(theirs: Any, ours: Any, where: str = "pipeline.model") -> Optional[str]:
    """The first setting (dotted path) where two plain configs differ, loss weights and render-only
    settings aside; None when they match."""
    if isinstance(theirs, dict) and isinstance(ours, dict):
        for key in sorted(set(theirs) | set(ours)):
            if free_to_differ(key):
                continue
            if key not in theirs or key not in ours:
                return f"{where}.{key} (set in only one of them)"
            why = config_difference(theirs[key], ours[key], f"{where}.{key}")
            if why:
                return why
        return None
    if isinstance(theirs, (list, tuple)) and isinstance(ours, (list, tuple)):
        theirs, ours = list(theirs), list(ours)
    return None if theirs == ours else f"{where} ({theirs!r} there, {ours!r} here)"


def camera_difference(theirs: Optional[Cameras], ours: Cameras, sizes_only: bool = False) -> Optional[str]:
    """Why two sets of training cameras are not the same frames seen the same way (None: they are);
    ``sizes_only``: their count and image sizes alone."""
    if theirs is None:
        return "it has no train_cameras.json (a run older than that file)"
    if len(theirs) != len(ours):
        return f"it was trained on {len(theirs)} frames, this run has {len(ours)}"
    ours = ours.to("cpu")
    if not (torch.equal(theirs.width.reshape(-1).long(), ours.width.reshape(-1).long())
            and torch.equal(theirs.height.reshape(-1).long(), ours.height.reshape(-1).long())):
        return "its training images have another size (another downscale)"
    if sizes_only:
        return None
    for name in ("fx", "fy", "cx", "cy"):
        if not torch.allclose(getattr(theirs, name).reshape(-1).float(), getattr(ours, name).reshape(-1).float(), rtol=1e-5, atol=1e-4):
            return f"its cameras have other intrinsics ({name})"
    if not torch.allclose(theirs.camera_to_worlds.float(), ours.camera_to_worlds.float(), atol=1e-5):
        return "its camera poses differ (another normalisation or frame order)"
    return None


def state_difference(theirs: dict[str, torch.Tensor], ours: dict[str, torch.Tensor]) -> Optional[str]:
    """The first parameter or buffer missing on one side or shaped differently (None: they match)."""
    for key in sorted(set(theirs) | set(ours)):
        if key not in theirs or key not in ours:
            return f"model entry '{key}' is in only one of them"
        if tuple(theirs[key].shape) != tuple(ours[key].shape):
            return f"model entry '{key}' has shape {tuple(theirs[key].shape)} there, {tuple(ours[key].shape)} here"
    return None


def warm_start_refusal(ckpt: dict, run_dir: Path, method_name: str, fingerprint: str, cameras: Cameras,
                       model_config: dict, model_state: dict[str, torch.Tensor], max_steps: int) -> Optional[str]:
    """Why the checkpoint ``ckpt`` of ``run_dir`` cannot start this run (None: it can)."""
    from nerf2gs_plugin.engine.config import read_config_doc
    from nerf2gs_plugin.engine.run_cameras import load_train_cameras

    if ckpt.get("method_name") != method_name:
        return f"it is a '{ckpt.get('method_name')}' run, this is '{method_name}'"
    theirs_cams = load_train_cameras(run_dir)
    why = camera_difference(theirs_cams, cameras, sizes_only=True)  # before the fingerprint: a downscale is named as such
    if why:
        return why
    if ckpt.get("dataset") != fingerprint:
        return "it was trained on other images (dataset fingerprint differs)"
    why = camera_difference(theirs_cams, cameras)
    if why:
        return why
    config_file = Path(run_dir) / "config.yml"
    if not config_file.is_file():
        return "it has no config.yml"
    theirs = read_config_doc(config_file)["config"].get("pipeline", {}).get("model", {})
    why = config_difference(theirs, model_config)
    if why:
        return f"its model is configured otherwise: {why}"
    why = state_difference(ckpt["model"], model_state)
    if why:
        return why
    if int(ckpt["step"]) + 1 >= max_steps:
        return f"it is already at step {int(ckpt['step'])}, this run ends at {max_steps}: nothing left to train"
    return None
