"""Entry-point plugins (methods, dataparsers): load ``module:attribute`` references, and every entry
point of a group, so that a plugin that fails to load is reported by name and skipped and never
breaks the others."""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Iterable


def load_ref(ref: str) -> object:
    """``"package.module:attribute"`` -> the attribute (imports the module)."""
    module, attr = ref.split(":")
    return getattr(importlib.import_module(module), attr)


def load_entry_points(group: str, expected: type, taken: Iterable[str] = ()) -> tuple[dict[str, object], dict[str, str]]:
    """Every entry point of ``group`` that loads to an ``expected`` instance under a name not in
    ``taken`` -> (name -> object, name -> one-line reason it was skipped)."""
    found: dict[str, object] = {}
    failures: dict[str, str] = {}
    taken = set(taken)
    for ep in entry_points(group=group):
        try:
            obj = ep.load()
            if not isinstance(obj, expected):
                raise TypeError(f"entry point {ep.value} is a {type(obj).__name__}, not a {expected.__name__}")
        except KeyboardInterrupt:
            raise
        except BaseException as e:  # noqa: BLE001 - a broken plugin (even one calling sys.exit) never breaks the others
            failures[ep.name] = f"{type(e).__name__}: {e}"
            continue
        if ep.name in taken or ep.name in found:
            failures[ep.name] = f"name clashes with an already registered one; plugin {ep.value} ignored"
            continue
        found[ep.name] = obj
    return found, failures
