"""A pycolmap reconstruction as numpy arrays (cameras in capture order, points, each frame's tracks).

numpy only: the SfM worker reads its models with it without importing torch.
"""

from __future__ import annotations

import numpy as np

GL_TO_CV = np.diag([1.0, -1.0, -1.0])
"""OpenGL <-> OpenCV camera axes: flip y and z (as ``nerf2gs_plugin.cameras``)."""


def camera_arrays(rec) -> tuple[list[str], np.ndarray, list]:
    """Registered image names (sorted = capture order), OpenGL c2w ``[N, 3, 4]`` (float64), cameras."""
    imgs = sorted((im for im in rec.images.values() if im.has_pose), key=lambda im: im.name)
    c2w = np.zeros((len(imgs), 3, 4))
    for k, im in enumerate(imgs):
        w2c = np.asarray(im.cam_from_world().matrix(), dtype=np.float64)
        rot = w2c[:3, :3].T
        c2w[k, :, :3] = rot @ GL_TO_CV
        c2w[k, :, 3] = -rot @ w2c[:3, 3]
    return [im.name for im in imgs], c2w, [rec.cameras[im.camera_id] for im in imgs]


def points_arrays(rec) -> tuple[np.ndarray, np.ndarray]:
    """The sparse points' ``[P, 3]`` positions (float32) and ``[P, 3]`` colours (uint8)."""
    pts = rec.points3D
    if not len(pts):
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
    return (np.array([p.xyz for p in pts.values()], dtype=np.float32).reshape(-1, 3),
            np.array([p.color for p in pts.values()], dtype=np.uint8).reshape(-1, 3))


def observed_points(rec, names: list[str]) -> list[np.ndarray]:
    """Per image of ``names``: the ``[K, 3]`` sparse points it observes (its tracks), as the scale check reads them."""
    by_name = {im.name: im for im in rec.images.values()}
    out = []
    for n in names:
        ids = [p.point3D_id for p in by_name[n].points2D if p.has_point3D()]
        out.append(np.array([rec.points3D[i].xyz for i in ids], dtype=np.float64).reshape(-1, 3))
    return out
