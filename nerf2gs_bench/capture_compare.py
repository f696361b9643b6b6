"""A capture's runs side by side from above through ``ns2gs-render compare`` (the same code, cameras
and hole measure as the command): the augmentation's own bird's-eye views, each run under its label."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence


def compare_from_above(run_dirs: Sequence[Path], labels: Sequence[str], output: Path) -> dict[str, dict]:
    """``ns2gs-render compare RUNS --labels LABELS --path birds-eye --output-format images --measure
    --output OUTPUT``; each label's measures (``bev_hole_fraction``, ``floater_fraction``, ``frames``).
    The frames (PNG, the runs side by side) are in ``output``."""
    from nerf2gs_plugin.cli.render import CompareArgs, render
    from nerf2gs_plugin.render.render_path import OutputOptions

    args = CompareArgs(runs=tuple(Path(d) for d in run_dirs), labels=tuple(labels), path="birds-eye", output=Path(output),
                       device="cpu", out=OutputOptions(output_format="images", measure=True))
    render(args, compare=True)
    measures = json.loads(Path(f"{output}.measures.json").read_text())
    return {m["label"]: m for m in measures}


def compare_frames(output: Path, count: int = 2) -> list[Path]:
    """``count`` frames of a compare folder, evenly spread (the first one included)."""
    frames = sorted(Path(output).glob("*.png"))
    if not frames:
        return []
    step = max(1, len(frames) // max(count, 1))
    return frames[::step][:count]


def save_small_png(frames: Sequence[Path], path: Path, max_width: int = 1200, max_bytes: int = 300_000) -> Path:
    """``frames`` stacked top to bottom, shrunk until the PNG is at most ``max_bytes`` (for the docs)."""
    import cv2
    import numpy as np

    from nerf2gs_plugin.utils.io import atomic_write_bytes

    imgs = [cv2.imread(str(f)) for f in frames]
    width = min(max(i.shape[1] for i in imgs), max_width)
    imgs = [cv2.resize(i, (width, round(i.shape[0] * width / i.shape[1])), interpolation=cv2.INTER_AREA) for i in imgs]
    stacked = np.concatenate(imgs, axis=0)
    while True:
        ok, buf = cv2.imencode(".png", stacked, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        if len(buf) <= max_bytes or stacked.shape[1] < 200:
            break
        stacked = cv2.resize(stacked, (stacked.shape[1] * 4 // 5, stacked.shape[0] * 4 // 5), interpolation=cv2.INTER_AREA)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(Path(path), buf.tobytes())
    return Path(path)
