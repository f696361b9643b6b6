"""View families: the rules that make the augmentation's additional cameras from the input poses.

``--augment.views birds-eye lane-shift`` names the families; each makes cameras (with the input
views' intrinsics) and says which input view each one came from. The augmentation renders the
concatenation of every family's cameras, in the order given, as one set of additional views: one
cache entry, one manifest (the poses and each view's family saved) and the same drop rules (outside
the scene box, mostly empty render); each family has its own share of the training samples
(augment/shares.py).

Built-in families (their parameters under their names, ``augment/config.py``):
  * ``birds-eye``: raised by delta-h and pitched down by theta-pitch (the paper's views);
  * ``lane-shift``: moved sideways along the ground plane's lateral axis (level, to the right of the
    heading: not the camera's own x axis, which its roll tilts), optionally turned toward the road ahead;
  * ``raise``: moved up along the scene's up vector, orientation kept (no pitch);
  * ``poses``: the poses of a user's file, each with the intrinsics of the nearest input camera.
A plugin adds a family through the ``nerf2gs.view_families`` entry-point group (a :class:`ViewFamily`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.augment.geometry import ViewGeometry, WorldFrame
from nerf2gs_plugin.cameras import Cameras, _axis_angle, ground_lateral
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_plugin.utils.plugins import load_entry_points, load_ref

ENTRY_POINT_GROUP = "nerf2gs.view_families"


@dataclass
class FamilyViews:
    """One family's cameras and, per camera, the input view it was made from."""

    cameras: Cameras
    sources: list[int]


@dataclass
class ViewFamily:
    """A registered family: ``make(train_cameras, world, augment_config) -> FamilyViews``."""

    make: Callable[[Cameras, WorldFrame, Any], FamilyViews]
    description: str


BUILTIN_FAMILIES: dict[str, str] = {
    "birds-eye": "nerf2gs_plugin.augment.views:BIRDS_EYE",
    "lane-shift": "nerf2gs_plugin.augment.views:LANE_SHIFT",
    "raise": "nerf2gs_plugin.augment.views:RAISE",
    "poses": "nerf2gs_plugin.augment.views:POSES",
}


@lru_cache(maxsize=1)
def view_families() -> dict[str, ViewFamily]:
    """Every family: the built-in ones, then those of installed plugins (a broken plugin is skipped)."""
    found = {name: load_ref(ref) for name, ref in BUILTIN_FAMILIES.items()}
    plugins, _ = load_entry_points(ENTRY_POINT_GROUP, ViewFamily, found)
    return {**found, **plugins}  # type: ignore[dict-item]


def get_family(name: str) -> ViewFamily:
    families = view_families()
    if name not in families:
        raise ConfigError(f"unknown view family '{name}'; known: {', '.join(families)}", "--augment.views")
    return families[name]


def _every(train: Cameras, every_n: int) -> list[int]:
    return list(range(0, len(train), max(int(every_n), 1)))


def _repeat(train: Cameras, idx: list[int], k: int) -> tuple[Cameras, list[int]]:
    """The input cameras ``idx``, each ``k`` times in a row (one per offset), and their indices."""
    src = [i for i in idx for _ in range(k)]
    return train[torch.tensor(src, dtype=torch.long)], src


def birds_eye(train: Cameras, world: WorldFrame, augment: Any) -> FamilyViews:
    geometry = ViewGeometry.of(augment)
    return FamilyViews(geometry.cameras(train, world), _every(train, geometry.every_n))


def lane_shift_poses(camera_to_worlds: Tensor, up: Tensor, offset_world: Tensor, look_ahead_world: float = 0.0) -> Tensor:
    """``[N, 3, 4]`` poses moved ``offset_world`` ``[N]`` along the ground's lateral axis (positive:
    right); with ``look_ahead_world > 0`` each is turned about ``up`` toward the point that far ahead
    of its input camera on the ground plane (the lane it left), else its orientation is kept."""
    up = torch.nn.functional.normalize(up.to(camera_to_worlds), dim=0)
    lateral = ground_lateral(camera_to_worlds, up)
    out = camera_to_worlds.clone()
    out[:, :, 3] = out[:, :, 3] + offset_world.to(out)[:, None] * lateral
    if look_ahead_world > 0:
        # from the shifted centre the point ahead lies at look_ahead along the heading and -offset across:
        # a turn by atan(offset / look_ahead) about up (turning by a about up takes the heading toward -lateral)
        angle = torch.atan2(offset_world.to(out), torch.full_like(offset_world.to(out), look_ahead_world))
        out[:, :, :3] = _axis_angle(up.expand(len(out), 3), angle) @ out[:, :, :3]
    return out


