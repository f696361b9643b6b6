"""Per-image appearance: a learned 3x4 affine colour transform per training image.

``rgb' = A_i[:, :3] @ rgb + A_i[:, 3]``, initialised to the identity, absorbs exposure and
white-balance differences between input images (StreetNeRF's appearance embedding, in the
affine form of Urban Radiance Fields' exposure compensation). Cameras that are not training
images (novel, bird's-eye or augmentation views: index >= num_images) use the mean transform,
which is the identity when the transforms are regularised towards it (or, with ``novel="identity"``,
the identity itself; a model may also pick a training image's transform for them, e.g. the nearest).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


class AppearanceTransforms(nn.Module):
    def __init__(self, num_images: int) -> None:
        super().__init__()
        eye = torch.eye(3, 4)
        self.transforms = nn.Parameter(eye.expand(max(num_images, 1), 3, 4).clone())
        self.num_images = num_images

    def mean_transform(self) -> Tensor:
        return self.transforms.mean(0)

    def forward(self, rgb: Tensor, image_idx: Tensor | None, novel: str = "mean") -> Tensor:
        """``rgb [R,3]``, ``image_idx [R]`` (or None: all novel) -> transformed ``[R,3]``; novel
        rows get the ``"mean"`` transform or the ``"identity"``."""
        if novel == "identity":
            fallback = torch.eye(3, 4, device=self.transforms.device, dtype=self.transforms.dtype)
        elif novel == "mean":
            fallback = self.mean_transform()
        else:
            raise ValueError(f"novel must be 'mean' or 'identity', got {novel!r}")
        if image_idx is None:
            A = fallback.expand(rgb.shape[0], 3, 4)
        else:
            idx = image_idx.long().to(rgb.device)
            known = (idx >= 0) & (idx < self.num_images)
            A = torch.where(known[:, None, None], self.transforms[idx.clamp(0, self.num_images - 1)], fallback[None])
        return torch.einsum("rij,rj->ri", A[:, :, :3], rgb) + A[:, :, 3]

    def apply_one(self, rgb: Tensor, i: int) -> Tensor:
        """``rgb [..., 3]`` in image ``i``'s transform (one transform for every pixel: no per-row gather)."""
        A = self.transforms[i]
        return rgb @ A[:, :3].T + A[:, 3]

    def deviation(self, i: int | None = None) -> Tensor:
        """Mean squared distance of the transforms (image ``i``'s alone, when given) from the identity (a
        small regulariser)."""
        A = self.transforms if i is None else self.transforms[i]
        eye = torch.eye(3, 4, device=A.device, dtype=A.dtype)
        return ((A - eye) ** 2).mean()
