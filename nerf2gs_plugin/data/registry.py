"""Dataparser registry: the built-in formats in code, third-party ones from the entry-point group
``nerf2gs.dataparsers``. A dataset folder is parsed by the first parser whose ``detect`` accepts
it (built-ins first). A plugin that fails to load is reported by name and skipped.

A new format is one module plus one registration: a :class:`DataParserSpecification` whose
``config`` is the format's parser config, a dataclass with a ``data`` and a ``downscale`` field (and
any of :class:`~nerf2gs_plugin.data.parser_config.DataParserConfig`'s options it supports) and the
methods ``splits() -> list[str]`` and ``parse(split) -> DataparserOutputs`` (``data.base.build_outputs``
does the normalisation, undistortion and packaging from raw frames). A callable
``config(data, downscale, **options)`` (the older contract) is still accepted.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable

from nerf2gs_plugin.utils.plugins import load_entry_points, load_ref

ENTRY_POINT_GROUP = "nerf2gs.dataparsers"


@dataclass(frozen=True)
class DataParserSpecification:
    """A dataset format: whether a folder holds it, and the parser config that reads it."""

    detect: Callable[[Path], bool]
    config: Callable[..., Any]  # the parser config dataclass (or a callable (data, downscale, **options))
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


@lru_cache(maxsize=1)
def discover_dataparsers() -> DataParserDiscovery:
    """Built-ins, then every entry point of ``nerf2gs.dataparsers``; failures reported once."""
    parsers: dict[str, DataParserSpecification] = {name: load_ref(ref) for name, ref in BUILTIN_DATAPARSERS.items()}
    plugins, failures = load_entry_points(ENTRY_POINT_GROUP, DataParserSpecification, parsers)
    for name, reason in failures.items():
        print(f"warning: dataparser plugin '{name}' failed to load and is skipped ({reason})", file=sys.stderr)
    return DataParserDiscovery({**parsers, **plugins}, failures)
