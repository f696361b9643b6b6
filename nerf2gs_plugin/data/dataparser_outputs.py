"""What every dataparser returns: the contract between data/ and datamanagers/."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras

MASK_KINDS = ("sky", "ground", "transient")


@dataclass
class DataparserOutputs:
    """One split of a dataset, already in the normalised world frame.

    Normalised world = ``dataparser_scale * (dataparser_transform @ [x_orig; 1])``. One unit of the
    normalised world is ``1 / (dataparser_scale * metres_per_unit)`` metres... so use
    :meth:`metres_to_world` rather than doing that by hand.
    """

    image_filenames: list[Path]
    cameras: Cameras  # already undistorted when the parser undistorted the images
    # per kind ("sky", "ground", "transient"): one path (or None) per image; a kind absent from
    # the dict means the dataset has no such masks. Mask PNGs: nonzero = inside the mask.
    mask_filenames: dict[str, list[Optional[Path]]] = field(default_factory=dict)
    depth_filenames: Optional[list[Optional[Path]]] = None  # metric depth (.npy, metres, z-depth)
    points3D_xyz: Optional[Tensor] = None  # [P, 3] normalised world
    points3D_rgb: Optional[Tensor] = None  # [P, 3] uint8
    scene_box: Tensor = field(default_factory=lambda: torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]))
    dataparser_transform: Tensor = field(default_factory=lambda: torch.eye(4)[:3])  # [3, 4]
    dataparser_scale: float = 1.0
    metres_per_unit: float = 1.0  # metres per unit of the ORIGINAL (un-normalised) data frame
    up: Tensor = field(default_factory=lambda: torch.tensor([0.0, 0.0, 1.0]))  # unit, normalised world
    split: str = "train"

    def metres_to_world(self, metres: float) -> float:
        """A length in metres, in normalised world units."""
        return metres * self.dataparser_scale / self.metres_per_unit

    def world_to_metres(self, units: float) -> float:
        return units * self.metres_per_unit / self.dataparser_scale

    def __len__(self) -> int:
        return len(self.image_filenames)
