"""Datasets: nerfstudio and COLMAP parsers, masks, undistortion, normalisation, synthetic street.

The datamanagers hold a :class:`DataParserConfig` (the options) and call its ``setup``; the format is detected
from the folder by the registered dataparsers (:mod:`.registry`: ``transforms.json`` -> nerfstudio,
a COLMAP ``sparse`` model -> COLMAP, then plugins of the ``nerf2gs.dataparsers`` entry-point group).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Union

from nerf2gs_plugin.data.colmap_parser import ColmapDataParserConfig, find_model_dir
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.nerfstudio_parser import NerfstudioDataParserConfig
from nerf2gs_plugin.data.normalize import (
    DataparserTransform,
    NormalizeOptions,
    load_dataparser_transform,
    save_dataparser_transform,
)
from nerf2gs_plugin.data.parser_config import DataParserConfig
from nerf2gs_plugin.data.fingerprint import dataset_fingerprint

__all__ = [
    "MASK_KINDS",
    "ColmapDataParserConfig",
    "DataParserConfig",
    "DataparserOutputs",
    "DataparserTransform",
    "NerfstudioDataParserConfig",
    "NormalizeOptions",
    "dataparser_config",
    "dataset_files",
    "folder_fingerprint",
    "list_splits",
    "load_dataparser_transform",
    "parse_dataset",
    "save_dataparser_transform",
]

def dataparser_config(data: Union[str, Path], downscale: float = 1.0, **options) -> Any:
    """The parser config for a dataset folder (or a ``transforms.json`` file): the first registered
    dataparser that detects its format. ``options``: the other fields of :class:`DataParserConfig`
    (``holdout_every``, ``metres_per_unit``, ``camera_height``, ``cache_dir``; None = the default)."""
    return DataParserConfig(downscale=downscale, **options).setup(data)


def parse_dataset(data: Union[str, Path], split: str = "train", downscale: float = 1.0, **options) -> DataparserOutputs:
    """One split of the dataset at ``data``, normalised (same transform for every split)."""
    return dataparser_config(data, downscale, **options).parse(split)


def dataset_files(data: Union[str, Path]) -> list[Path]:
    """Every file a training or evaluation run on ``data`` reads: the dataset description
    (transforms.json or the COLMAP model), the sparse points, and each split's images, masks and
    depth maps (eval splits included)."""
    data = Path(data)
    root = data.parent if data.is_file() else data
    files: list[Path] = []
    cfg = dataparser_config(data)
    if isinstance(cfg, NerfstudioDataParserConfig):
        meta_path = data if data.is_file() else data / "transforms.json"
        files.append(meta_path)
        try:
            ply = json.loads(meta_path.read_text()).get("ply_file_path")
        except (OSError, ValueError, AttributeError):
            ply = None
        if ply:
            files.append(meta_path.parent / str(ply))
    else:
        model = find_model_dir(root)
        files += sorted(p for p in model.iterdir() if p.is_file()) if model is not None else []
    for split in cfg.splits():
        out = cfg.parse(split)
        files += list(out.image_filenames)
        files += [p for paths in out.mask_filenames.values() for p in paths if p is not None]
        files += [p for p in (out.depth_filenames or []) if p is not None]
    return files


def folder_fingerprint(data: Union[str, Path]) -> str:
    """The content fingerprint of the dataset at ``data``, which keys bench runs and caches: every
    file a run reads (:func:`dataset_files`; content of small files, size + mtime + ends of big
    ones). A moved copy of small files keeps it; a regenerated scene, a changed mask, pose, point
    or eval image does not."""
    from nerf2gs_plugin.data.fingerprint import files_fingerprint

    data = Path(data)
    return files_fingerprint(dataset_files(data), data.parent if data.is_file() else data)


def list_splits(data: Union[str, Path], **options) -> list[str]:
    """Split names of the dataset at ``data``: "train" first, then its eval splits."""
    return dataparser_config(data, **options).splits()
