"""What every ns2gs-* front end shares: one-line errors and exit codes."""

from __future__ import annotations

import errno
import signal
import sys
import threading
from typing import Callable, TypeVar

from nerf2gs_plugin.errors import Terminated, UserError

T = TypeVar("T")


def _raise_terminated(signum, frame) -> None:  # noqa: ARG001
    raise Terminated()


def exit_on_sigterm():
    """SIGTERM raises :class:`Terminated` (a ``KeyboardInterrupt``): the ``except KeyboardInterrupt``
    clean-ups (checkpoint, lock, temp files) run, then :func:`run_cli` exits 143. Returns the handler
    it replaced (None off the main thread, where none can be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


def _disk_line(e: OSError) -> str:
    """ENOSPC / EDQUOT: the file, the reason and the disk (its mount point and what is left on it)."""
    from pathlib import Path

    from nerf2gs_plugin.utils.disk import free_bytes, mount_point

    line = f"{e.filename}: {e.strerror}" if e.filename else str(e.strerror or e)
    where = Path(e.filename).parent if e.filename else Path.cwd()
    try:
        free = free_bytes(where)
    except OSError:
        return line
    return f"{line} ({free / 1e6:.0f} MB free on {mount_point(where)}; free space there or choose another output folder)"


def run_cli(main: Callable[[], T]) -> T:
    """Run ``main``; bad input becomes ``error: <one line>`` on stderr and exit status 2;
    warnings are one plain line each, once (:mod:`nerf2gs_plugin.warn`); Ctrl-C exits 130, SIGTERM 143."""
    from nerf2gs_plugin.warn import install_plain_warnings

    install_plain_warnings()
    previous = exit_on_sigterm()
    try:
        return main()
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except OSError as e:  # disk full, read-only or permission denied: the file and the reason, one line
        if e.errno in (errno.ENOSPC, errno.EDQUOT):
            print(f"error: {_disk_line(e)}", file=sys.stderr)
            sys.exit(2)
        where = f"{e.filename}: " if e.filename else ""
        print(f"error: {where}{e.strerror or e}", file=sys.stderr)
        sys.exit(2)
    except Terminated:
        print("terminated", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    finally:
        if previous is not None:  # a caller in the same process (a test) keeps its own handler
            signal.signal(signal.SIGTERM, previous)
