"""Headless matplotlib and the atomic figure save every chart and picture uses."""

from __future__ import annotations

import os
from pathlib import Path

from nerf2gs_plugin.utils.io import temp_beside


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (no display needed); imported on first use."""
    import matplotlib  # noqa: PLC0415 - heavy, only where a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


def save_figure(fig, path: Path) -> None:
    """Write ``fig`` to ``path`` through a temp file and a rename, then close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_beside(path)
    fig.savefig(tmp, dpi=110)
    pyplot().close(fig)
    os.replace(tmp, path)
