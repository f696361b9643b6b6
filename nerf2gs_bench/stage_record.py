"""The seconds a bench stage took, saved beside what it made, under the key of what made it.

A rerun that reuses a stage's output takes ~0 s for it; the bench then reports the seconds saved when
the output was made. The key holds the hash of the code that made it: output made by other code is
not reused (the stage runs again and saves its own seconds)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Optional

from nerf2gs_plugin.utils.io import atomic_write_text


def stage_key(*parts: Any) -> str:
    """12 hex digits over ``parts`` (code hashes, options, input fingerprints), JSON-encoded."""
    return hashlib.sha1(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:12]


def read_stage(path: Path, key: str) -> Optional[dict]:
    """The record saved at ``path`` when its key is ``key``; None when absent, unreadable or made otherwise."""
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and record.get("key") == key else None


def write_stage(path: Path, key: str, seconds: float, **extra: Any) -> dict:
    """Save ``seconds`` (and ``extra``) under ``key`` at ``path``; returns the record."""
    record = {"key": key, "seconds": round(float(seconds), 1), **extra}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(path), json.dumps(record, indent=1, default=str))
    return record
