"""``--camera-path-file camera_path.json``: nerfstudio's camera path (what its viewer's render panel
saves and ``ns-render camera-path`` reads).

Read: ``render_height`` / ``render_width`` and the ``camera_path`` list (one entry per frame:
``camera_to_world``, 16 numbers of a row-major 4x4; ``fov``, the vertical field of view in degrees;
``aspect``), or, when a file has no ``camera_path``, its ``keyframes`` (``matrix`` row-major, ``fov``).
The poses are nerfstudio's: OpenGL camera axes (x right, y up, looking down -z) in the run's
normalised world frame, which are this project's conventions too, so they are used as they are.
Intrinsics as nerfstudio makes them: ``f = (H / 2) / tan(fov / 2)`` for both axes, principal point
at the image centre; the width is ``render_width`` (or ``H * aspect``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.render.paths.registry import PathOptions, register_path
from nerf2gs_plugin.render.scene import PathContext


def _frame(entry: dict, key: str, height: int, width: int) -> tuple[torch.Tensor, float, int]:
    m = torch.tensor(entry[key], dtype=torch.float32).reshape(-1)
    if m.numel() != 16:
        raise ValueError(f"'{key}' has {m.numel()} numbers, expected 16 (a 4x4 matrix)")
    fov = float(entry.get("fov", 50.0))
    if not 0 < fov < 180:
        raise ValueError(f"fov {fov} is not in (0, 180) degrees")
    w = int(round(height * float(entry["aspect"]))) if not width and "aspect" in entry else width
    if w <= 0:
        raise ValueError("no render_width and no aspect to make one")
    return m.reshape(4, 4)[:3], height / 2.0 / math.tan(math.radians(fov) / 2.0), w


def read_camera_path(path: Path) -> Cameras:
    """The cameras of a nerfstudio ``camera_path.json``; a missing or malformed file raises
    :class:`DataError` naming the file and what is wrong."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise DataError("camera path file does not exist", path) from None
    except (OSError, json.JSONDecodeError) as e:
        raise DataError(f"not a readable JSON camera path ({e})", path) from None
    try:
        height, width = int(doc["render_height"]), int(doc.get("render_width", 0))
        if height <= 0 or width < 0:
            raise ValueError(f"render size {width}x{height} is not positive")
        entries, key = (doc["camera_path"], "camera_to_world") if doc.get("camera_path") else (doc["keyframes"], "matrix")
        if not entries:
            raise ValueError("no cameras in 'camera_path' or 'keyframes'")
        frames = [_frame(e, key, height, width) for e in entries]
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else str(e)
        raise DataError(f"malformed nerfstudio camera path ({what})", path) from None
    c2w = torch.stack([f[0] for f in frames])
    if not bool(torch.isfinite(c2w).all()):
        raise DataError("malformed nerfstudio camera path (non-finite camera_to_world)", path)
    focal = torch.tensor([f[1] for f in frames])
    w = torch.tensor([f[2] for f in frames])
    return Cameras(c2w, fx=focal, fy=focal, cx=w / 2.0, cy=height / 2.0, width=w, height=height)


@register_path("camera-path")
def camera_path(ctx: PathContext, opts: PathOptions) -> Cameras:
    if opts.camera_path_file is None:
        from nerf2gs_plugin.errors import ConfigError

        raise ConfigError("--path camera-path needs --camera-path-file camera_path.json")
    return read_camera_path(opts.camera_path_file)
