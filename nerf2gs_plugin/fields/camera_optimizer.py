"""Learnable per-training-image pose corrections (nerfstudio's camera optimizer, SO3xR3 mode).

On a real capture the training poses come from our own SfM and carry its error. With
``mode="SO3xR3"`` every training image gets a
6-vector ``[t, r]`` (:mod:`nerf2gs_plugin.utils.lie`), initialised to zero and trained with the
model by its own optimizer group (``camera_opt``) plus a small L2 penalty that keeps the
whole set from drifting (a gauge the images cannot fix). Only TRAINING rays are corrected: eval and
novel cameras are rendered where they are asked for. Cameras with an index outside the training
images (augmentation views: bird's-eye renders) are never corrected.

Any ray or splatting method can hold one: rays go through :meth:`CameraOptimizer.apply_to_rays`,
whole cameras through :meth:`CameraOptimizer.apply_to_cameras`.

Off by default: at CPU scale (a few hundred StreetNeRF steps) it does not help; on an SfM capture the
refined poses ended further from the truth than the SfM's, and on a street with perturbed poses the
centres drifted away (docs/methods.md). A few hundred steps
leave the field too blurry for its translation gradient to point home (the tiny-scene test shows a
basin of ~2 px; outside it the colour loss is as happy moving away); nerfstudio runs it for 30k steps.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras, RayBundle
from nerf2gs_plugin.utils.lie import correct_poses, correct_rays, so3xr3_matrices

PARAM_GROUP = "camera_opt"
"""The optimizer group of the corrections (the method config's ``optimizers`` must name it)."""


@dataclass
class CameraOptimizerConfig:
    """Pose refinement of the training cameras (--pipeline.model.camera-optimizer.*)."""

    mode: Literal["off", "SO3xR3"] = "off"
    """off: the dataset's poses as they are; SO3xR3: a learned rotation + translation per training
    image (its learning rate: --optimizers.camera-opt.*)."""
    trans_l2_penalty: float = 1e-2
    """Weight of the mean translation-correction norm (scene units) in the loss."""
    rot_l2_penalty: float = 1e-3
    """Weight of the mean rotation-correction norm (radians) in the loss."""

    @property
    def enabled(self) -> bool:
        return self.mode != "off"


class CameraOptimizer(nn.Module):
    """``pose_adjustment [N, 6]`` for N training images; identity for any other camera index."""

    def __init__(self, config: CameraOptimizerConfig, num_cameras: int) -> None:
        super().__init__()
        if config.mode != "SO3xR3":
            raise ValueError(f"camera optimizer mode must be SO3xR3 to build one, got {config.mode!r}")
        self.config = config
        self.num_cameras = num_cameras
        self.pose_adjustment = nn.Parameter(torch.zeros(max(num_cameras, 1), 6))

    def corrections(self, indices: Tensor) -> Tensor:
        """``[R, 3, 4]`` corrections of camera ``indices [R]``; exactly the identity for indices
        that are not training images."""
        idx = indices.long().reshape(-1).to(self.pose_adjustment.device)
        known = (idx >= 0) & (idx < self.num_cameras)
        tangent = self.pose_adjustment[idx.clamp(0, self.num_cameras - 1)] * known[:, None].to(self.pose_adjustment.dtype)
        return so3xr3_matrices(tangent)

    def apply_to_rays(self, rays: RayBundle) -> RayBundle:
        """A new bundle with each ray moved by its camera's correction (``camera_indices``)."""
        o, d = correct_rays(rays.origins, rays.directions, self.corrections(rays.camera_indices))
        return dataclasses.replace(rays, origins=o, directions=d)

    def apply_to_cameras(self, cameras: Cameras, indices: Tensor) -> Cameras:
        """``cameras`` (the training cameras ``indices``) at their corrected poses."""
        corr = self.corrections(indices).to(cameras.camera_to_worlds)
        return cameras.with_poses(correct_poses(cameras.camera_to_worlds, corr))

    def regulariser(self) -> Tensor:
        """nerfstudio's penalty: weighted mean norms of the translation and rotation corrections."""
        adj = self.pose_adjustment[: self.num_cameras]
        return (self.config.trans_l2_penalty * adj[:, :3].norm(dim=-1).mean()
                + self.config.rot_l2_penalty * adj[:, 3:].norm(dim=-1).mean())

    @torch.no_grad()
    def metrics(self) -> dict[str, Tensor]:
        """Mean and max correction (scene units, degrees), for the training log."""
        adj = self.pose_adjustment[: self.num_cameras].detach()
        trans, rot = adj[:, :3].norm(dim=-1), adj[:, 3:].norm(dim=-1) * (180.0 / math.pi)
        return {"camera_opt_translation_mean": trans.mean(), "camera_opt_translation_max": trans.max(),
                "camera_opt_rotation_deg_mean": rot.mean(), "camera_opt_rotation_deg_max": rot.max()}
