"""A third-party nerf2gs method, packaged on its own: a dense voxel-grid radiance field
(Plenoxels-like without spherical harmonics). It proves the plugin contract: a MethodSpecification
under the ``nerf2gs.methods`` entry-point group, trained by ``ns2gs-train voxel-grid``."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras, RayBundle
from nerf2gs_plugin.datamanagers.rays import RayDataManagerConfig
from nerf2gs_plugin.engine.losses import masked_mean
from nerf2gs_plugin.engine.model import Model, ModelConfig
from nerf2gs_plugin.engine.optimizers import OptimizerConfig
from nerf2gs_plugin.engine.pipeline import PipelineConfig
from nerf2gs_plugin.engine.trainer_config import TrainerConfig
from nerf2gs_plugin.registry import MethodSpecification


@dataclass
class VoxelGridConfig(ModelConfig):
    _target: type = field(default_factory=lambda: VoxelGridModel)
    resolution: int = 48
    num_samples: int = 48
    background: tuple[float, float, float] = (0.5, 0.6, 0.8)
    """Initial colour of the learned background."""


class VoxelGridModel(Model):
    config: VoxelGridConfig
    depth_along = "ray"  # its depth is the expected distance along the (unit) ray

    def populate_modules(self, train_data) -> None:
        r = self.config.resolution
        self.grid = nn.Parameter(torch.zeros(1, 4, r, r, r))  # density logit + rgb logits
        self.background = nn.Parameter(torch.logit(torch.tensor(self.config.background)))  # seen where rays leave the box

    def get_param_groups(self) -> dict[str, list[nn.Parameter]]:
        return {"grid": [self.grid, self.background]}

    def _query(self, pts: Tensor) -> tuple[Tensor, Tensor]:
        lo, hi = self.scene_box[0].to(pts), self.scene_box[1].to(pts)
        g = (2 * (pts - lo) / (hi - lo) - 1).reshape(1, -1, 1, 1, 3)
        v = F.grid_sample(self.grid, g, align_corners=True, padding_mode="zeros").reshape(4, -1).T
        return F.softplus(v[:, 0] - 2.0), torch.sigmoid(v[:, 1:])

    def _render_rays(self, rays: RayBundle) -> dict[str, Tensor]:
        lo, hi = self.scene_box[0].to(rays.origins), self.scene_box[1].to(rays.origins)
        inv = 1.0 / torch.where(rays.directions.abs() < 1e-9, torch.full_like(rays.directions, 1e-9), rays.directions)
        t0, t1 = (lo - rays.origins) * inv, (hi - rays.origins) * inv
        near = torch.minimum(t0, t1).amax(-1).clamp_min(0.0)
        far = torch.maximum(t0, t1).amin(-1).clamp_min(near + 1e-4)
        n = self.config.num_samples
        u = (torch.arange(n, device=near.device) + 0.5) / n
        t = near[:, None] + (far - near)[:, None] * u
        pts = rays.origins[:, None] + rays.directions[:, None] * t[..., None]
        sigma, rgb = self._query(pts.reshape(-1, 3))
        delta = ((far - near) / n)[:, None]
        alpha = 1 - torch.exp(-sigma.reshape(-1, n) * delta)
        trans = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1 - alpha[:, :-1] + 1e-10], -1), -1)
        w = alpha * trans
        acc = w.sum(-1, keepdim=True)
        bg = torch.sigmoid(self.background)
        color = (w[..., None] * rgb.reshape(-1, n, 3)).sum(1) + (1 - acc) * bg
        depth = (w * t).sum(-1, keepdim=True) / acc.clamp_min(1e-6)
        return {"rgb": color, "depth": depth, "accumulation": acc}

    def get_outputs(self, inputs: RayBundle) -> dict[str, Tensor]:
        return self._render_rays(inputs)

    def get_loss_dict(self, outputs, batch, metrics_dict) -> dict[str, Tensor]:
        weight = batch["weight"]
        if "transient_mask" in batch:
            weight = weight * (~batch["transient_mask"]).float()
        return {"rgb": masked_mean((outputs["rgb"] - batch["rgb"]).abs(), weight)}

    @torch.no_grad()
    def render_camera(self, camera: Cameras) -> dict[str, Tensor]:
        h, w = int(camera.height[0]), int(camera.width[0])
        rays = camera.generate_rays(0)
        outs = [self._render_rays(rays[i : i + 8192]) for i in range(0, len(rays), 8192)]
        return {k: torch.cat([o[k] for o in outs]).reshape(h, w, -1) for k in outs[0]}

    def num_primitives(self) -> int:
        return self.config.resolution**3


voxel_grid_method = MethodSpecification(
    config=TrainerConfig(
        method_name="voxel-grid",
        max_num_iterations=300,
        steps_per_eval_image=100,
        steps_per_save=300,
        pipeline=PipelineConfig(datamanager=RayDataManagerConfig(rays_per_batch=1024), model=VoxelGridConfig()),
        optimizers={"grid": OptimizerConfig(lr=0.1, eps=1e-15)},
    ),
    description="Example plugin: a dense voxel-grid radiance field (third-party package).",
)
