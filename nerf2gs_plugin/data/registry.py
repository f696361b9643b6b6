"""Dataparser registry: the built-in formats in code, third-party ones from the entry-point group
``nerf2gs.dataparsers``. A dataset folder is parsed by the first parser whose ``detect`` accepts
it (built-ins first). A plugin that fails to load is reported by name and skipped.

A new format is one module plus one registration: a :class:`DataParserSpecification` whose
``config(data, downscale)`` returns an object with ``splits() -> list[str]`` and
``parse(split) -> DataparserOutputs`` (``data.base.build_outputs`` does the normalisation,
undistortion and packaging from raw frames).
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass
from functools import lru_cache
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Callable

ENTRY_POINT_GROUP = "nerf2gs.dataparsers"


@dataclass(frozen=True)
class DataParserSpecification:
    """A dataset format: whether a folder holds it, and the parser config that reads it."""

    detect: Callable[[Path], bool]
    config: Callable[[Path, float], Any]  # (data folder, downscale) -> config with splits() and parse(split)
    description: str


# name -> "module:attribute" of a DataParserSpecification, imported on first use
BUILTIN_DATAPARSERS: dict[str, str] = {
    "nerfstudio": "nerf2gs_plugin.data.nerfstudio_parser:nerfstudio_dataparser",
    "colmap": "nerf2gs_plugin.data.colmap_parser:colmap_dataparser",
}


@dataclass
class DataParserDiscovery:
    parsers: dict[str, DataParserSpecification]
    failures: dict[str, str]  # name -> one-line reason


def _load(ref: str) -> object:
    module, attr = ref.split(":")
    return getattr(importlib.import_module(module), attr)


@lru_cache(maxsize=1)
def discover_dataparsers() -> DataParserDiscovery:
    """Built-ins, then every entry point of ``nerf2gs.dataparsers``; failures reported once."""
    parsers: dict[str, DataParserSpecification] = {name: _load(ref) for name, ref in BUILTIN_DATAPARSERS.items()}
    failures: dict[str, str] = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            spec = ep.load()
            if not isinstance(spec, DataParserSpecification):
                raise TypeError(f"entry point {ep.value} is a {type(spec).__name__}, not a DataParserSpecification")
            if ep.name in parsers:
                raise ValueError(f"name clashes with an already registered dataparser; plugin {ep.value} ignored")
        except Exception as e:  # noqa: BLE001 - a broken plugin must never break the other formats
            failures[ep.name] = f"{type(e).__name__}: {e}"
            print(f"warning: dataparser plugin '{ep.name}' failed to load and is skipped ({failures[ep.name]})",
                  file=sys.stderr)
            continue
        parsers[ep.name] = spec
    return DataParserDiscovery(parsers, failures)
