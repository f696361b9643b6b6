"""User-facing errors: one clear line naming the file and what is wrong, never a deep traceback.

Raise :class:`UserError` (or a subclass) anywhere bad input is detected; the ``ns2gs-*`` front
ends catch it, print ``error: <message>`` and exit with status 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Union


class UserError(Exception):
    """Bad input from the user (file, flag, data). The message is shown as one line."""

    def __init__(self, message: str, path: Optional[Union[str, Path]] = None) -> None:
        self.path = Path(path) if path is not None else None
        super().__init__(f"{path}: {message}" if path is not None else message)


class DataError(UserError):
    """A dataset file is missing or malformed."""


class ConfigError(UserError):
    """A config file or flag is malformed, or names something unknown."""


class CheckpointError(UserError):
    """A checkpoint is missing, corrupt, or of another method or dataset."""


class TrainingDiverged(UserError):
    """NaN/inf in the loss or the parameters; the last good checkpoint is kept."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (a scheduler's preemption, ``kill``): cleaned up like Ctrl-C, but the command exits
    143 (128 + SIGTERM), not SIGINT's 130 (see :func:`nerf2gs_plugin.cli.common.exit_on_sigterm`)."""


class ModelOutputError(UserError):
    """An external model (segmenter, enhancer, reference render) gave output that cannot be used:
    NaN/inf, the wrong shape, values outside its declared range. Nothing is written from it."""
