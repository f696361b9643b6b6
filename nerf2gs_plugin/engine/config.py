"""A run's ``config.yml``: safe YAML round trips of method configs.

Configs are dataclasses that tyro turns into the CLI (bases in :mod:`nerf2gs_plugin.utils.config`).
On disk a config is safe YAML of plain
values (never pickled classes) with a format version; loading one starts from the method's
registered default config and applies the stored values, so a renamed or removed field is a
clear error instead of arbitrary code. A saved file opens with :data:`HEADER` and closes with
:data:`END_MARKER`: YAML reads a file cut short at a line boundary as valid (the missing fields
would silently take their defaults), the missing last line does not.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.config import apply_plain, missing_fields, to_plain
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.warn import warn

CONFIG_FORMAT_VERSION = 1
MAX_YAML_VALUES = 100_000  # a config has a few hundred; far fewer than what an alias bomb stands for
END_MARKER = "# end of config.yml"
HEADER = f"# nerf2gs run config; a complete file ends with the line '{END_MARKER}'\n"
T = TypeVar("T")


def save_config(path: Path, method_name: str, config: Any) -> None:
    doc = {"format_version": CONFIG_FORMAT_VERSION, "method_name": method_name, "config": to_plain(config)}
    atomic_write_text(path, HEADER + yaml.safe_dump(doc, sort_keys=False) + END_MARKER + "\n")


def is_sealed(text: str, path: Path) -> bool:
    """True for a file :func:`save_config` wrote (refused when its end marker is missing: cut short);
    False for one without the header (written by an older nerf2gs, or by hand)."""
    if not text.startswith(HEADER.split(";")[0]):
        return False
    lines = text.rstrip().splitlines()
    if lines[-1].strip() != END_MARKER:
        raise ConfigError(f"cut short: its last line is not '{END_MARKER}' (the file was truncated; "
                          "restore it or train again)", path)
    return True


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
    return _read_doc(path)[0]


def _read_doc(path: Path) -> tuple[dict, bool]:
    """The validated document and whether it was sealed (see :func:`is_sealed`)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("config file not found", path)
    try:
        text = path.read_text()
        sealed = is_sealed(text, path)
        doc = safe_load_limited(text, path)
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
    return doc, sealed


def load_config(path: Path, default: T) -> T:
    doc, sealed = _read_doc(path)
    try:
        config = apply_plain(default, doc["config"])
    except ConfigError as e:
        raise ConfigError(str(e), path) from None
    if not sealed:
        _warn_missing(path, missing_fields(default, doc["config"]))
    return config


def _warn_missing(path: Path, missing: list[str]) -> None:
    """An unsealed (older) config cannot tell a newer field from one lost to truncation: say which
    fields take their defaults, so a cut-short file is noticed."""
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        warn(f"{path} has no end marker (an older config.yml)",
             f"{len(missing)} field(s) not in it take their defaults ({shown}); if the file was cut short, restore it")
