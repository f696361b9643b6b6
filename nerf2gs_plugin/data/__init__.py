"""Datasets: nerfstudio and COLMAP parsers, masks, undistortion, normalisation, synthetic street.

The datamanagers call :func:`parse_dataset` and :func:`list_splits` only; the format is detected
from the folder by the registered dataparsers (:mod:`.registry`: ``transforms.json`` -> nerfstudio,
a COLMAP ``sparse`` model -> COLMAP, then plugins of the ``nerf2gs.dataparsers`` entry-point group).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Union

from nerf2gs_plugin.data.colmap_parser import ColmapDataParserConfig
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.nerfstudio_parser import NerfstudioDataParserConfig
from nerf2gs_plugin.data.normalize import (
    DataparserTransform,
    NormalizeOptions,
    load_dataparser_transform,
    save_dataparser_transform,
)
from nerf2gs_plugin.data.registry import discover_dataparsers
from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.data.fingerprint import dataset_fingerprint

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

def dataparser_config(data: Union[str, Path], downscale: float = 1.0) -> Any:
    """The parser config for a dataset folder (or a ``transforms.json`` file): the first registered
    dataparser that detects its format."""
    data = Path(data)
    if not data.exists():
        raise DataError("dataset folder does not exist", data)
    for spec in discover_dataparsers().parsers.values():
        if spec.detect(data):
            return spec.config(data, downscale)
    raise DataError("not a dataset: no transforms.json and no COLMAP model (sparse/0 or sparse/)", data)


def parse_dataset(data: Union[str, Path], split: str = "train", downscale: float = 1.0) -> DataparserOutputs:
    """One split of the dataset at ``data``, normalised (same transform for every split)."""
    return dataparser_config(data, downscale).parse(split)


def folder_fingerprint(data: Union[str, Path]) -> str:
    """The content fingerprint of the dataset at ``data`` (its training images), which keys bench
    runs and caches: a moved copy keeps it, a regenerated scene does not."""
    return dataset_fingerprint(parse_dataset(data, "train").image_filenames)


def list_splits(data: Union[str, Path]) -> list[str]:
    """Split names of the dataset at ``data``: "train" first, then its eval splits."""
    return dataparser_config(data).splits()
