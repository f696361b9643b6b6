"""Pipeline: one DataManager and one Model; the train step and evaluation."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.datamanagers.base import DataManager, DataManagerConfig
from nerf2gs_plugin.utils.config import InstantiateConfig
from nerf2gs_plugin.engine.model import Model, ModelConfig
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse


@dataclass
class PipelineConfig(InstantiateConfig):
    _target: type = field(default_factory=lambda: Pipeline)
    datamanager: DataManagerConfig = field(default_factory=DataManagerConfig)
    model: ModelConfig = field(default_factory=ModelConfig)


class Pipeline(nn.Module):
    """``wrap_datamanager`` (e.g. the AugmentedDataManager's factory) replaces the method's
    DataManager by a wrapper of it once the model is built: the model is built from the real
    training data, and with the same random state as without the wrapper; then it takes the wrapper's
    :meth:`DataManager.initial_points` (if any) as more primitives to start from."""

    def __init__(self, config: PipelineConfig, data: Path, device: torch.device | str = "cpu", seed: int = 0,
                 datamanager: Optional[DataManager] = None,
                 wrap_datamanager: Optional[Callable[[DataManager], DataManager]] = None) -> None:
        super().__init__()
        self.config = config
        self.device = torch.device(device)
        self.datamanager: DataManager = datamanager or config.datamanager.setup(data=data, device=self.device, seed=seed)
        self.model: Model = config.model.setup(train_data=self.datamanager.train_data).to(self.device)
        if wrap_datamanager is not None:
            self.datamanager = wrap_datamanager(self.datamanager)
            self.model.add_extra_views(len(self.datamanager.all_train_cameras) - self.model.num_train_images)
            points = self.datamanager.initial_points()
            if points is not None and len(points[0]):
                added = self.model.add_initial_points(points[0].to(self.device), points[1].to(self.device))
                if added:
                    print(f"initial points: {added} added where only the additional views see the scene")

    def get_train_loss_dict(self, step: int) -> tuple[dict[str, Tensor], dict[str, Tensor], dict[str, Tensor]]:
        inputs, batch = self.datamanager.next_train(step)
        outputs = self.model.get_train_outputs(inputs, batch)
        metrics = self.model.get_metrics_dict(outputs, batch)
        losses = self.model.get_loss_dict(outputs, batch, metrics)
        return outputs, losses, metrics

    @torch.no_grad()
    def get_eval_image_metrics(self, step: int) -> dict[str, float]:
        """PSNR of ONE eval view (the ``step``-th in turn): a cheap signal while training, named
        ``eval_psnr_1view`` so it is not taken for the eval PSNR of ``ns2gs-eval`` (all views)."""
        camera, batch = self.datamanager.next_eval(step)
        was_training = self.model.training
        self.model.eval()
        out = self.model.render_camera(camera)
        self.model.train(was_training)
        mse = ((out["rgb"] - batch["image"]) ** 2).mean()
        return {"eval_psnr_1view": float(psnr_from_mse(mse))}

    @torch.no_grad()
    def render_split(self, name: str, max_images: Optional[int] = None) -> list[tuple[dict[str, Tensor], dict[str, Any], float]]:
        """Render every camera of an eval split: (outputs, batch, seconds) per image."""
        self.model.eval()
        results = []
        for i, (camera, batch) in enumerate(self.datamanager.eval_images(name)):
            if max_images is not None and i >= max_images:
                break
            t0 = time.perf_counter()
            out = self.model.render_camera(camera)
            results.append((out, batch, time.perf_counter() - t0))
        return results
