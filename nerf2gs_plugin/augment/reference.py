"""The augmentation's reference: a trained run loaded as the renderer of the augmented views, the
enhancer named by ``--augment.enhancer``, and the factory that wraps a DataManager in the augmentation."""

from __future__ import annotations

import dataclasses
import functools
import inspect
from pathlib import Path
from typing import Optional

import torch

from nerf2gs_plugin.augment.config import AugmentConfig
from nerf2gs_plugin.augment.datamanager import AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.base import DataManager
from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint, load_checkpoint, resolve_checkpoint
from nerf2gs_plugin.engine.config import read_config_doc
from nerf2gs_plugin.runs.load import load_run
from nerf2gs_plugin.enhancer import make_enhancer
from nerf2gs_plugin.errors import CheckpointError, ConfigError
from nerf2gs_plugin.utils.parallel import view_workers


def _same_data_other_downscale(run_dir: Path, datamanager, fingerprint: Optional[str]) -> bool:
    """True when the reference was trained on this dataset at another ``downscale``: the fingerprint
    keys the (resized) training files, so it is recomputed at the reference's downscale. The
    reference then renders at the target's cameras, i.e. at the target's resolution."""
    try:
        doc = read_config_doc(run_dir / "config.yml")
        saved = doc["config"]["pipeline"]["datamanager"]
        ref_ds = float(saved.get("dataparser", saved)["downscale"])  # older configs: on the datamanager
    except (KeyError, TypeError, ValueError, ConfigError):
        return False
    ours = datamanager.config.dataparser
    if fingerprint is None or ref_ds == float(ours.downscale):
        return False
    parsed = dataclasses.replace(ours, downscale=ref_ds).setup(datamanager.data).parse("train")
    return dataset_fingerprint(parsed.image_filenames) == fingerprint


def load_reference(reference: Path, datamanager, device: torch.device | str, appearance: str = "mean") -> Reference:
    """A reference run (directory or .ckpt) for the augmentation of ``datamanager``'s dataset: it must
    have been trained on the same images and its method must render whole cameras. ``appearance``:
    ``--augment.appearance``, for a model whose ``render_camera`` takes one (else it has none to choose)."""
    run_dir, ckpt_file = resolve_checkpoint(reference)
    ckpt = load_checkpoint(ckpt_file, map_location="cpu")
    ours = dataset_fingerprint(datamanager.train_data.image_filenames)
    if ckpt.get("dataset") != ours and not _same_data_other_downscale(run_dir, datamanager, ckpt.get("dataset")):
        raise CheckpointError(
            f"reference was trained on a different dataset (fingerprint {ckpt.get('dataset')} vs {ours} for {datamanager.data})", ckpt_file
        )
    ref = load_run(ckpt_file, device=device, data=datamanager.data)
    if not hasattr(ref.model, "render_camera") or getattr(type(ref.model).render_camera, "__isabstractmethod__", False):
        raise CheckpointError(f"method '{ref.config.method_name}' cannot render cameras (no render_camera)", ckpt_file)
    render = ref.model.render_camera
    params = inspect.signature(render).parameters
    if "appearance" in params:
        render = functools.partial(render, appearance=appearance)
    render_pixels = (lambda camera, pixels: render(camera, pixels=pixels)) if "pixels" in params else None
    render_key = getattr(ref.model, "render_key", lambda: "")()  # renders that differ from training's sampling
    key = f"{ref.config.method_name}:{ref.checkpoint_hash}" + (f":{render_key}" if render_key else "")
    return Reference(render, key, run_dir, ref.model.depth_along,
                     getattr(ref.model, "refined_train_cameras", None), render_pixels,
                     view_workers() if torch.device(device).type == "cpu" else 1)  # no forked workers on a GPU


def build_enhancer(spec: str):
    """The enhancer named by ``--augment.enhancer`` (None for "none"), built here so the data
    managers never import an enhancer implementation."""
    if spec in ("", "none"):
        return None
    return make_enhancer(spec)


def augmented_datamanager(inner: DataManager, reference: Path, augment: AugmentConfig, device: torch.device | str,
                          total_steps: Optional[int] = None) -> AugmentedDataManager:
    """The factory the Trainer and ``ns2gs-data export-augmented`` call: ``inner`` wrapped in an
    AugmentedDataManager fed by the reference run at ``reference`` (``total_steps``: the run's length,
    for ``--augment.real-only-from``)."""
    return AugmentedDataManager(inner, load_reference(reference, inner, device, augment.appearance), augment, build_enhancer(augment.enhancer),
                                total_steps)
