"""Whole images, one per step (splatting methods)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.datamanagers.base import DataManager, DataManagerConfig
from nerf2gs_plugin.datamanagers.resolution import downscale_at, downscaled
from nerf2gs_plugin.utils.schedule import scheduled


@dataclass
class FullImageDataManagerConfig(DataManagerConfig):
    _target: type = field(default_factory=lambda: FullImageDataManager)
    num_downscales: int = 0
    """Coarse to fine (nerfstudio's splatfacto --pipeline.model.num-downscales): the first training steps see the
    views at 1/2^N of their size, doubled every resolution-schedule steps (0: full size throughout)."""
    resolution_schedule: int = scheduled(300)
    """Steps at each size before the next doubling (nerfstudio: 3000 of 30000)."""


class FullImageDataManager(DataManager):
    """Cycles through a random permutation of the training images; extra views are drawn with
    probability ``extra_prob`` (each at ``extra_view_probs``). ``image_idx`` indexes :attr:`all_train_cameras`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._order: list[int] = []

    def next_train(self, step: int) -> tuple[Cameras, dict[str, Any]]:
        d = downscale_at(step, self.config.num_downscales, self.config.resolution_schedule)
        if self._use_extra():
            i = int(self._extra_indices(1)[0])
            return downscaled(self.extra_images.cameras[i], self.train_batch(len(self.train_images) + i), d)
        if not self._order:
            self._order = torch.randperm(len(self.train_images), generator=self.generator).tolist()
        i = self._order.pop()
        return downscaled(self.train_images.cameras[i], self.train_images.image_batch(i), d)

    def state_dict(self) -> dict:
        return {**super().state_dict(), "order": list(self._order)}

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self._order = list(state.get("order", []))