def lane_shift(train: Cameras, world: WorldFrame, augment: Any) -> FamilyViews:
    cfg = augment.lane_shift
    if not cfg.offsets or cfg.look_ahead < 0:
        raise ConfigError("needs at least one offset and look-ahead >= 0", "--augment.lane-shift.*")
    cams, src = _repeat(train, _every(train, cfg.every_n), len(cfg.offsets))
    offsets = torch.tensor([world.metres_to_world(d) for d in cfg.offsets] * (len(src) // len(cfg.offsets)), dtype=torch.float64)
    c2w = lane_shift_poses(cams.camera_to_worlds, world.up, offsets, world.metres_to_world(cfg.look_ahead))
    return FamilyViews(cams.with_poses(c2w), src)


def raise_poses(camera_to_worlds: Tensor, up: Tensor, height_world: Tensor) -> Tensor:
    """``[N, 3, 4]`` poses moved ``height_world`` ``[N]`` along ``up``, orientation kept."""
    up = torch.nn.functional.normalize(up.to(camera_to_worlds), dim=0)
    out = camera_to_worlds.clone()
    out[:, :, 3] = out[:, :, 3] + height_world.to(out)[:, None] * up
    return out


def raise_views(train: Cameras, world: WorldFrame, augment: Any) -> FamilyViews:
    cfg = augment.raise_
    if not cfg.heights:
        raise ConfigError("needs at least one height", "--augment.raise.heights")
    cams, src = _repeat(train, _every(train, cfg.every_n), len(cfg.heights))
    heights = torch.tensor([world.metres_to_world(h) for h in cfg.heights] * (len(src) // len(cfg.heights)), dtype=torch.float64)
    return FamilyViews(cams.with_poses(raise_poses(cams.camera_to_worlds, world.up, heights)), src)


def read_pose_file(path: Path) -> Tensor:
    """``[N, 3, 4]`` camera-to-world poses of a pose file (see ``PosesFileConfig``); a missing or
    malformed file raises :class:`DataError` naming it and what is wrong."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise DataError("pose file does not exist", path) from None
    except (OSError, ValueError) as e:
        raise DataError(f"not a readable JSON pose file ({e})", path) from None
    try:
        if isinstance(doc, dict) and "camera_path" in doc:  # nerfstudio's camera_path.json: row-major 4x4 each
            rows = [torch.tensor(e["camera_to_world"], dtype=torch.float32).reshape(4, 4) for e in doc["camera_path"]]
        else:
            rows = [torch.tensor(m, dtype=torch.float32).reshape(-1, 4) for m in doc["camera_to_worlds"]]
        if not rows:
            raise ValueError("no poses")
        if any(r.shape[0] not in (3, 4) for r in rows):
            raise ValueError("a pose is not 3x4 or 4x4")
        poses = torch.stack([r[:3] for r in rows])
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else str(e)
        raise DataError(f"malformed pose file ({what}; expected camera_to_worlds: a list of 3x4 or 4x4 matrices)", path) from None
    if not bool(torch.isfinite(poses).all()):
        raise DataError("malformed pose file (non-finite numbers)", path)
    return poses


def pose_file_views(train: Cameras, world: WorldFrame, augment: Any) -> FamilyViews:
    if augment.poses.file is None:
        raise ConfigError("the poses family needs a file", "--augment.poses.file")
    poses = read_pose_file(augment.poses.file).to(train.camera_to_worlds)
    nearest = torch.cdist(poses[:, :, 3], train.camera_to_worlds[:, :, 3]).argmin(dim=1).tolist()
    return FamilyViews(train[torch.tensor(nearest, dtype=torch.long)].with_poses(poses), nearest)


BIRDS_EYE = ViewFamily(birds_eye, "raised by delta-h and pitched down by theta-pitch (the paper's views)")
LANE_SHIFT = ViewFamily(lane_shift, "moved sideways along the ground's lateral axis (--augment.lane-shift.offsets)")
RAISE = ViewFamily(raise_views, "moved up without pitch (--augment.raise.heights)")
POSES = ViewFamily(pose_file_views, "the poses of a file (--augment.poses.file)")


@dataclass
class AdditionalViews:
    """Every family's cameras, concatenated in the order of ``--augment.views``."""

    cameras: Cameras
    sources: list[int]
    families: list[str]


def additional_views(train: Cameras, world: WorldFrame, augment: Any) -> Optional[AdditionalViews]:
    """The additional cameras of ``augment.views`` (None when ``extra_views`` is off or no family makes one)."""
    if not augment.extra_views:
        return None
    names = list(augment.views)
    if len(set(names)) != len(names):
        raise ConfigError(f"a family is named twice: {' '.join(names)}", "--augment.views")
    parts = [(name, get_family(name).make(train, world, augment)) for name in names]
    parts = [(n, p) for n, p in parts if len(p.cameras)]
    if not parts:
        return None
    if len(parts) == 1:  # one family: its cameras as they are
        made = AdditionalViews(parts[0][1].cameras, parts[0][1].sources, [parts[0][0]] * len(parts[0][1].cameras))
    else:
        made = AdditionalViews(Cameras.cat([p.cameras for _, p in parts]), [i for _, p in parts for i in p.sources],
                               [n for n, p in parts for _ in range(len(p.cameras))])
    n = int(getattr(augment, "view_downscale", 1))
    if n > 1:  # smaller renders and cheaper steps; the camera's size keys each render (cache.view_key)
        made.cameras = made.cameras.scaled(1.0 / n)
    return made
