"""A run's ``config.yml``: safe YAML round trips of method configs.

Configs are dataclasses that tyro turns into the CLI (bases in :mod:`nerf2gs_plugin.utils.config`).
On disk a config is safe YAML of plain
values (never pickled classes) with a format version; loading one starts from the method's
registered default config and applies the stored values, so a renamed or removed field is a
clear error instead of arbitrary code.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.config import apply_plain, to_plain
from nerf2gs_plugin.utils.io import atomic_write_text

CONFIG_FORMAT_VERSION = 1
T = TypeVar("T")


def save_config(path: Path, method_name: str, config: Any) -> None:
    doc = {"format_version": CONFIG_FORMAT_VERSION, "method_name": method_name, "config": to_plain(config)}
    atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False))


def read_config_doc(path: Path) -> dict:
    """Read and validate a saved config.yml (not yet applied to a default)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("config file not found", path)
    try:
        doc = yaml.safe_load(path.read_text())
    except UnicodeDecodeError as e:
        raise ConfigError(f"not UTF-8 text (byte {e.start})", path) from None
    except yaml.YAMLError as e:
        first = str(e).splitlines()[0] if str(e) else "parse error"
        raise ConfigError(f"malformed YAML ({first})", path) from None
    if not isinstance(doc, dict) or "method_name" not in doc or "config" not in doc:
        raise ConfigError("not an nerf2gs config (needs method_name and config)", path)
    version = doc.get("format_version")
    if version != CONFIG_FORMAT_VERSION:
        raise ConfigError(f"config format version {version!r}, this nerf2gs reads {CONFIG_FORMAT_VERSION}", path)
    return doc


def load_config(path: Path, default: T) -> T:
    doc = read_config_doc(path)
    try:
        return apply_plain(default, doc["config"])
    except ConfigError as e:
        raise ConfigError(str(e), path) from None
