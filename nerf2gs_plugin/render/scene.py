"""What a camera path is built from: a run's training cameras in its normalised frame, the ground's
up, the metric scale, and the bird's-eye views its augmentation trained on (when it has any)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras


@dataclass
class PathContext:
    """The frame a path lives in: everything in normalised world units, OpenGL cameras."""

    train: Cameras  # the capture's training cameras, in capture order
    up: Tensor  # [3] unit normal of the ground plane
    units_per_metre: float  # the dataparser's metric scale: world units in one metre
    augment_views: Optional[Cameras] = None  # the bird's-eye views the run's augmentation trained on
    augment_source: str = ""  # where those came from (a manifest, or recomputed from the config)

    def metres(self, m: float) -> float:
        """A length in metres, in world units."""
        return m * self.units_per_metre


@dataclass
class _World:
    """The world frame the augmentation's view families read (``up``, metres to world units)."""

    up: Tensor
    units_per_metre: float

    def metres_to_world(self, metres: float) -> float:
        return metres * self.units_per_metre


def trained_birds_eye(config: Any, dataset: Optional[str], train: Cameras, up: Tensor,
                      units_per_metre: float) -> tuple[Optional[Cameras], str]:
    """The bird's-eye views a run trained on: read back from its reference's augment cache manifest
    (the poses it saved), else made again from the run's config as the augmentation makes them; only
    the ``birds-eye`` family's views (``(None, "")`` for a run without them)."""
    from nerf2gs_plugin.augment.datamanager import find_cached_extra_views
    from nerf2gs_plugin.augment.views import additional_views
    from nerf2gs_plugin.engine.checkpoints import resolve_checkpoint
    from nerf2gs_plugin.errors import UserError

    aug = getattr(config, "augment", None)
    if config is None or getattr(config, "augment_from", None) is None or aug is None or not aug.extra_views:
        return None, ""
    # at the capture's size whatever size the run trained them at (--augment.view-downscale): the render's own --downscale sets it
    made = additional_views(train, _World(up, units_per_metre), replace(aug, view_downscale=1))
    if made is None:
        return None, ""
    try:
        ref_dir, _ = resolve_checkpoint(Path(config.augment_from))
    except UserError:
        ref_dir = None
    manifest = (find_cached_extra_views(ref_dir, dataset, aug, len(made.cameras))
                if ref_dir is not None and dataset is not None else None)
    if manifest is not None and manifest.num_extra:
        kept = made.cameras[torch.tensor(manifest.extra_indices, dtype=torch.long)]
        cams, source = kept.with_poses(manifest.extra_poses().to(kept.device)), str(manifest.path)
        families = manifest.extra_families or [made.families[i] for i in manifest.extra_indices]
    else:
        cams, source, families = made.cameras, "recomputed from the run's --augment config (no cache manifest found)", made.families
    birds = [i for i, f in enumerate(families) if f == "birds-eye"]
    if not birds:
        return None, ""
    return cams[torch.tensor(birds, dtype=torch.long)], source


def context_from_run_model(run: Any) -> PathContext:
    """The path context of a :class:`~nerf2gs_plugin.runs.model.RunModel`."""
    up = run.up if run.up is not None else torch.tensor([0.0, 0.0, 1.0])
    up = torch.nn.functional.normalize(up.float(), dim=0)
    views, source = trained_birds_eye(run.config, run.dataset, run.train_cameras, up, run.units_per_metre)
    return PathContext(run.train_cameras, up, float(run.units_per_metre), views, source)


def context_from_loaded_run(run: Any) -> PathContext:
    """The path context of a :class:`~nerf2gs_plugin.runs.load.LoadedRun` (what eval loads)."""
    from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint

    td = run.pipeline.datamanager.train_data
    up = torch.nn.functional.normalize(td.up.float(), dim=0)
    upm = float(td.metres_to_world(1.0))
    views, source = trained_birds_eye(run.config, dataset_fingerprint(td.image_filenames), td.cameras, up, upm)
    return PathContext(td.cameras, up, upm, views, source)
