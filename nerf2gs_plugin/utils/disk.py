"""Which disk a path is on, and what is left on it (for errors that name the disk)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path


def existing_parent(path: Path) -> Path:
    """``path`` itself when it exists, else its nearest existing parent (absolute)."""
    path = Path(path).absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def mount_point(path: Path) -> Path:
    """The mount point of the disk that holds ``path`` (or would hold it)."""
    path = existing_parent(path)
    while not os.path.ismount(path) and path != path.parent:
        path = path.parent
    return path


def free_bytes(path: Path) -> int:
    """Bytes free on the disk that holds (or would hold) ``path``."""
    return shutil.disk_usage(existing_parent(path)).free
