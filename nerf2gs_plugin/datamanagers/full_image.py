"""Whole images, one per step (splatting methods)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.datamanagers.base import DataManager, DataManagerConfig


@dataclass
class FullImageDataManagerConfig(DataManagerConfig):
    _target: type = field(default_factory=lambda: FullImageDataManager)


class FullImageDataManager(DataManager):
    """Cycles through a random permutation of the training images; extra views are drawn with
    probability ``extra_prob`` (each at ``extra_view_probs``). ``image_idx`` indexes :attr:`all_train_cameras`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._order: list[int] = []

    def next_train(self, step: int) -> tuple[Cameras, dict[str, Any]]:
        if self._use_extra():
            i = int(self._extra_indices(1)[0])
            return self.extra_images.cameras[i], self.train_batch(len(self.train_images) + i)
        if not self._order:
            self._order = torch.randperm(len(self.train_images), generator=self.generator).tolist()
        i = self._order.pop()
        return self.train_images.cameras[i], self.train_images.image_batch(i)

    def state_dict(self) -> dict:
        return {**super().state_dict(), "order": list(self._order)}

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self._order = list(state.get("order", []))
