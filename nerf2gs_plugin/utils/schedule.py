"""Step-valued settings, marked where they are declared, and the one function that rescales them.

A config field whose value is a step count carries ``metadata={"schedule": kind}`` (use
:func:`scheduled`); :func:`with_steps` walks any tree of config dataclasses (and dicts of them) and
rescales every marked field to a new step budget, so no list of other methods' field names is
needed and a third-party method's marked fields are rescaled too. Kinds:

* ``total``    the run length (``max_num_iterations``): becomes ``steps``; it defines the ratio;
* ``step``     a step at which something starts/stops/repeats: ``max(1, round(v * ratio))``;
* ``interval`` a refinement interval: shrinks with the budget but stays ``>= 20`` steps apart
  (and never grows): ``max(20, min(v, round(v * ratio)))``;
* ``cap``      at most the run length (``steps_per_save``): ``min(v, steps)``;
* ``horizon``  a decay horizon (an optimizer's ``max_steps``): becomes ``steps``, only where the
  sibling field named by ``metadata["only_if"]`` is not None (a decaying learning rate).

Imports nothing of the package (the ground floor).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Optional, TypeVar

T = TypeVar("T")
SCHEDULE_KEY = "schedule"
KINDS = ("total", "step", "interval", "cap", "horizon")
MIN_INTERVAL = 20


def scheduled(default: int, kind: str = "step", only_if: Optional[str] = None) -> Any:
    """A dataclass field holding a step count of ``kind`` (see the module docstring)."""
    if kind not in KINDS:
        raise ValueError(f"unknown schedule kind {kind!r} (one of {', '.join(KINDS)})")
    meta = {SCHEDULE_KEY: kind, **({"only_if": only_if} if only_if else {})}
    return dataclasses.field(default=default, metadata=meta)


def schedule_fields(config: Any) -> dict[str, str]:
    """``{field name: kind}`` of the marked fields of one config dataclass (not nested)."""
    return {f.name: f.metadata[SCHEDULE_KEY] for f in dataclasses.fields(config) if SCHEDULE_KEY in f.metadata}


def _is_config(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _total(config: Any) -> int:
    names = [name for name, kind in schedule_fields(config).items() if kind == "total"]
    if len(names) != 1:
        raise ValueError(f"{type(config).__name__} marks {len(names)} fields as the run length (schedule 'total'), expected 1")
    return int(getattr(config, names[0]))


def _rescaled(value: Any, steps: int, ratio: float) -> Any:
    if isinstance(value, dict):
        return {k: _rescaled(v, steps, ratio) for k, v in value.items()}
    if not _is_config(value):
        return value
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(value):
        v = getattr(value, f.name)
        kind = f.metadata.get(SCHEDULE_KEY)
        if kind is None:
            nested = _rescaled(v, steps, ratio)
            if nested is not v:
                changes[f.name] = nested
        elif kind == "total":
            changes[f.name] = steps
        elif kind == "step":
            changes[f.name] = max(1, int(round(v * ratio)))
        elif kind == "interval":
            changes[f.name] = max(MIN_INTERVAL, min(v, int(round(v * ratio))))
        elif kind == "cap":
            changes[f.name] = min(v, steps)
        elif kind == "horizon" and getattr(value, f.metadata.get("only_if", f.name)) is not None:
            changes[f.name] = steps
    return dataclasses.replace(value, **changes) if changes else value


def with_steps(config: T, steps: int) -> T:
    """``config`` (at its own run length) with every marked schedule rescaled to ``steps``."""
    ratio = steps / max(_total(config), 1)
    return _rescaled(config, int(steps), ratio)
