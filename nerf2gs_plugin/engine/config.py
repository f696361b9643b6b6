"""Config base classes and safe YAML round trips.

Configs are dataclasses that tyro turns into the CLI. On disk a config is safe YAML of plain
values (never pickled classes) with a format version; loading one starts from the method's
registered default config and applies the stored values, so a renamed or removed field is a
clear error instead of arbitrary code.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path
from typing import Any, Type, TypeVar, Union, get_type_hints

import yaml

from nerf2gs_plugin.errors import ConfigError

CONFIG_FORMAT_VERSION = 1
T = TypeVar("T")


@dataclasses.dataclass
class InstantiateConfig:
    """A config that knows the class it builds (its _target field), like nerfstudio's."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Hide ``_target`` from the command line: it is the class a config builds, not a setting
        (tyro would list it as an unsettable ``{fixed}`` option)."""
        super().__init_subclass__(**kwargs)
        if "_target" in cls.__dict__.get("__annotations__", {}):
            import tyro

            cls.__annotations__["_target"] = tyro.conf.Suppress[type]

    def setup(self, **kwargs: Any) -> Any:
        target = getattr(self, "_target")
        return target(self, **kwargs)


def to_plain(obj: Any) -> Any:
    """Dataclass tree -> dict of plain YAML-safe values (paths become strings)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {
            f.name: to_plain(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if not f.name.startswith("_")
        }
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (list, tuple)):
        return [to_plain(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if isinstance(obj, type):
        return f"{obj.__module__}.{obj.__qualname__}"
    return str(obj)


def apply_plain(default: T, values: dict, where: str = "config") -> T:
    """Return ``default`` with the fields in ``values`` replaced, recursively, with type checks."""
    if not isinstance(values, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(values).__name__}")
    hints = get_type_hints(type(default))
    names = {f.name for f in dataclasses.fields(default) if not f.name.startswith("_")}
    changes = {}
    for key, value in values.items():
        if key not in names:
            raise ConfigError(f"{where}: unknown field '{key}'")
        current = getattr(default, key)
        if dataclasses.is_dataclass(current) and isinstance(value, dict):
            changes[key] = apply_plain(current, value, f"{where}.{key}")
        elif isinstance(current, dict) and isinstance(value, dict) and current and all(
            dataclasses.is_dataclass(v) for v in current.values()
        ):
            merged = dict(current)
            for k, v in value.items():
                if k not in current:
                    raise ConfigError(f"{where}.{key}: unknown entry '{k}'")
                merged[k] = apply_plain(current[k], v, f"{where}.{key}.{k}")
            changes[key] = merged
        else:
            changes[key] = _coerce(value, current, hints.get(key), f"{where}.{key}")
    return dataclasses.replace(default, **changes)


def _coerce(value: Any, current: Any, hint: Any, where: str) -> Any:
    if value is None:
        return None
    if isinstance(current, Path) or hint in (Path, "Path"):
        return Path(value)
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true/false, got {value!r}")
        return value
    if isinstance(current, (int, float)) and not isinstance(current, bool):
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return type(current)(value) if isinstance(current, float) else value
    if isinstance(current, tuple):
        return tuple(value)
    if isinstance(current, Path) and isinstance(value, str):
        return Path(value)
    if isinstance(current, str) and not isinstance(value, str):
        raise ConfigError(f"{where}: expected a string, got {value!r}")
    return value


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write to a temp file beside ``path`` then rename: readers never see half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


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
