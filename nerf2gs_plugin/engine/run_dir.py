"""Exclusive run directories: never two trainings writing into one folder.

With the default timestamp a clash (two runs started in the same second) gets a new unique
folder (``<stamp>-1``, ``-2``, ...). With an explicit ``--timestamp`` (or ``--run-dir``) the folder is locked
(``fcntl.flock`` on ``.lock``, released by the kernel even on kill -9): a second training there
is an error, as is one that would overwrite another run's checkpoints without resuming them.
A folder is only taken when it is empty or carries the marker a training leaves (``.ns2gs_run``):
the user's own files are never overwritten.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import Optional

from nerf2gs_plugin.errors import ConfigError

LOCK_NAME = ".lock"
MARKER_NAME = ".ns2gs_run"  # written when a training takes the folder: only such folders are taken again


def unique_run_dir(path: Path) -> Path:
    """Create ``path`` (or ``path-1``, ``path-2``, ... if taken) atomically; returns the one made."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for i in range(10000):
        cand = path if i == 0 else path.with_name(f"{path.name}-{i}")
        try:
            cand.mkdir()
            return cand
        except FileExistsError:
            continue
    raise ConfigError("no free run directory name", path)


class RunDirLock:
    """An exclusive lock on a run directory for the lifetime of one training."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = Path(run_dir)
        self.fd: Optional[int] = None

    def acquire(self, resuming_from: Optional[Path] = None) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.run_dir / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            other = os.read(fd, 32).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise ConfigError(f"run directory is in use by another training (pid {other}); choose another --timestamp or --run-dir", self.run_dir) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self.fd = fd
        ckpts = self.run_dir / "checkpoints"
        own = resuming_from is not None and Path(resuming_from).resolve().is_relative_to(self.run_dir.resolve())
        if not own and ckpts.is_dir() and any(ckpts.glob("step-*.ckpt")):
            self.release()
            raise ConfigError("run directory already holds another run's checkpoints; choose another --timestamp "
                              "or --run-dir, or resume it with --load-checkpoint", self.run_dir)
        marker = self.run_dir / MARKER_NAME
        if not marker.is_file():
            foreign = sorted(p.name for p in self.run_dir.iterdir() if p.name not in (LOCK_NAME, MARKER_NAME))
            if foreign and not own:  # the user's own files (a config.yml, a log): never overwritten
                self.release()
                more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
                raise ConfigError(f"folder is not empty and not a run folder of ours (it holds {', '.join(foreign[:3])}{more}); "
                                  "choose an empty or new --run-dir", self.run_dir)
            marker.write_text("a run folder of ns2gs-train: it may write here\n")

    def release(self) -> None:
        if self.fd is not None:
            try:
                fcntl.flock(self.fd, fcntl.LOCK_UN)
            finally:
                os.close(self.fd)
                self.fd = None
