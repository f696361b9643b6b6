"""ImageSet: the pixels of a set of cameras in one flat buffer, so rays and whole images are
gathered with tensor indexing whatever the image sizes."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.images import load_image, load_mask
from nerf2gs_plugin.errors import DataError


@dataclass
class ImageSet:
    cameras: Cameras
    pixels: Tensor  # [P, 3] float in [0, 1], images concatenated row-major
    offsets: Tensor  # [N] long, first pixel of each image
    masks: dict[str, Tensor] = field(default_factory=dict)  # kind -> [P] bool
    weights: Optional[Tensor] = None  # [N] loss weight per image
    names: list[str] = field(default_factory=list)
    confidence: Optional[Tensor] = None  # [P] float in [0, 1]: per-pixel loss weight (reference renders), None = all 1
    photos: Optional[Tensor] = None  # [P, 3]: the photos under composites (a second target, --augment.composite-loss either)
    photo_margin: float = 0.0  # the photo is that target unless the image is nearer the render by more than this

    def __post_init__(self) -> None:
        if self.weights is None:
            self.weights = torch.ones(len(self.cameras), device=self.pixels.device)

    def __len__(self) -> int:
        return len(self.cameras)

    @property
    def num_pixels(self) -> int:
        return self.pixels.shape[0]

    def hw(self, i: int) -> tuple[int, int]:
        return int(self.cameras.height[i]), int(self.cameras.width[i])

    def _slice(self, flat: Tensor, i: int) -> Tensor:
        h, w = self.hw(i)
        start = int(self.offsets[i])
        return flat[start : start + h * w].reshape(h, w, -1)

    def image(self, i: int) -> Tensor:
        """``[H, W, 3]``"""
        return self._slice(self.pixels, i)

    def mask(self, kind: str, i: int) -> Optional[Tensor]:
        """``[H, W, 1]`` bool, or None when the set has no masks of that kind."""
        if kind not in self.masks:
            return None
        return self._slice(self.masks[kind], i)

    def image_batch(self, i: int) -> dict:
        batch = {"image": self.image(i), "image_idx": i, "weight": self.weights[i]}
        for kind in self.masks:
            batch[f"{kind}_mask"] = self.mask(kind, i)
        if self.confidence is not None:
            batch["confidence"] = self._slice(self.confidence, i)
        if self.photos is not None:
            batch["photo"] = self._slice(self.photos, i)
            batch["photo_margin"] = self.photo_margin
        return batch

    def locate(self, flat_index: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Flat pixel indices ``[R]`` -> (image index, v, u), each ``[R]``."""
        img = torch.searchsorted(self.offsets, flat_index, right=True) - 1
        local = flat_index - self.offsets[img]
        w = self.cameras.width.to(flat_index.device)[img]
        return img, local // w, local % w

    def to(self, device) -> "ImageSet":
        return ImageSet(
            self.cameras.to(device),
            self.pixels.to(device),
            self.offsets.to(device),
            {k: v.to(device) for k, v in self.masks.items()},
            self.weights.to(device),
            list(self.names),
            self.confidence.to(device) if self.confidence is not None else None,
            self.photos.to(device) if self.photos is not None else None,
            self.photo_margin,
        )

    def with_images(self, images: list[Tensor]) -> "ImageSet":
        """Same cameras, masks and confidence, new pixels (e.g. composites)."""
        return replace(self, pixels=torch.cat([im.reshape(-1, 3) for im in images]), masks=dict(self.masks), names=list(self.names))

    def with_photos(self, photos: Optional[Tensor], margin: float = 0.0) -> "ImageSet":
        """Same images, with ``photos`` ``[P, 3]`` (the pixels before compositing) as a second target (None: none),
        taken unless the image is nearer the render by more than ``margin`` (mean absolute RGB)."""
        if photos is not None and photos.shape != self.pixels.shape:
            raise ValueError(f"photos hold {photos.shape[0]} pixels, the images {self.num_pixels}")
        return replace(self, masks=dict(self.masks), names=list(self.names), photos=photos, photo_margin=margin)

    def with_confidence(self, maps: Optional[list[Tensor]]) -> "ImageSet":
        """Same images, a per-pixel confidence map ``[H, W, 1]`` per image (None: none)."""
        flat = torch.cat([m.reshape(-1).float() for m in maps]).to(self.pixels.device) if maps is not None else None
        if flat is not None and flat.shape[0] != self.num_pixels:
            raise ValueError(f"confidence maps hold {flat.shape[0]} pixels, the images {self.num_pixels}")
        return replace(self, masks=dict(self.masks), names=list(self.names), confidence=flat)

    @staticmethod
    def from_images(cameras: Cameras, images: list[Tensor], masks: Optional[dict[str, list[Tensor]]] = None,
                    weights: Optional[Tensor] = None, names: Optional[list[str]] = None) -> "ImageSet":
        sizes = torch.tensor([im.shape[0] * im.shape[1] for im in images], dtype=torch.long)
        offsets = torch.cat([torch.zeros(1, dtype=torch.long), sizes.cumsum(0)[:-1]])
        pixels = torch.cat([im.reshape(-1, 3).float() for im in images]) if images else torch.zeros(0, 3)
        flat_masks = {k: torch.cat([m.reshape(-1).bool() for m in ms]) for k, ms in (masks or {}).items()}
        return ImageSet(cameras, pixels, offsets.to(pixels.device), flat_masks, weights, names or [f"{i:05d}" for i in range(len(images))])


def load_image_set(outputs: DataparserOutputs) -> ImageSet:
    """Read every image (and mask) of a split into an ImageSet."""
    images, masks = [], {k: [] for k in MASK_KINDS if k in outputs.mask_filenames}
    for i, path in enumerate(outputs.image_filenames):
        img = load_image(path)
        h, w = int(outputs.cameras.height[i]), int(outputs.cameras.width[i])
        if tuple(img.shape[:2]) != (h, w):
            raise DataError(f"image is {img.shape[1]}x{img.shape[0]} but its camera says {w}x{h}", path)
        images.append(img)
        for kind in masks:
            mpath = outputs.mask_filenames[kind][i]
            masks[kind].append(load_mask(mpath, (h, w)) if mpath is not None else torch.zeros(h, w, dtype=torch.bool))
    return ImageSet.from_images(outputs.cameras, images, masks, names=[p.name for p in outputs.image_filenames])
