"""Loading a trained run back: for eval, the viewer, export, and as the augmentation reference."""

from __future__ import annotations

import dataclasses
import functools
import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import torch

from nerf2gs_plugin.datamanagers.augmented import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.base import DataManager
from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint, file_hash, load_checkpoint, resolve_checkpoint
from nerf2gs_plugin.engine.config import load_config, read_config_doc
from nerf2gs_plugin.engine.pipeline import Pipeline
from nerf2gs_plugin.enhancers import make_enhancer
from nerf2gs_plugin.data import parse_dataset
from nerf2gs_plugin.errors import CheckpointError, ConfigError
from nerf2gs_plugin.registry import get_method

if TYPE_CHECKING:  # the trainer builds the augmentation from here: no arrow back at run time
    from nerf2gs_plugin.engine.trainer_config import TrainerConfig


@dataclass
class LoadedRun:
    run_dir: Path
    checkpoint: Path
    config: TrainerConfig
    pipeline: Pipeline
    step: int
    checkpoint_hash: str
    train_seconds: float

    @property
    def model(self):
        return self.pipeline.model


def load_run(path: Path, device: torch.device | str = "cpu", data: Optional[Path] = None) -> LoadedRun:
    """A run directory or ``.ckpt`` -> its pipeline with the checkpoint loaded (eval mode)."""
    run_dir, ckpt_file = resolve_checkpoint(path)
    doc = read_config_doc(run_dir / "config.yml")
    spec = get_method(doc["method_name"])
    config: TrainerConfig = load_config(run_dir / "config.yml", spec.config)
    if data is not None:
        config = dataclasses.replace(config, data=Path(data))
    else:
        config = dataclasses.replace(config, data=find_dataset(Path(config.data), run_dir))
    if not Path(config.data).exists():
        raise ConfigError(f"the run's dataset {config.data} does not exist (pass the dataset path explicitly)", run_dir / "config.yml")
    ckpt = load_checkpoint(ckpt_file, expected_method=doc["method_name"], map_location=device)
    from nerf2gs_plugin.warn import quiet

    with quiet():  # what the data lacks was said when the run was trained
        pipeline = Pipeline(config.pipeline, config.data, device)
    try:
        pipeline.model.load_model_state(ckpt["model"])
    except (RuntimeError, KeyError) as e:
        raise CheckpointError(f"checkpoint does not fit the {doc['method_name']} model ({str(e).splitlines()[0][:160]})", ckpt_file) from None
    pipeline.model.eval()
    return LoadedRun(run_dir, ckpt_file, config, pipeline, int(ckpt["step"]), file_hash(ckpt_file), float(ckpt.get("train_seconds", 0.0)))


def _same_data_other_downscale(run_dir: Path, datamanager, fingerprint: Optional[str]) -> bool:
    """True when the reference was trained on this dataset at another ``downscale``: the fingerprint
    keys the (resized) training files, so it is recomputed at the reference's downscale. The
    reference then renders at the target's cameras, i.e. at the target's resolution."""
    try:
        doc = read_config_doc(run_dir / "config.yml")
        ref_ds = float(doc["config"]["pipeline"]["datamanager"]["downscale"])
    except (KeyError, TypeError, ValueError, ConfigError):
        return False
    if fingerprint is None or ref_ds == float(datamanager.config.downscale):
        return False
    options = datamanager.config.data_options() if hasattr(datamanager.config, "data_options") else {}
    return dataset_fingerprint(parse_dataset(datamanager.data, "train", downscale=ref_ds, **options).image_filenames) == fingerprint


def find_dataset(recorded: Path, run_dir: Path) -> Path:
    """The run's dataset: the recorded path, or, for a relative one recorded by an older run (the
    path from where it was trained), that path under the first ancestor of the run directory
    that holds it (a run under <repo>/benchmarks/runs/ finds <repo>/benchmarks/runs/data/street)."""
    if recorded.is_absolute() or recorded.exists():
        return recorded
    for parent in Path(run_dir).absolute().parents:
        if (parent / recorded).exists():
            return parent / recorded
    return recorded


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
    if "appearance" in inspect.signature(render).parameters:
        render = functools.partial(render, appearance=appearance)
    return Reference(render, f"{ref.config.method_name}:{ref.checkpoint_hash}", run_dir, ref.model.depth_along,
                     getattr(ref.model, "refined_train_cameras", None))


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
