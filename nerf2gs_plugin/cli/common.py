"""What every ns2gs-* front end shares: one-line errors and exit codes."""

from __future__ import annotations

import sys
from typing import Callable, TypeVar

from nerf2gs_plugin.errors import UserError

T = TypeVar("T")


def run_cli(main: Callable[[], T]) -> T:
    """Run ``main``; bad input becomes ``error: <one line>`` on stderr and exit status 2;
    warnings are one plain line each, once (:mod:`nerf2gs_plugin.warn`)."""
    from nerf2gs_plugin.warn import install_plain_warnings

    install_plain_warnings()
    try:
        return main()
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except OSError as e:  # disk full, read-only or permission denied: the file and the reason, one line
        where = f"{e.filename}: " if e.filename else ""
        print(f"error: {where}{e.strerror or e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
