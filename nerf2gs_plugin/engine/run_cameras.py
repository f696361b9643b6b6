"""``train_cameras.json`` in a run directory: the training cameras, so that a run can be used
without its dataset (``ns2gs-export`` needs the model only; Scaffold-GS decodes its Gaussians for
a training view; a model's per-image tables are sized by the number of training images)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.errors import DataError

FILENAME = "train_cameras.json"
_FIELDS = ("fx", "fy", "cx", "cy", "width", "height")


def save_train_cameras(run_dir: Path, cameras: Cameras) -> Path:
    """Write the cameras (normalised frame, OpenGL ``camera_to_worlds``) as plain JSON."""
    cams = cameras.to("cpu")
    doc = {
        "format": 1,
        "frame": "normalised (dataparser_transforms.json maps the dataset's frame to it)",
        "camera_to_worlds": cams.camera_to_worlds.tolist(),
        **{name: getattr(cams, name).tolist() for name in _FIELDS},
        "distortion_params": cams.distortion_params.tolist(),
    }
    path = Path(run_dir) / FILENAME
    atomic_write_text(path, json.dumps(doc))
    return path


def load_train_cameras(run_dir: Path) -> Optional[Cameras]:
    """The run's training cameras, or None for a run written before this file existed."""
    path = Path(run_dir) / FILENAME
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
        return Cameras(
            torch.tensor(doc["camera_to_worlds"], dtype=torch.float32),
            **{name: torch.tensor(doc[name]) for name in _FIELDS},
            distortion_params=torch.tensor(doc["distortion_params"], dtype=torch.float32),
        )
    except (ValueError, KeyError, TypeError) as e:
        raise DataError(f"malformed training cameras ({type(e).__name__}: {e})", path) from None
