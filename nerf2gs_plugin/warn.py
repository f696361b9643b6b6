"""User-facing warnings: one plain line each, ``warning: <what>: <consequence>``, once per command.

Code calls :func:`warn` (a :class:`UserWarning` subclass underneath, so tests and library users
can still catch or filter them). The ns2gs-* commands call :func:`install_plain_warnings` first:
every warning is then printed as one line on stderr, without Python's category and source line,
and a text already printed is not printed again (a bench trains many runs in one process; the
same missing masks are worth one line).
"""

from __future__ import annotations

import sys
import warnings
from contextlib import contextmanager
from typing import Iterator, Optional, TextIO

_PRINTED: set[str] = set()


class Nerf2gsWarning(UserWarning):
    """A warning meant for the person running the command (missing masks, random init, ...)."""


def warn(what: str, consequence: str, stacklevel: int = 2) -> None:
    """Warn that ``what`` (the cause) has ``consequence`` (what the run does about it)."""
    warnings.warn(f"{what}: {consequence}", Nerf2gsWarning, stacklevel=stacklevel + 1)


def format_line(message: object) -> str:
    text = " ".join(str(message).split())  # one line whatever the message
    return text if text.startswith("warning: ") else f"warning: {text}"


def install_plain_warnings(file: Optional[TextIO] = None) -> None:
    """Print every warning as one plain line, each distinct text once per process."""

    def show(message, category, filename, lineno, file_=None, line=None) -> None:  # noqa: ARG001
        text = format_line(message)
        if text in _PRINTED:
            return
        _PRINTED.add(text)
        print(text, file=file or sys.stderr, flush=True)

    warnings.showwarning = show
    warnings.simplefilter("always", Nerf2gsWarning)  # de-duplicated by text above, not by source line


@contextmanager
def quiet() -> Iterator[None]:
    """No :class:`Nerf2gsWarning` inside (loading a finished run for eval, export or as a reference:
    what was missing at training time was said then)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Nerf2gsWarning)
        yield
