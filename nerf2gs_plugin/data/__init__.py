"""Datasets: nerfstudio and COLMAP parsers, masks, undistortion, normalisation, synthetic street.

The datamanagers call :func:`parse_dataset` and :func:`list_splits` only; the format is detected
from the folder (``transforms.json`` -> nerfstudio, a COLMAP ``sparse`` model -> COLMAP).
"""

from __future__ import annotations

from pathlib import Path
from typing import Union

from nerf2gs_plugin.data.colmap_parser import ColmapDataParserConfig, find_model_dir
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.nerfstudio_parser import NerfstudioDataParserConfig
from nerf2gs_plugin.data.normalize import (
    DataparserTransform,
    NormalizeOptions,
    load_dataparser_transform,
    save_dataparser_transform,
)
from nerf2gs_plugin.errors import DataError

__all__ = [
    "MASK_KINDS",
    "ColmapDataParserConfig",
    "DataparserOutputs",
    "DataparserTransform",
    "NerfstudioDataParserConfig",
    "NormalizeOptions",
    "dataparser_config",
    "folder_fingerprint",
    "list_splits",
    "load_dataparser_transform",
    "parse_dataset",
    "save_dataparser_transform",
]

ParserConfig = Union[NerfstudioDataParserConfig, ColmapDataParserConfig]


def dataparser_config(data: Union[str, Path], downscale: float = 1.0, **options) -> ParserConfig:
    """The parser config for a dataset folder (or a ``transforms.json`` file), by auto-detection.
    ``options``: ``holdout_every``, ``metres_per_unit``, ``camera_height`` (None = the parser's default)."""
    data = Path(data)
    options = {k: v for k, v in options.items() if v is not None}
    if data.is_file() and data.suffix.lower() == ".json":
        return NerfstudioDataParserConfig(data=data, downscale=downscale, **options)
    if not data.exists():
        raise DataError("dataset folder does not exist", data)
    if (data / "transforms.json").is_file():
        return NerfstudioDataParserConfig(data=data, downscale=downscale, **options)
    if find_model_dir(data) is not None:
        return ColmapDataParserConfig(data=data, downscale=downscale, **options)
    raise DataError("not a dataset: no transforms.json and no COLMAP model (sparse/0 or sparse/)", data)


def parse_dataset(data: Union[str, Path], split: str = "train", downscale: float = 1.0, **options) -> DataparserOutputs:
    """One split of the dataset at ``data``, normalised (same transform for every split)."""
    return dataparser_config(data, downscale, **options).parse(split)


def folder_fingerprint(data: Union[str, Path]) -> str:
    """The content fingerprint of the dataset at ``data`` (its training images), which keys bench
    runs and caches: a moved copy keeps it, a regenerated scene does not."""
    from nerf2gs_plugin.data.fingerprint import dataset_fingerprint

    return dataset_fingerprint(parse_dataset(data, "train").image_filenames)


def list_splits(data: Union[str, Path], **options) -> list[str]:
    """Split names of the dataset at ``data``: "train" first, then its eval splits."""
    return dataparser_config(data, **options).splits()
