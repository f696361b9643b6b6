"""A run's model without its dataset: what ``ns2gs-export`` needs (the checkpoint, ``config.yml``,
``dataparser_transforms.json`` and ``train_cameras.json`` of the run directory, no images)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.engine.checkpoints import load_checkpoint, resolve_checkpoint
from nerf2gs_plugin.engine.config import load_config, read_config_doc
from nerf2gs_plugin.engine.run_cameras import load_train_cameras
from nerf2gs_plugin.errors import CheckpointError, ConfigError


@dataclass
class RunModel:
    run_dir: Path
    checkpoint: Path
    method_name: str
    model: torch.nn.Module
    step: int
    train_cameras: Cameras
    config: Optional[Any] = None  # the run's TrainerConfig
    dataset: Optional[str] = None  # the training images' fingerprint recorded in the checkpoint
    units_per_metre: float = 1.0  # normalised world units per metre (the dataparser's metric scale)
    up: Optional[torch.Tensor] = None  # [3] the ground's up in the normalised frame


def load_run_model(path: Path, device: torch.device | str = "cpu", data: Optional[Path] = None) -> RunModel:
    """A run directory or ``.ckpt`` -> its model with the checkpoint loaded (eval mode).

    The dataset is read only for a run that predates ``train_cameras.json`` (then it must exist,
    at the recorded path or at ``data``)."""
    from nerf2gs_plugin.data import load_dataparser_transform
    from nerf2gs_plugin.registry import get_method

    run_dir, ckpt_file = resolve_checkpoint(path)
    cameras = load_train_cameras(run_dir)
    if cameras is None:  # an older run: build it from its dataset
        from nerf2gs_plugin.runs.load import load_run

        run = load_run(path, device=device, data=data)
        td = run.pipeline.datamanager.train_data
        ckpt = load_checkpoint(run.checkpoint, expected_method=run.config.method_name, map_location="cpu")
        return RunModel(run.run_dir, run.checkpoint, run.config.method_name, run.model, run.step, td.cameras, run.config,
                        ckpt.get("dataset"), td.metres_to_world(1.0), td.up)
    doc = read_config_doc(run_dir / "config.yml")
    spec = get_method(doc["method_name"])
    config = load_config(run_dir / "config.yml", spec.config)
    tf = load_dataparser_transform(run_dir / "dataparser_transforms.json")
    # one placeholder point: the model is built at its smallest, then resized to the checkpoint
    stub = DataparserOutputs(
        image_filenames=[Path(f"train_{i}") for i in range(len(cameras))], cameras=cameras,
        points3D_xyz=tf.scene_box.mean(0, keepdim=True), points3D_rgb=torch.full((1, 3), 128, dtype=torch.uint8),
        scene_box=tf.scene_box, dataparser_transform=tf.transform, dataparser_scale=tf.scale,
        metres_per_unit=tf.metres_per_unit, up=tf.up,
    )
    ckpt = load_checkpoint(ckpt_file, expected_method=doc["method_name"], map_location=device)
    from nerf2gs_plugin.warn import quiet

    with quiet():
        model = config.pipeline.model.setup(train_data=stub).to(device)
    try:
        model.load_model_state(ckpt["model"])
    except (RuntimeError, KeyError) as e:
        raise CheckpointError(f"checkpoint does not fit the {doc['method_name']} model ({str(e).splitlines()[0][:160]})", ckpt_file) from None
    if not isinstance(model, torch.nn.Module):
        raise ConfigError(f"method '{doc['method_name']}' did not build a model", run_dir / "config.yml")
    model.eval()
    return RunModel(run_dir, ckpt_file, doc["method_name"], model, int(ckpt["step"]), cameras, config, ckpt.get("dataset"),
                    tf.scale / tf.metres_per_unit, tf.up)
