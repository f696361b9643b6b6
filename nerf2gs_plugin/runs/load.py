"""Loading a trained run back: for eval, the viewer, export, and as the augmentation reference
(:mod:`nerf2gs_plugin.augment.reference`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import torch

from nerf2gs_plugin.engine.checkpoints import file_hash, load_checkpoint, resolve_checkpoint
from nerf2gs_plugin.engine.config import load_config, read_config_doc
from nerf2gs_plugin.engine.pipeline import Pipeline
from nerf2gs_plugin.errors import CheckpointError, ConfigError
from nerf2gs_plugin.registry import get_method

if TYPE_CHECKING:  # an annotation only
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
