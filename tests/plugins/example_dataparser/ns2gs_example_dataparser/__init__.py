"""An example third-party dataparser: a folder with ``poses.csv`` and its images.

One row per image: ``split,image,fx,fy,cx,cy,width,height`` then the 12 numbers of the OpenGL
camera-to-world matrix (3x4, row major). Masks are found in ``masks/{sky,ground,transient}/`` as for
the built-in formats; ``data.base.build_outputs`` normalises the scene and packages the split.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import torch

from nerf2gs_plugin.data.base import RawFrame, build_outputs, check_split, find_folder_mask
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.normalize import NormalizeOptions
from nerf2gs_plugin.data.registry import DataParserSpecification
from nerf2gs_plugin.data.undistort import Intrinsics
from nerf2gs_plugin.errors import DataError

FILE = "poses.csv"


@dataclass
class PosesCsvDataParserConfig:
    """The parser config: ``data`` and ``downscale``, plus the options of the DataManager's
    ``--pipeline.datamanager.dataparser.*`` it supports (here ``cache_dir``; the splits are in the file)."""

    data: Path = Path("data/poses")
    downscale: float = 1.0
    cache_dir: Optional[Path] = None
    normalize: NormalizeOptions = field(default_factory=NormalizeOptions)

    def _frames(self) -> dict[str, list[RawFrame]]:
        root = Path(self.data)
        groups: dict[str, list[RawFrame]] = {"train": []}
        with open(root / FILE, newline="") as f:
            for line, row in enumerate(csv.reader(f), start=1):
                if len(row) != 20:
                    raise DataError(f"line {line}: expected 20 columns, got {len(row)}", root / FILE)
                split, image = row[0], root / row[1]
                fx, fy, cx, cy = (float(v) for v in row[2:6])
                c2w = torch.tensor([float(v) for v in row[8:20]], dtype=torch.float32).reshape(3, 4)
                masks = {k: find_folder_mask(root, k, image) for k in MASK_KINDS}
                groups.setdefault(split, []).append(RawFrame(image, c2w, Intrinsics(fx, fy, cx, cy, int(row[6]), int(row[7])), masks))
        return groups

    def splits(self) -> list[str]:
        return list(self._frames())

    def parse(self, split: str = "train") -> DataparserOutputs:
        groups = self._frames()
        check_split(split, groups.get(split, []), list(groups), Path(self.data) / FILE)
        return build_outputs(split, groups[split], groups["train"], Path(self.data), self.normalize, float(self.downscale),
                             cache_dir=self.cache_dir)


poses_csv_dataparser = DataParserSpecification(
    detect=lambda data: data.is_dir() and (data / FILE).is_file(),
    config=PosesCsvDataParserConfig,
    description="example plugin: poses.csv (intrinsics + OpenGL camera-to-world per image)",
)
