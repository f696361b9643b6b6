"""Stages 5-6: undistortion to PINHOLE and the dataset layout the parsers read.

Layout written into DATA::

    images/            undistorted frames (PINHOLE)
    images_2|4|8/      downscaled copies (area averaging; same names)
    sparse/0/          the undistorted COLMAP model (PINHOLE cameras, points3D)
    sparse_pc.ply      the sparse points (initialises splats)
    transforms.json    nerfstudio format: PINHOLE intrinsics, frames in capture order, metres_per_unit
                       and up from the ground plane (see :mod:`nerf2gs_plugin.data.ground`), ground_plane
    colmap/            work files: frames/, database.db, distorted/ (the raw SfM model)
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from nerf2gs_plugin.data.images import scaled_size
from nerf2gs_plugin.data.ply import write_ply_points
from nerf2gs_plugin.data.process.model_arrays import camera_arrays, points_arrays
from nerf2gs_plugin.errors import DataError

DOWNSCALES = (2, 4, 8)


def undistort(model_dir: Path, image_dir: Path, out_root: Path, progress=None) -> Path:
    """PINHOLE images + model into ``out_root/{images,sparse}`` (via a temp folder, then renamed)."""
    import pycolmap

    task = progress.add_task("undistort (PINHOLE)", total=1, stats="") if progress else None
    work = out_root.with_name(out_root.name + ".tmp")
    shutil.rmtree(work, ignore_errors=True)
    pycolmap.undistort_images(str(work), str(model_dir), str(image_dir), output_type="COLMAP")
    shutil.rmtree(out_root, ignore_errors=True)
    os.replace(work, out_root)
    if task is not None:
        progress.update(task, advance=1)
    return out_root


def install_images(src: Path, root: Path) -> None:
    """The undistorted images of ``src`` into ``root/images``, one atomic rename per changed file.

    A re-run of ``process`` on the same model writes the same bytes: those files are left as they are
    (with their ``images_{2,4,8}`` copies), so a run reading the capture meanwhile never finds a file
    missing. A changed image loses its copies, which
    :func:`write_downscaled` makes again; an image no longer in ``src`` is removed with its copies.
    """
    import filecmp

    dst = root / "images"
    dst.mkdir(parents=True, exist_ok=True)
    derived = [root / f"images_{d}" for d in DOWNSCALES]
    new = {p.name for p in src.iterdir() if p.is_file()}
    for name in sorted(new):
        if (dst / name).is_file() and filecmp.cmp(src / name, dst / name, shallow=False):
            continue
        for k in derived:
            (k / name).unlink(missing_ok=True)
        os.replace(src / name, dst / name)
    for p in dst.iterdir():
        if p.is_file() and p.name not in new:
            p.unlink()


def write_downscaled(root: Path, names: list[str], progress=None) -> None:
    """``images_{2,4,8}/`` copies of ``images/`` for ``names`` (kept per file when already there; copies of
    other names removed)."""
    task = progress.add_task("downscaled copies", total=len(names) * len(DOWNSCALES), stats="") if progress else None
    keep = set(names)
    for d in DOWNSCALES:
        out = root / f"images_{d}"
        out.mkdir(exist_ok=True)
        for p in out.iterdir():
            if p.is_file() and p.name not in keep and not p.name.startswith("."):
                p.unlink()
        for n in names:
            dst = out / n
            if not dst.is_file():
                img = cv2.imread(str(root / "images" / n), cv2.IMREAD_UNCHANGED)
                small = cv2.resize(img, scaled_size(img.shape[1], img.shape[0], d), interpolation=cv2.INTER_AREA)
                tmp = dst.with_name(f".{dst.stem}.tmp{dst.suffix}")
                cv2.imwrite(str(tmp), small)
                os.replace(tmp, dst)
            if task is not None:
                progress.update(task, advance=1)


def pinhole_params(cam) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of a COLMAP camera of any model, from pycolmap's own accessors: the
    undistorter keeps a camera whose distortion is zero in its model (a SIMPLE_RADIAL with k = 0 is
    ``[f, cx, cy, k]``), so reading ``params[:4]`` as PINHOLE gave fy = cx, cx = cy, cy = k = 0."""
    extra = [float(cam.params[i]) for i in cam.extra_params_idxs()]
    if any(abs(v) > 1e-9 for v in extra):
        raise DataError(f"camera {cam.camera_id} ({cam.model.name}) still has distortion {extra} after undistortion", "sparse/0")
    return (float(cam.focal_length_x), float(cam.focal_length_y), float(cam.principal_point_x), float(cam.principal_point_y))


def write_transforms(root: Path, rec, metres_per_unit: float, up: Optional[np.ndarray], extra: dict) -> Path:
    """``transforms.json`` (+ ``sparse_pc.ply``) from the undistorted model, atomically."""
    names, c2w, cams = camera_arrays(rec)
    xyz, rgb = points_arrays(rec)
    write_ply_points(root / "sparse_pc.ply", xyz, rgb)
    frames = []
    for n, m, cam in zip(names, c2w, cams):
        fx, fy, cx, cy = pinhole_params(cam)
        frames.append({"file_path": f"images/{n}", "transform_matrix": np.vstack([m, [0, 0, 0, 1]]).tolist(),
                       "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": int(cam.width), "h": int(cam.height)})
    meta = {"camera_model": "PINHOLE", "frames": frames, "ply_file_path": "sparse_pc.ply", "metres_per_unit": float(metres_per_unit)}
    if up is not None:
        meta["up"] = [float(v) for v in up]
    meta.update(extra)
    path = root / "transforms.json"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(meta, indent=1))
    os.replace(tmp, path)
    return path
