"""The capture check of a reconstruction (one scale, one path along the capture) and its cut to the longest
consistent stretch: what ``process`` keeps of an SfM model, and what ranks the mapping runs in the SfM worker
(numpy and pycolmap only: the worker does not import torch). ``opts`` is the process options
(``camera_height``, ``metres_per_unit``, ``broken_join``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from nerf2gs_plugin.errors import DataError


def metric_scale(xyz: np.ndarray, c2w: np.ndarray, opts: Any):
    """The ground-plane scale and up (:func:`~nerf2gs_plugin.data.ground.estimate_metric_scale`; a
    plane steeper than ``MAX_TILT_DEG`` from the cameras' up is no plane there). Without a plane,
    ``--metres-per-unit`` is needed, and up is the cameras' mean up (a warning says so)."""
    from nerf2gs_plugin.data.ground import estimate_metric_scale

    cam_up = c2w[:, :, 1].mean(0)
    scale = estimate_metric_scale(xyz, c2w[:, :, 3], cam_up, opts.camera_height, opts.metres_per_unit, where="--camera-height",
                                  cam_right=c2w[:, :, 0])
    if scale.plane is None:
        import warnings

        why = scale.note or "no ground plane below the cameras"
        warnings.warn(f"{why}: up is the cameras' own (perpendicular to their horizontal axes, else their mean up)"
                      + (", metric scale from the densest layer of points below them (check it, or pass --metres-per-unit)"
                         if scale.source == "camera-height, lowest layer" else ""), stacklevel=2)
    return scale


MAX_CUTS = 3
"""At most this many cuts of a broken reconstruction (``--broken-join drop``) before it is kept as it is."""


def cut_to_consistent(rec, opts: Any, ordered: bool) -> tuple[list[str], np.ndarray, object, dict, list[str]]:
    """The capture check of ``rec`` and, with ``--broken-join drop``, its longest consistent stretch (at most
    :data:`MAX_CUTS` cuts, deregistered from ``rec`` in place): (names, c2w, metric scale, check, dropped names)."""
    from nerf2gs_plugin.data.process import model_arrays

    dropped: list[str] = []
    for cut in range(MAX_CUTS + 1):
        names, c2w, _ = model_arrays.camera_arrays(rec)
        xyz, _ = model_arrays.points_arrays(rec)
        scale = metric_scale(xyz, c2w, opts)
        check = check_reconstruction(rec, names, c2w, scale.up, ordered=ordered)
        if check["consistent"] or opts.broken_join == "keep" or cut == MAX_CUTS:
            break
        dropped += drop_shorter_stretch(rec, names, check)
    return names, c2w, scale, check, dropped


def consistent_frames(rec, opts: Any, ordered: bool) -> int:
    """How many of ``rec``'s frames the capture check keeps as one consistent stretch (a copy is cut, the
    warnings silenced): what a mapping attempt is ranked by, so a model joined at two scales or in the wrong
    place loses to another attempt's consistent one (:func:`~nerf2gs_plugin.data.process.sfm.reconstruct`)."""
    import warnings

    import pycolmap

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            names, *_ = cut_to_consistent(pycolmap.Reconstruction(rec), dataclasses.replace(opts, broken_join="drop"), ordered)
        except DataError:  # no scale for it: the parent's check says why, for the model kept
            return 0
    return len(names)


def drop_shorter_stretch(rec, names: list[str], check: dict) -> list[str]:
    """Deregister, from the pycolmap reconstruction ``rec``, the frames on the shorter side of the failed
    check's split (the path jump's when it failed, else the height split). Returns their names."""
    jump = check.get("path_jump")
    at = jump["index"] + 1 if jump is not None and not jump["consistent"] else check["split"]
    drop = set(names[at:] if at >= len(names) - at else names[:at])
    deregister(rec, drop)
    return sorted(drop)


def deregister(rec, drop: set[str]) -> None:
    """Deregister the frames named ``drop`` from ``rec`` with their observations (a point seen only there goes with them)."""
    for im in list(rec.images.values()):
        if im.name in drop and im.has_pose:
            for idx, p in enumerate(im.points2D):
                if p.has_point3D():
                    rec.delete_observation(im.image_id, idx)
            rec.deregister_frame(im.frame_id)


def check_reconstruction(rec, names: list[str], c2w: np.ndarray, up: np.ndarray, ordered: bool = False) -> dict:
    """The reconstruction's consistency along the capture (:mod:`~nerf2gs_plugin.data.process.scale_check`):
    the camera's height above its road (one scale) and its path in name order (no jump; ``ordered``: a
    video or sequentially matched photos, held to ``MAX_STEP_JUMP``, else a photo set, to
    ``MAX_STEP_JUMP_PHOTOS``). Each failure is a warning (what to do about it is
    :func:`checked_reconstruction`'s). Returns the JSON record, with the report's ``line``."""
    from nerf2gs_plugin.data.process import model_arrays
    from nerf2gs_plugin.data.process.scale_check import (MAX_STEP_JUMP, MAX_STEP_JUMP_PHOTOS, local_camera_heights, path_jump,
                                                         scale_jump)
    from nerf2gs_plugin.warn import warn

    height = scale_jump(local_camera_heights(c2w[:, :3, 3], model_arrays.observed_points(rec, names), up), names)
    jump = path_jump(c2w[:, :3, 3], names, MAX_STEP_JUMP if ordered else MAX_STEP_JUMP_PHOTOS)
    bad = [check for check in (height, jump) if check is not None and not check.consistent]
    for check in bad:
        warn(*check.problem(), stacklevel=2)
    line = ("capture check FAILED: " + "; ".join(c.summary for c in bad) + " (warnings above)" if bad else
            "capture check: " + ", ".join(c.summary for c in (height, jump) if c is not None))
    doc = {**height.to_json(), "path_jump": jump.to_json() if jump is not None else None, "consistent": not bad}
    return {**doc, "line": line}
