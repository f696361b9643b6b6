"""DataManager: owns the parsed dataset and hands out training and eval batches.

Training images live in an :class:`ImageSet`; an optional second ImageSet of *extra* views (the
bird's-eye views of an augmented run) is sampled with probability ``extra_prob`` and weighted by
its per-image weight. The AugmentedDataManager fills both; methods never know which is which.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Iterator, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.data.parser_config import MOVED_TO_DATAPARSER, DataParserConfig
from nerf2gs_plugin.datamanagers.image_set import ImageSet, load_image_set
from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.utils.config import InstantiateConfig

# eval splits in the order they are reported; a dataset may hold any subset (or others)
PREFERRED_EVAL_SPLITS = ("street", "bev_1", "bev_2", "val", "test")


@dataclass
class DataManagerConfig(InstantiateConfig):
    _target: type = field(default_factory=lambda: DataManager)
    dataparser: DataParserConfig = field(default_factory=DataParserConfig)
    """How the dataset folder is read: downscale, splits, metric scale, where resized copies go."""
    moved_fields: ClassVar[dict[str, str]] = {name: f"dataparser.{name}" for name in MOVED_TO_DATAPARSER}
    """Fields that moved into ``dataparser``: older config.yml files and override dicts name them here."""


class DataManager(ABC):
    """The DataManager contract (abstract): ``next_train``, ``next_eval`` and eval splits by name.
    Ray managers hand out ray batches, full-image managers one camera and its image."""

    config: DataManagerConfig

    def __init__(self, config: DataManagerConfig, data: Path, device: torch.device | str = "cpu", seed: int = 0) -> None:
        self.config = config
        self.data = Path(data)
        self.device = torch.device(device)
        self.parser = config.dataparser.setup(self.data)
        self.train_data: DataparserOutputs = self.parser.parse("train")
        if len(self.train_data) == 0:
            raise DataError("the train split is empty", self.data)
        self.train_images: ImageSet = load_image_set(self.train_data).to(self.device)
        self.extra_images: Optional[ImageSet] = None
        self.extra_prob = 0.0
        self.extra_view_probs: Optional[Tensor] = None
        self._split_names = [s for s in self.parser.splits() if s != "train"]
        self._eval_cache: dict[str, tuple[DataparserOutputs, ImageSet]] = {}
        self.generator = torch.Generator().manual_seed(seed)

    # ------------------------------------------------------------------ augmentation hooks
    def set_train_images(self, images: ImageSet) -> None:
        """Replace the training pixels (e.g. with transient-free composites); cameras stay."""
        self.train_images = images.to(self.device)

    def set_extra_images(self, images: Optional[ImageSet], prob: float, view_probs: Optional[Tensor] = None) -> None:
        """Mix ``images`` into training with probability ``prob`` per sample; ``view_probs`` ``[len(images)]``:
        how often each is drawn among them (None: all alike)."""
        self.extra_images = images.to(self.device) if images is not None and len(images) else None
        self.extra_prob = float(prob) if self.extra_images is not None else 0.0
        if view_probs is not None and (self.extra_images is None or len(view_probs) != len(self.extra_images)):
            raise ValueError("view_probs needs one probability per extra image")
        self.extra_view_probs = view_probs.double().cpu() if view_probs is not None else None

    @property
    def all_train_cameras(self) -> Cameras:
        """Real then extra training cameras: the index space of ``camera_indices``/``image_idx``."""
        if self.extra_images is None:
            return self.train_images.cameras
        return Cameras.cat([self.train_images.cameras, self.extra_images.cameras])

    def train_batch(self, i: int) -> dict[str, Any]:
        """Training view ``i`` of :attr:`all_train_cameras` (real then extra) as a whole-image batch; an extra
        view carries all-false masks of the kinds the real ones have (nothing of a render is sky or transient)."""
        n = len(self.train_images)
        if i < n or self.extra_images is None:
            return self.train_images.image_batch(i)
        batch = self.extra_images.image_batch(i - n)
        batch["image_idx"] = i
        for kind in self.train_images.masks:
            batch.setdefault(f"{kind}_mask", torch.zeros_like(batch["image"][..., :1], dtype=torch.bool))
        return batch

    # ------------------------------------------------------------------ eval
    def eval_split_names(self) -> list[str]:
        ordered = [s for s in PREFERRED_EVAL_SPLITS if s in self._split_names]
        return ordered + [s for s in self._split_names if s not in ordered]

    def eval_split(self, name: str) -> tuple[DataparserOutputs, ImageSet]:
        if name not in self._eval_cache:
            if name not in self._split_names:
                raise DataError(f"no eval split '{name}' (the dataset has: {', '.join(self.eval_split_names()) or 'none'})", self.data)
            outputs = self.parser.parse(name)
            if len(outputs) == 0:
                raise DataError(f"eval split '{name}' is empty", self.data)
            self._eval_cache[name] = (outputs, load_image_set(outputs).to(self.device))
        return self._eval_cache[name]

    def eval_images(self, name: str) -> Iterator[tuple[Cameras, dict[str, Any]]]:
        _, images = self.eval_split(name)
        for i in range(len(images)):
            yield images.cameras[i], images.image_batch(i)

    def next_eval(self, step: int) -> tuple[Cameras, dict[str, Any]]:
        """One whole eval image (cycling through the first eval split), for periodic eval."""
        names = self.eval_split_names()
        if not names:
            return self.train_images.cameras[step % len(self.train_images)], self.train_images.image_batch(step % len(self.train_images))
        _, images = self.eval_split(names[0])
        i = step % len(images)
        return images.cameras[i], images.image_batch(i)

    # ------------------------------------------------------------------ training
    @abstractmethod
    def next_train(self, step: int) -> tuple[Any, dict[str, Any]]: ...

    def _use_extra(self) -> bool:
        return self.extra_images is not None and torch.rand((), generator=self.generator).item() < self.extra_prob

    def _extra_indices(self, n: int) -> Tensor:
        """``n`` extra-image indices drawn at :attr:`extra_view_probs` (uniform without them: the draws of before)."""
        assert self.extra_images is not None
        if self.extra_view_probs is None:
            return torch.randint(len(self.extra_images), (n,), generator=self.generator)
        return torch.multinomial(self.extra_view_probs, n, replacement=True, generator=self.generator)

    def initial_points(self) -> Optional[tuple[Tensor, Tensor]]:
        """Points ``[P, 3]`` (normalised world) and colours ``[P, 3]`` (0-1) a model may start from besides the
        dataset's sparse points (the augmentation's: where only its views see the scene); None: none."""
        return None

    def state_dict(self) -> dict:
        return {"generator": self.generator.get_state()}

    def load_state_dict(self, state: dict) -> None:
        if "generator" in state:
            # a checkpoint loaded with map_location="cuda" moves the (CPU) generator's state there
            self.generator.set_state(state["generator"].cpu())
