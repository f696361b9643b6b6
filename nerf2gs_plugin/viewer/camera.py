"""viser client cameras <-> our :class:`Cameras`.

viser poses are ``R_world_camera`` (a ``wxyz`` quaternion) and a position, in the OpenCV camera
frame (x right, y down, looking down +z); ``fov`` is vertical, in radians. Our cameras are OpenGL
camera-to-world (x right, y up, looking down -z): the two frames differ by a flip of y and z.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from viser import transforms as vtf

from nerf2gs_plugin.cameras import Cameras

_FLIP_YZ = np.diag([1.0, -1.0, -1.0])


def viser_to_cameras(wxyz: np.ndarray, position: np.ndarray, fov: float, aspect: float, height: int) -> Cameras:
    """One camera of ``height`` rows (width from ``aspect``) at a viser pose; pinhole, centred."""
    if not (0.0 < fov < math.pi) or aspect <= 0 or height < 1:
        raise ValueError(f"bad viewer camera: fov={fov}, aspect={aspect}, height={height}")
    R_cv = vtf.SO3(np.asarray(wxyz, dtype=np.float64)).as_matrix()
    R_gl = R_cv @ _FLIP_YZ
    c2w = np.concatenate([R_gl, np.asarray(position, dtype=np.float64).reshape(3, 1)], axis=1)
    h = int(height)
    w = max(1, int(round(h * aspect)))
    f = 0.5 * h / math.tan(0.5 * fov)
    return Cameras(torch.from_numpy(c2w).float()[None], fx=f, fy=f, cx=w / 2.0, cy=h / 2.0, width=w, height=h)


def cameras_to_viser(camera: Cameras, index: int = 0) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(wxyz, position, vertical fov, aspect)`` of one of our cameras, in viser's convention."""
    c2w = camera.camera_to_worlds[index].detach().cpu().double().numpy()
    R_cv = c2w[:, :3] @ _FLIP_YZ
    wxyz = vtf.SO3.from_matrix(R_cv).wxyz
    h, w = float(camera.height[index]), float(camera.width[index])
    fov = 2.0 * math.atan(0.5 * h / float(camera.fy[index]))
    return np.asarray(wxyz, dtype=np.float64), c2w[:, 3].copy(), fov, w / h


def look_direction(camera: Cameras, index: int = 0) -> np.ndarray:
    """World-space viewing direction (OpenGL -z) of one camera."""
    return -camera.camera_to_worlds[index, :, 2].detach().cpu().double().numpy()
