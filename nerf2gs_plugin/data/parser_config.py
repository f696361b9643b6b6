"""The dataparser config a DataManager holds (``--pipeline.datamanager.dataparser.*``): the options
every format takes. The format itself is detected from the folder by the registered dataparsers
(:mod:`.registry`), and :meth:`DataParserConfig.setup` builds that format's own parser config.

The options sat on the DataManager config before; their old flags stay as aliases and old
``config.yml`` files are read through :data:`MOVED_TO_DATAPARSER`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Optional, Union

import tyro

from nerf2gs_plugin.data.registry import discover_dataparsers
from nerf2gs_plugin.errors import ConfigError, DataError

OLD_FLAG_PREFIX = "--pipeline.datamanager."


def _old_flag(name: str) -> Any:
    """The flag this option had on the DataManager config, kept working."""
    return tyro.conf.arg(aliases=(OLD_FLAG_PREFIX + name.replace("_", "-"),))


@dataclass
class DataParserConfig:
    """How a dataset folder is read (the format is detected from the folder)."""

    downscale: Annotated[float, _old_flag("downscale")] = 1.0
    """Shrink images on load by this factor (2 = half size)."""
    holdout_every: Annotated[Optional[int], _old_flag("holdout_every")] = None
    """Datasets without split keys: every N-th frame is the "test" split (None: the parser's 8; 0: none)."""
    metres_per_unit: Annotated[Optional[float], _old_flag("metres_per_unit")] = None
    """Metres per data unit (overrides the dataset's metres_per_unit / scene.json)."""
    camera_height: Annotated[Optional[float], _old_flag("camera_height")] = None
    """Metric scale and up from the ground plane fitted to the sparse points, the train cameras being this
    many metres above it (e.g. 1.5 for a car); for captures in arbitrary units (the bird's-eye height is then in metres)."""
    cache_dir: Annotated[Optional[Path], _old_flag("cache_dir")] = None
    """Where undistorted / resized copies of the images go (default: DATA/.ns2gs_cache, or $NS2GS_CACHE_DIR)."""

    def setup(self, data: Union[str, Path]) -> Any:
        """The parser config for ``data`` (a folder or a ``transforms.json``): the first registered
        dataparser that detects its format, given the options set here (None = the parser's default)."""
        data = Path(data)
        if not data.exists():
            raise DataError("dataset folder does not exist", data)
        for name, spec in discover_dataparsers().parsers.items():
            if spec.detect(data):
                return build_parser(name, spec.config, data, self)
        raise DataError("not a dataset: no transforms.json and no COLMAP model (sparse/0 or sparse/)", data)


MOVED_TO_DATAPARSER = tuple(f.name for f in dataclasses.fields(DataParserConfig))
"""DataManager config fields that moved into its ``dataparser`` (read from older config.yml files)."""


def build_parser(name: str, config: Any, data: Path, options: DataParserConfig) -> Any:
    """A format's parser config: ``config`` is its dataclass (built with ``data``, ``downscale`` and
    the options that are set), or a callable ``(data, downscale, **options)`` (the older plugin contract)."""
    values = {k: v for k, v in dataclasses.asdict(options).items() if v is not None and k != "downscale"}
    if not (isinstance(config, type) and dataclasses.is_dataclass(config)):  # its files go to the default cache
        return config(data, options.downscale, **{k: v for k, v in values.items() if k != "cache_dir"})
    accepted = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(values) - accepted)
    if unknown:
        raise ConfigError(f"dataparser '{name}' takes no option {', '.join(unknown)}", "--pipeline.datamanager.dataparser")
    return config(data=data, downscale=options.downscale, **values)
