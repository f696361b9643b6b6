"""Random rays from all training pixels (NeRF methods)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch

from nerf2gs_plugin.cameras import RayBundle
from nerf2gs_plugin.datamanagers.base import DataManager, DataManagerConfig
from nerf2gs_plugin.datamanagers.image_set import ImageSet


@dataclass
class RayDataManagerConfig(DataManagerConfig):
    _target: type = field(default_factory=lambda: RayDataManager)
    rays_per_batch: int = 1024
    """Rays per training step."""


class RayDataManager(DataManager):
    config: RayDataManagerConfig

    def _pixels(self, images: ImageSet, n: int, extra: bool) -> torch.Tensor:
        """``n`` flat pixel indices: uniform over all pixels, or (extra views with view probabilities)
        an image at its probability, then a pixel of it."""
        if not extra or self.extra_view_probs is None:
            return torch.randint(images.num_pixels, (n,), generator=self.generator)
        img = self._extra_indices(n)
        sizes = (images.cameras.height * images.cameras.width).reshape(-1).long().cpu()[img]
        return images.offsets.cpu()[img] + (torch.rand(n, generator=self.generator, dtype=torch.float64) * sizes).long()

    def _sample(self, images: ImageSet, n: int, index_offset: int, extra: bool = False) -> tuple[RayBundle, dict[str, Any]]:
        flat = self._pixels(images, n, extra).to(self.device)
        img, v, u = images.locate(flat)
        rays = images.cameras.generate_rays(img, torch.stack([u, v], dim=-1))
        rays.camera_indices = img + index_offset
        batch: dict[str, Any] = {
            "rgb": images.pixels[flat],
            "weight": images.weights[img][:, None],
            "image_idx": img + index_offset,
        }
        if images.confidence is not None:  # reference renders: a ray weighs as much as the reference knows its pixel
            batch["weight"] = batch["weight"] * images.confidence[flat][:, None]
        for kind in self.train_images.masks:
            m = images.masks.get(kind)
            batch[f"{kind}_mask"] = m[flat][:, None] if m is not None else torch.zeros(n, 1, dtype=torch.bool, device=self.device)
        return rays, batch

    def next_train(self, step: int) -> tuple[RayBundle, dict[str, Any]]:
        n = self.config.rays_per_batch
        n_extra = 0
        if self.extra_images is not None and self.extra_prob > 0:
            n_extra = int(torch.binomial(torch.tensor(float(n)), torch.tensor(self.extra_prob), generator=self.generator))
        rays, batch = self._sample(self.train_images, n - n_extra, 0)
        if n_extra == 0:
            return rays, batch
        rays_x, batch_x = self._sample(self.extra_images, n_extra, len(self.train_images), extra=True)
        rays = RayBundle(*(torch.cat([getattr(rays, k), getattr(rays_x, k)]) for k in ("origins", "directions", "pixel_radius", "camera_indices")))
        return rays, {k: torch.cat([batch[k], batch_x[k]]) for k in batch}
