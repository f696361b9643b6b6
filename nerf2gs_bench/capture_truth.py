"""A processed real capture's cameras against its ground-truth cameras (Strecha et al. 2008's
``<image>.camera`` files: metric, surveyed): ATE and the error of the camera-height metric scale.

Why here: on real photos only a surveyed capture says whether the SfM and its metric scale are right;
the dashcam captures have no such truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from nerf2gs_plugin.errors import DataError

OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0])
"""Strecha's cameras look along +z with y down; the datasets' transforms along -z with y up."""


def read_strecha_camera(path: Path) -> np.ndarray:
    """Camera-to-world ``[3, 4]`` (OpenGL axes, metres) of one ``.camera`` file: K (3 rows),
    distortion (1), R (3 rows: camera-to-world rotation), camera centre (1), image size (1)."""
    try:
        rows = [[float(v) for v in line.split()] for line in Path(path).read_text().splitlines() if line.strip()]
        R, centre = np.array(rows[4:7]), np.array(rows[7])
        if R.shape != (3, 3) or centre.shape != (3,):
            raise ValueError("expected 3x3 R in rows 5-7 and the centre in row 8")
    except (OSError, ValueError, IndexError) as e:
        raise DataError(f"not a Strecha .camera file ({e})", path) from e
    return np.concatenate([R @ OPENCV_TO_OPENGL, centre[:, None]], axis=1)


def vertical_axis(mean_up: np.ndarray) -> np.ndarray:
    """The signed world axis (x, y or z) nearest ``mean_up``."""
    k = int(np.argmax(np.abs(mean_up)))
    axis = np.zeros(3)
    axis[k] = np.sign(mean_up[k])
    return axis


def truth_report(dataset: Path, truth: Path) -> dict:
    """ATE, rotation error, scale error (the dataset's metres per SfM unit against the Sim(3)'s) and
    up error of the dataset's registered cameras against ``truth/<image name>.camera``. True up: the
    surveyed frame's axis nearest the true cameras' mean up (photos of a facade look up a little: their
    mean up is not the vertical)."""
    from nerf2gs_plugin.eval.pose_eval import capture_report

    meta = json.loads((Path(dataset) / "transforms.json").read_text())
    est, true = [], []
    for frame in meta["frames"]:
        cam = Path(truth) / f"{Path(frame['file_path']).name}.camera"
        if cam.is_file():
            est.append(np.asarray(frame["transform_matrix"], dtype=np.float64)[:3, :4])
            true.append(read_strecha_camera(cam))
    if len(est) < 3:
        raise DataError(f"{len(est)} registered frames have a ground-truth camera (need 3): names must match <image>.camera", truth)
    true_arr = np.stack(true)
    up = vertical_axis(true_arr[:, :, 1].mean(0))
    total = len(list(Path(truth).glob("*.camera")))
    report = capture_report(np.stack(est), true_arr, float(meta["metres_per_unit"]), np.asarray(meta.get("up", [0, 0, 1])),
                            up, len(est), total)
    return {**report, "frames_compared": len(est)}
