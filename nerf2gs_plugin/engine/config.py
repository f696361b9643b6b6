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
MAX_YAML_VALUES = 100_000  # a config has a few hundred; far fewer than what an alias bomb stands for
T = TypeVar("T")


def save_config(path: Path, method_name: str, config: Any) -> None:
    doc = {"format_version": CONFIG_FORMAT_VERSION, "method_name": method_name, "config": to_plain(config)}
    atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False))


def _expanded_size(node: yaml.Node, memo: dict[int, int]) -> int:
    """Values ``node`` stands for with every alias expanded (each distinct node counted once)."""
    key = id(node)
    if key not in memo:
        memo[key] = 0  # a recursive alias counts as nothing more (the constructor refuses it)
        if isinstance(node, yaml.SequenceNode):
            memo[key] = 1 + sum(_expanded_size(n, memo) for n in node.value)
        elif isinstance(node, yaml.MappingNode):
            memo[key] = 1 + sum(_expanded_size(k, memo) + _expanded_size(v, memo) for k, v in node.value)
        else:
            memo[key] = 1
    return memo[key]


def safe_load_limited(text: str, path: Path, max_values: int = MAX_YAML_VALUES) -> Any:
    """``yaml.safe_load`` that first sizes the document with its aliases expanded: an alias bomb
    (a few KB standing for billions of values) is one clear error, before anything is built."""
    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        size = _expanded_size(node, {})
        if size > max_values:
            raise ConfigError(f"YAML expands to {size:,} values through its aliases (at most {max_values:,}): "
                              "refused as an alias bomb", path)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def read_config_doc(path: Path) -> dict:
    """Read and validate a saved config.yml (not yet applied to a default)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("config file not found", path)
    try:
        doc = safe_load_limited(path.read_text(), path)
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
