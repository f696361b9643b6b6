"""Config base helpers: dataclass configs that build their class, and the plain-value round trip
(dataclass tree <-> YAML-safe dict) that run configs and benches use.

Loading starts from a registered default config and applies stored values with type checks, so a
renamed or removed field is a clear error instead of arbitrary code (a field a config moved into a
nested one, listed in its ``moved_fields``, is read at its old place too).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import UnionType
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from nerf2gs_plugin.errors import ConfigError

T = TypeVar("T")


@dataclasses.dataclass
class InstantiateConfig:
    """A config that knows the class it builds (``_target``), like nerfstudio's."""

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
    values = _moved(values, getattr(type(default), "moved_fields", {}), where)
    hints = get_type_hints(type(default))
    names = {f.name for f in dataclasses.fields(default) if not f.name.startswith("_")}
    changes = {}
    for key, value in values.items():
        if key not in names:
            raise ConfigError(f"{where}: unknown field '{key}'")
        current = getattr(default, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, dict):  # e.g. a truncated config.yml: "datamanager:" with nothing under it
                raise ConfigError(f"{where}.{key}: expected a mapping, got {value!r}")
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


def _moved(values: dict, moved: dict[str, str], where: str) -> dict:
    """``values`` with each field a config lists in its ``moved_fields`` (old name -> ``parent.name``)
    put under its new parent: configs saved before the move still load."""
    if not any(old in values for old in moved):
        return values
    values = dict(values)
    for old, new in moved.items():
        if old not in values:
            continue
        parent, _, name = new.partition(".")
        nested = values.get(parent) or {}
        if not isinstance(nested, dict) or name in nested:
            raise ConfigError(f"{where}: '{old}' moved to '{new}', which is given too")
        values[parent] = {**nested, name: values.pop(old)}
    return values


def missing_fields(default: Any, values: Any, where: str = "") -> list[str]:
    """Dotted names of the fields of ``default`` (recursively) that ``values`` does not set."""
    if not isinstance(values, dict):
        return []
    values = _moved(values, getattr(type(default), "moved_fields", {}), where)  # at their old place: given
    out: list[str] = []
    for f in dataclasses.fields(default):
        if f.name.startswith("_"):
            continue
        name = f"{where}{f.name}"
        if f.name not in values:
            out.append(name)
            continue
        current = getattr(default, f.name)
        if dataclasses.is_dataclass(current):
            out += missing_fields(current, values[f.name], name + ".")
        elif isinstance(current, dict) and isinstance(values[f.name], dict) and all(dataclasses.is_dataclass(v) for v in current.values()):
            for k, v in current.items():
                if k not in values[f.name]:
                    out.append(f"{name}.{k}")
                else:
                    out += missing_fields(v, values[f.name][k], f"{name}.{k}.")
    return out


_SIMPLE = (str, int, float, bool)


def _check_hint(value: Any, hint: Any, where: str) -> None:
    """A value for a field whose default is None: its type must be one the field's hint allows
    (``Optional[str]`` takes a string, not ``[a, list]``); hints other than plain types pass."""
    origin = get_origin(hint)
    if origin is Literal:
        if value not in get_args(hint):
            raise ConfigError(f"{where}: expected one of {', '.join(map(repr, get_args(hint)))}, got {value!r}")
        return
    options = [a for a in get_args(hint) if a is not type(None)] if origin in (Union, UnionType) else [hint]
    if not options or not all(o in _SIMPLE for o in options):
        return
    for o in options:
        if o is bool and isinstance(value, bool):
            return
        if o in (int, float) and isinstance(value, (int, float)) and not isinstance(value, bool) and (o is float or isinstance(value, int)):
            return
        if o is str and isinstance(value, str):
            return
    raise ConfigError(f"{where}: expected {' or '.join(o.__name__ for o in options)}, got {value!r}"[:300])


def _coerce(value: Any, current: Any, hint: Any, where: str) -> Any:
    if value is None:
        return None
    if current is None and hint is not None:
        _check_hint(value, hint, where)
    if isinstance(current, Path) or hint in (Path, "Path") or Path in get_args(hint):  # Optional[Path] too
        if not isinstance(value, (str, Path)):
            raise ConfigError(f"{where}: expected a path, got {value!r}"[:300])
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
