"""StreetNeRF: the segmentation-guided street NeRF that is the reference of the whole paper.

Li et al., "Segmentation-Guided Neural Radiance Fields for Novel Street View Synthesis", VISAPP 2025
(arXiv 2503.14219), a Zip-NeRF derivative with sky, ground and transient masks and per-image
appearance. The paper gives the ideas, not every loss form, so the forms below are ours where said.

Field and sampling (Zip-NeRF / nerfacto, scaled down for 2 CPU cores):
  * hash grid (``fields/hash_encoding.py``, C++ kernel on CPU) + small MLPs, L-inf scene contraction,
    Zip-NeRF level downweighting ``erf(1/sqrt(8 r^2 n_l^2))`` with the sample's cone radius;
  * two proposal rounds (``num_proposal_samples``, each its own small hash grid) then
    ``num_nerf_samples`` fine samples; proposal weights are annealed ``w**a`` with nerfacto's
    schedule (a: 0 -> 1 over ``proposal_anneal_steps``).

Losses (sum is minimised; ``M_*`` are the masks, ``W`` the per-image weight):
  * colour: ``mean_{W, not M_t} |C - C_gt|^2`` (nerfacto's MSE). With ``transient_mask`` the
    transient pixels get zero weight, as StreetNeRF's "disabling loss computation" (Sec. 3).
  * interlevel (mip-NeRF 360 Eq. 13, nerfacto weight 1.0) and distortion (mip-NeRF 360 Eq. 15 in
    spacing space, weight ``distortion_weight`` = 0.002 as nerfacto).
  * sky (``sky``): colour is ``C_field + (1 - A) * sky(d)`` with a direction-only SH+MLP sky model
    (infinite depth, StreetNeRF's sky colour modelling). Our form of its mask term:
    ``sky_weight * mean_{M_s} A`` (L1 on the accumulation of sky rays, 0.1) plus
    ``opaque_weight * mean_{not M_s, not M_t} (1 - A)`` (0.01), so sky is never a floater wall and
    everything that is not sky is solid.
  * ground (``ground_reg``): StreetNeRF regularises ground rays towards a plane. Our form: the plane
    has the data's up vector as normal and an offset ``h`` estimated from the data: the densest
    height of the sparse points below the cameras when the data has points, else an EMA of the
    median height of the rendered ground points between ``ground_start_step / 2`` and
    ``ground_start_step``; either way fixed while the loss is on (no feedback loop). For a ground ray with plane hit ``t*``:
    ``ground_weight * mean_{M_g} [ sum_i w_i min(|t_i - t*| / t*, 1) + (1 - A) ]`` (0.05), a
    line-of-sight loss (Urban Radiance Fields, Rematas et al. 2022) that bounds the relative depth
    error and pays full price for missing mass: the road becomes one opaque flat sheet, which is
    what removes the holes seen from above. Starts at ``ground_start_step``.
  * sparse-point depth (``point_depth``, ours, not in the paper; ``point_depth.py``): the same bounded
    line-of-sight loss on rays cast from training cameras through the dataset's sparse points that
    they see, ``point_depth_weight * mean [ sum_i w_i min(|t_i - t*| / t*, 1) + (1 - A) ]`` (0.05, DS-NeRF's
    SfM depth in URF's form), ``point_rays_per_batch`` rays a step. It builds the facades that street
    cameras see only at grazing angles, which is what bird's-eye views look at.
  * appearance (``appearance``): per-image affine 3x4 colour transform applied to the composite
    (``fields/appearance.py``), mean transform at novel views; ``appearance_reg_weight`` (1.0)
    pulls the transforms towards the identity so the mean stays a neutral exposure.

Any mask kind the data lacks turns its term off with one warning.

Camera refinement (``camera_optimizer.mode="SO3xR3"``, off by default; ``fields/camera_optimizer.py``):
a learned SO3xR3 correction per training image moves that image's training rays before rendering,
with its own optimizer group ``camera_opt`` and nerfstudio's small L2 penalty (``camera_opt_reg``).
The sparse-point rays are corrected too, by the correction of the camera they were cast from: a
point ray is the ray of the pixel where the point projects in that image, and its target distance
is a per-view depth, so it moves with the image like the colour rays (and the ground loss sees the
corrected rays it renders). Eval and novel cameras are never corrected. The augmentation renders
its composites from :meth:`StreetNeRFModel.refined_train_cameras` (see ``augment/datamanager.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras, RayBundle
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.engine.callbacks import TrainingCallback, TrainingCallbackAttributes, TrainingCallbackLocation
from nerf2gs_plugin.engine.losses import masked_mean
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse
from nerf2gs_plugin.engine.model import Model, ModelConfig
from nerf2gs_plugin.fields.appearance import AppearanceTransforms
from nerf2gs_plugin.fields.camera_optimizer import PARAM_GROUP as CAMERA_OPT_GROUP, CameraOptimizer, CameraOptimizerConfig
from nerf2gs_plugin.fields.hash_encoding import HashGridSpec
from nerf2gs_plugin.fields.sky import SkyModel
from nerf2gs_plugin.fields.street_field import ProposalField, StreetField
from nerf2gs_plugin.warn import warn
from nerf2gs_plugin.methods.point_visibility import visible_point_rays
from nerf2gs_plugin.methods.streetnerf.point_depth import line_of_sight_loss
from nerf2gs_plugin.methods.streetnerf.sampling import (
    distortion_loss,
    interlevel_loss,
    pdf_edges,
    render_weights,
    s_to_t,
    uniform_edges,
)
from nerf2gs_plugin.errors import ConfigError


@dataclass
class StreetNeRFModelConfig(ModelConfig):
    """StreetNeRF's model; the four switches are what the ablation bench turns off."""

    _target: type = field(default_factory=lambda: StreetNeRFModel)
    sky: bool = True
    """Direction-only sky model behind the field + accumulation -> 0 on sky-mask pixels."""
    ground_reg: bool = True
    """Plane regularisation of ground-mask rays."""
    transient_mask: bool = True
    """Exclude transient-mask pixels from the colour loss."""
    appearance: bool = True
    """Per-image affine colour transform."""
    expect_masks: bool = True
    """Warn when the dataset lacks sky, ground or transient masks. Off for a run trained without masks
    on purpose (the masks stage's first reference), where their absence is not news."""
    eval_appearance: Literal["mean", "identity", "nearest"] = "mean"
    """Colour transform of a rendered camera (render_camera: eval, held-out photos, views from above,
    the augmentation's renders): the mean of the per-image transforms (default), the identity, or
    the transform of the training camera nearest to it (by centre; a training camera gets its own):
    photos taken one after another share exposure and white balance, the mean of a whole set may
    not (castle-P30: the mean transform tints held-out photos blue)."""
    point_depth: bool = True
    """Depth supervision from the dataset's sparse points (ours, see the module docstring); off
    with a warning when the data has no points."""
    # field
    num_levels: int = 12
    """Hash grid: resolution levels."""
    features_per_level: int = 2
    """Hash grid: features per level."""
    log2_hashmap_size: int = 15
    """Hash grid: log2 of the table entries per level."""
    base_res: int = 16
    """Hash grid: coarsest resolution."""
    max_res: int = 1024
    """Hash grid: finest resolution."""
    hidden_dim: int = 64
    """Width of the density MLP."""
    color_hidden_dim: int = 64
    """Width of the colour MLP."""
    geo_feat_dim: int = 15
    """Features passed from the density MLP to the colour MLP."""
    sh_degree: int = 0
    """Degree of the view-direction encoding of colour. 0 (view-independent colour) by default: the
    bird's-eye directions were never seen in training, and a view-dependent head extrapolates them to
    grey/dark facades (degree 0 wins from above and on the street on the validation views:
    benchmarks/results/sh_degree_val.md).
    Raise it (nerfacto: 4) for glossy real scenes seen from the training directions only."""
    anti_alias: bool = True
    """Zip-NeRF level downweighting by the sample footprint."""
    # proposals
    num_proposal_samples: tuple[int, ...] = (48, 24)
    """Samples per ray of each proposal round."""
    num_nerf_samples: int = 24
    """Samples per ray of the final (field) round."""
    proposal_levels: int = 5
    """Hash-grid levels of each proposal network."""
    proposal_log2_hashmap_size: int = 14
    """log2 of the hash table entries of the proposal networks."""
    proposal_max_res: tuple[int, ...] = (128, 256)
    """Finest resolution of each proposal network."""
    proposal_hidden_dim: int = 16
    """Width of the proposal networks' MLPs."""
    proposal_anneal_steps: int = 800
    """Steps over which the proposal weights are annealed (mip-NeRF 360)."""
    near_plane: float = 0.01
    """Ray start distance (scene units)."""
    far_plane: float = 1000.0
    """Ray end distance (scene units; contracted space beyond the box)."""
    # loss weights
    interlevel_weight: float = 1.0
    """Weight of the proposal (interlevel) loss."""
    distortion_weight: float = 0.002
    """Weight of the distortion loss (mip-NeRF 360)."""
    sky_weight: float = 0.1
    """Weight of the sky-mask accumulation loss."""
    opaque_weight: float = 0.01
    """Weight of the loss pushing non-sky rays to full accumulation."""
    ground_weight: float = 0.05
    """Weight of the ground-plane line-of-sight loss."""
    ground_start_step: int = 200
    """Step from which the ground-plane loss is on."""
    ground_ema: float = 0.95
    """Moving-average factor of the fitted ground plane."""
    appearance_reg_weight: float = 1.0
    """Weight pulling the per-image colour transforms to the identity (on their mean squared deviation).
    1e-3 left them almost free: on castle-P30 they fitted more than the photos' exposure and cost the
    held-out photos; 1.0 is a little better on the two synthetic streets' validation views and no worse
    under exposure stress (benchmarks/results/appearance_reg.md)."""
    point_depth_weight: float = 0.05
    """Weight of the sparse-point depth loss."""
    point_rays_per_batch: int = 256
    """Rays through sparse points per step for the point-depth loss."""
    # rendering
    eval_chunk: int = 4096
    """Rays rendered at once when rendering a whole image."""
    render_nerf_samples: Optional[int] = None
    """Renders (no gradient: eval, the masks' reference, the augmentation's views) take this many fine
    samples per ray; None: the training's fine samples (num-nerf-samples). Fewer make a view faster but can
    miss surfaces of a long-trained reference's views from above (docs/speed.md)."""
    render_min_weight: float = 1e-4
    """Renders (no gradient: eval, views from above, the augmentation, the masks' reference) run the colour
    network only for samples whose compositing weight exceeds this; the others add at most this much
    each to a pixel's colour (0: every sample, the colour of training)."""
    background: tuple[float, float, float] = (0.5, 0.5, 0.5)
    """Learned constant background, used only when sky is off."""
    encoding_backend: str = "auto"
    """Hash-grid encoding: auto (our C++ kernel on CPU, else torch), cpu or torch."""
    camera_optimizer: CameraOptimizerConfig = field(default_factory=CameraOptimizerConfig)
    """Refinement of the training poses (SfM poses of a real capture); off by default."""


class StreetNeRFModel(Model):
    config: StreetNeRFModelConfig
    primitive_kind = None  # a field: its size is parameters and MB (num_primitives: hash-table entries)
    depth_along = "ray"  # expected distance along the unit ray

    def populate_modules(self, train_data: DataparserOutputs) -> None:
        c = self.config
        if len(c.proposal_max_res) != len(c.num_proposal_samples):
            raise ConfigError("proposal_max_res and num_proposal_samples must have the same length (one per proposal round)")
        if c.render_nerf_samples is not None and c.render_nerf_samples < 1:
            raise ConfigError(f"render_nerf_samples must be >= 1 (or None), got {c.render_nerf_samples}")
        box = train_data.scene_box.float()
        spec = HashGridSpec(c.num_levels, c.features_per_level, c.log2_hashmap_size, c.base_res, c.max_res)
        self.field = StreetField(box, spec, hidden=c.hidden_dim, geo_feat_dim=c.geo_feat_dim, sh_degree=c.sh_degree,
                                 color_hidden=c.color_hidden_dim, backend=c.encoding_backend)
        self.proposals = nn.ModuleList(
            ProposalField(box, HashGridSpec(c.proposal_levels, 2, c.proposal_log2_hashmap_size, 16, r), hidden=c.proposal_hidden_dim,
                          backend=c.encoding_backend)
            for r in c.proposal_max_res
        )
        kinds = set(train_data.mask_filenames)
        self.use_sky_loss = c.sky and self._mask_available("sky", kinds, "sky accumulation loss", c.expect_masks)
        self.use_ground = c.ground_reg and self._mask_available("ground", kinds, "ground plane regularisation", c.expect_masks)
        self.use_transient = c.transient_mask and self._mask_available("transient", kinds, "transient exclusion", c.expect_masks)
        self.sky_model = SkyModel() if c.sky else None
        self.bg_logit = None if c.sky else nn.Parameter(torch.logit(torch.tensor(c.background).clamp(0.01, 0.99)))
        self.appearance = AppearanceTransforms(self.num_train_images) if c.appearance else None
        if c.appearance:  # for eval_appearance="nearest"; rebuilt from the data, never in checkpoints
            self.register_buffer("train_centres", train_data.cameras.centers.float().reshape(-1, 3).clone(), persistent=False)
        up = torch.nn.functional.normalize(train_data.up.float().reshape(3), dim=0)
        self.register_buffer("up", up)
        self.register_buffer("ground_height", torch.zeros(()))
        self.register_buffer("ground_known", torch.zeros((), dtype=torch.bool))
        self.ground_from_points = False
        if train_data.points3D_xyz is not None:
            h = ground_height_from_points(train_data.points3D_xyz.float() @ up, train_data.cameras.centers.float() @ up)
            if h is not None:  # a plane from the data's points stays fixed; else it is estimated while training
                self.ground_height.fill_(h)
                self.ground_known.fill_(True)
                self.ground_from_points = True
        self._setup_point_rays(train_data)
        self.camera_optimizer = CameraOptimizer(c.camera_optimizer, self.num_train_images) if c.camera_optimizer.enabled else None
        self.step = 0

    def _setup_point_rays(self, train_data: DataparserOutputs) -> None:
        """Rays through every (training camera, visible sparse point) pair, kept as non-persistent
        buffers: they are rebuilt from the data, never stored in checkpoints."""
        self.use_point_depth = False
        if not self.config.point_depth:
            return
        if train_data.points3D_xyz is None or len(train_data.points3D_xyz) == 0:
            warn("the dataset has no sparse points", "StreetNeRF trains without its point-depth loss", stacklevel=3)
            return
        pr = visible_point_rays(train_data.cameras, train_data.points3D_xyz)
        if len(pr) == 0:
            warn("no sparse point is visible in any training view", "StreetNeRF trains without its point-depth loss", stacklevel=3)
            return
        rays = pr.rays
        for name, value in (("pt_origins", rays.origins), ("pt_directions", rays.directions), ("pt_radius", rays.pixel_radius),
                            ("pt_cameras", pr.camera_indices), ("pt_t_star", pr.t_star)):
            self.register_buffer(name, value.clone(), persistent=False)
        self.use_point_depth = True

    @staticmethod
    def _mask_available(kind: str, kinds: set[str], term: str, expected: bool = True) -> bool:
        if kind not in kinds:
            if expected:
                warn(f"the dataset has no {kind} masks", f"StreetNeRF trains without the {term}", stacklevel=3)
            return False
        return True

    # ------------------------------------------------------------------ contract
    def get_param_groups(self) -> dict[str, list[nn.Parameter]]:
        groups = {"fields": list(self.field.parameters()), "proposal_networks": list(self.proposals.parameters())}
        other = []
        if self.sky_model is not None:
            other += list(self.sky_model.parameters())
        if self.bg_logit is not None:
            other.append(self.bg_logit)
        if self.appearance is not None:
            other += list(self.appearance.parameters())
        groups["sky_appearance"] = other
        if self.camera_optimizer is not None:
            groups[CAMERA_OPT_GROUP] = list(self.camera_optimizer.parameters())
        return groups

    def get_training_callbacks(self, attrs: TrainingCallbackAttributes) -> list[TrainingCallback]:
        def set_step(step: int) -> None:
            self.step = step

        return [TrainingCallback([TrainingCallbackLocation.BEFORE_STEP], set_step)]

    def _anneal(self) -> float:
        """nerfacto's proposal-weight annealing exponent (0 -> 1, fast at the start)."""
        if not self.training:
            return 1.0
        x = min(max(self.step / max(self.config.proposal_anneal_steps, 1), 0.0), 1.0)
        b = 10.0
        return (b * x) / ((b - 1.0) * x + 1.0)

    def _render_rays(self, rays: RayBundle, image_idx: Optional[Tensor], novel: str = "mean", colour: bool = True) -> dict[str, Tensor]:
        """``colour`` False: the weights, accumulation and distances only (no colour network, sky or
        appearance), for a loss that reads no colour; the same sampling and weights as with colour."""
        c = self.config
        R = len(rays)
        dev = rays.origins.device
        jitter = self.training
        near = torch.full((R, 1), c.near_plane, device=dev)
        far = torch.full((R, 1), c.far_plane, device=dev)
        o, d = rays.origins, rays.directions
        radius = rays.pixel_radius.reshape(R, 1)

        def positions(s_edges: Tensor) -> tuple[Tensor, Tensor, Tensor]:
            t_edges = s_to_t(s_edges, near, far)
            t_mid = (t_edges[:, 1:] + t_edges[:, :-1]) / 2
            x = (o[:, None, :] + d[:, None, :] * t_mid[..., None]).reshape(-1, 3)
            r = (radius * t_mid).reshape(-1) if c.anti_alias else None
            return t_edges, x, r

        s_edges = uniform_edges(R, c.num_proposal_samples[0], dev, jitter)
        proposals: list[tuple[Tensor, Tensor]] = []
        anneal = self._anneal()
        for i, prop in enumerate(self.proposals):
            t_edges, x, r = positions(s_edges)
            sigma = prop(x, r).reshape(R, -1)
            w = render_weights(sigma, t_edges)
            proposals.append((s_edges, w))
            n_next = c.num_proposal_samples[i + 1] if i + 1 < len(self.proposals) else self._fine_samples()
            s_edges = pdf_edges(s_edges, w.detach() ** anneal, n_next, jitter)
        t_edges, x, r = positions(s_edges)
        n = s_edges.shape[1] - 1
        t_mid = (t_edges[:, 1:] + t_edges[:, :-1]) / 2
        if not colour:
            w = render_weights(self.field.density(x, r)[0].reshape(R, n), t_edges)
            return {"accumulation": w.sum(-1, keepdim=True), "weights": w, "s_edges": s_edges, "t_mid": t_mid,
                    "proposals": proposals}  # type: ignore[dict-item]
        dirs = d[:, None, :].expand(R, n, 3).reshape(-1, 3)
        if torch.is_grad_enabled() or c.render_min_weight <= 0:
            sigma, rgb = self.field(x, dirs, r)
            w = render_weights(sigma.reshape(R, n), t_edges)
        else:  # a render: the colour network only where a sample shows (its share of the pixel is > render_min_weight)
            sigma, geo = self.field.density(x, r)
            w = render_weights(sigma.reshape(R, n), t_edges)
            shown = (w > c.render_min_weight).reshape(-1)
            rgb = torch.zeros(R * n, 3, device=dev, dtype=w.dtype)
            rgb[shown] = self.field.color(geo[shown], dirs[shown])
        acc = w.sum(-1, keepdim=True)
        color = (w[..., None] * rgb.reshape(R, n, 3)).sum(1)
        if self.sky_model is not None:
            color = color + (1.0 - acc) * self.sky_model(d)
        else:
            color = color + (1.0 - acc) * torch.sigmoid(self.bg_logit)
        if self.appearance is not None:
            color = self.appearance(color, image_idx, novel)
        depth = (w * t_mid).sum(-1, keepdim=True) / acc.clamp_min(1e-6)
        return {"rgb": color, "accumulation": acc, "depth": depth, "weights": w, "s_edges": s_edges, "t_mid": t_mid,
                "proposals": proposals}  # type: ignore[dict-item]

    def _fine_samples(self) -> int:
        c = self.config
        return c.num_nerf_samples if torch.is_grad_enabled() or c.render_nerf_samples is None else c.render_nerf_samples

    def render_key(self) -> str:
        """What, beyond the weights, makes a render differ from training's sampling ("" when nothing):
        the augmentation's view store keys a reference's renders by it."""
        n = self.config.render_nerf_samples
        return "" if n is None or n == self.config.num_nerf_samples else f"fine{n}"

    def get_outputs(self, inputs: RayBundle) -> dict[str, Any]:
        if not isinstance(inputs, RayBundle):
            raise TypeError("StreetNeRF is a ray method: get_outputs takes a RayBundle (use render_camera for cameras)")
        if self.training and self.camera_optimizer is not None:
            inputs = self.camera_optimizer.apply_to_rays(inputs)
        out = self._render_rays(inputs, inputs.camera_indices if self.training else None)
        out["origins"], out["directions"] = inputs.origins, inputs.directions
        return out

    def get_metrics_dict(self, outputs: dict[str, Any], batch: dict[str, Any]) -> dict[str, Tensor]:
        metrics = {"psnr": psnr_from_mse(((outputs["rgb"].detach() - batch["rgb"]) ** 2).mean())}
        if self.use_ground and bool(self.ground_known):
            metrics["ground_height"] = self.ground_height.detach().clone()
        if self.camera_optimizer is not None:
            metrics.update(self.camera_optimizer.metrics())
        return metrics

    def _colour_weight(self, batch: dict[str, Any]) -> Tensor:
        weight = batch["weight"].float()
        if self.use_transient and "transient_mask" in batch:
            weight = weight * (~batch["transient_mask"]).float()
        return weight

    def get_loss_dict(self, outputs: dict[str, Any], batch: dict[str, Any], metrics_dict: dict[str, Tensor]) -> dict[str, Tensor]:
        c = self.config
        weight = self._colour_weight(batch)
        losses = {"rgb": masked_mean((outputs["rgb"] - batch["rgb"]) ** 2, weight)}
        if self.training:
            losses["interlevel"] = c.interlevel_weight * interlevel_loss(outputs["s_edges"], outputs["weights"], outputs["proposals"])
            losses["distortion"] = c.distortion_weight * distortion_loss(outputs["s_edges"], outputs["weights"])
        acc = outputs["accumulation"]
        static = (weight > 0).float()
        if self.use_sky_loss and "sky_mask" in batch:
            sky = batch["sky_mask"].float()
            losses["sky"] = c.sky_weight * masked_mean(acc, sky)
            losses["opaque"] = c.opaque_weight * masked_mean(1.0 - acc, (1.0 - sky) * static)
        if self.use_ground and "ground_mask" in batch:
            g = self._ground_loss(outputs, batch["ground_mask"].reshape(-1) & (static.reshape(-1) > 0))
            if g is not None:
                losses["ground"] = c.ground_weight * g
        if self.use_point_depth and self.training:
            losses["point_depth"] = c.point_depth_weight * self._point_depth_loss()
        if self.appearance is not None:
            losses["appearance_reg"] = c.appearance_reg_weight * self.appearance.deviation()
        if self.camera_optimizer is not None and self.training:
            losses["camera_opt_reg"] = self.camera_optimizer.regulariser()
        return losses

    def _point_depth_loss(self) -> Tensor:
        """Line-of-sight loss on a random batch of the sparse-point rays."""
        n = self.pt_t_star.shape[0]
        idx = torch.randint(0, n, (min(self.config.point_rays_per_batch, n),), device=self.pt_t_star.device)
        cams = self.pt_cameras[idx]
        rays = RayBundle(self.pt_origins[idx], self.pt_directions[idx], self.pt_radius[idx], cams)
        if self.camera_optimizer is not None:  # the ray of a pixel of that image: it moves with the image
            rays = self.camera_optimizer.apply_to_rays(rays)
        out = self._render_rays(rays, cams, colour=False)
        return line_of_sight_loss(out["weights"], out["t_mid"], out["accumulation"], self.pt_t_star[idx, None]).mean()

    def _ground_loss(self, outputs: dict[str, Any], ground: Tensor) -> Optional[Tensor]:
        """Line-of-sight loss of ground rays towards the ground plane (see the module docstring)."""
        if not self.training or not bool(ground.any()):
            return None
        o, d = outputs["origins"][ground], outputs["directions"][ground]
        w, t_mid, acc = outputs["weights"][ground], outputs["t_mid"][ground], outputs["accumulation"][ground]
        start = self.config.ground_start_step
        if not self.ground_from_points and start // 2 <= self.step < start:
            # estimated from photometric geometry only, then frozen: updating it while the loss pulls
            # the weights towards it feeds back and drifts (the plane ends up far below the road)
            self._update_ground_height(o, d, w, t_mid, acc)
        if self.step < start or not bool(self.ground_known):
            return None
        cos = d @ self.up
        t_star = (self.ground_height - o @ self.up) / cos.clamp(max=-1e-6)
        valid = (cos < -1e-3) & (t_star > self.config.near_plane) & (t_star < self.config.far_plane)
        if not bool(valid.any()):
            return None
        return line_of_sight_loss(w[valid], t_mid[valid], acc[valid], t_star[valid, None]).mean()

    @torch.no_grad()
    def _update_ground_height(self, o: Tensor, d: Tensor, w: Tensor, t_mid: Tensor, acc: Tensor) -> None:
        """EMA of the median height of the rendered ground points (median depth, solid rays only)."""
        pts_h = (o + d * median_depth(w, t_mid)) @ self.up
        solid = acc.reshape(-1) > 0.5
        if int(solid.sum()) < 16:
            return
        med = pts_h[solid].median()
        if bool(self.ground_known):
            self.ground_height.mul_(self.config.ground_ema).add_((1 - self.config.ground_ema) * med)
        else:
            self.ground_height.copy_(med)
            self.ground_known.fill_(True)

    @torch.no_grad()
    def render_camera(self, camera: Cameras, appearance: Optional[str] = None, pixels: Optional[Tensor] = None) -> dict[str, Tensor]:
        """Whole image for one camera in ``eval_chunk``-ray chunks; deterministic (no jitter).
        ``appearance``: how a camera that is no training photo is coloured ("mean", "identity",
        "nearest"); None: ``config.eval_appearance``. ``pixels``: bool ``[H, W]``, render only these
        rays (the others are 0 in every output): a composite needs the reference only under its mask."""
        was_training = self.training
        self.eval()
        try:
            camera = camera.to(self.device)
            h, w = int(camera.height[0]), int(camera.width[0])
            rays = camera.generate_rays(0)
            if pixels is not None:
                if tuple(pixels.shape) != (h, w):
                    raise ValueError(f"pixels is {tuple(pixels.shape)}, the camera is {(h, w)}")
                where = pixels.to(self.device).reshape(-1).bool()
                rays = rays[where]
            keys = ("rgb", "depth", "accumulation")
            chunks: dict[str, list[Tensor]] = {k: [] for k in keys}
            mode = appearance or self.config.eval_appearance
            nearest = self._nearest_train_image(camera) if mode == "nearest" else None
            novel = "identity" if mode == "identity" else "mean"
            for i in range(0, len(rays), self.config.eval_chunk):
                chunk = rays[i : i + self.config.eval_chunk]
                idx = None if nearest is None else torch.full((len(chunk),), nearest, dtype=torch.long, device=self.device)
                out = self._render_rays(chunk, idx, novel)
                for k in keys:
                    chunks[k].append(out[k])
            if pixels is None:
                result = {k: torch.cat(v).reshape(h, w, -1) for k, v in chunks.items()}
            else:
                result = {}
                for k, v in chunks.items():
                    flat = torch.zeros(h * w, 3 if k == "rgb" else 1, device=self.device)
                    if v:
                        flat[where] = torch.cat(v)
                    result[k] = flat.reshape(h, w, -1)
            result["rgb"] = result["rgb"].clamp(0.0, 1.0)
            return result
        finally:
            self.train(was_training)

    @torch.no_grad()
    def refined_train_cameras(self, cameras: Cameras) -> Optional[Cameras]:
        """The training cameras (in training-image order) at the poses the camera optimizer learned;
        None without one (the dataset's poses are the model's)."""
        if self.camera_optimizer is None:
            return None
        if len(cameras) != self.num_train_images:
            raise ValueError(f"{len(cameras)} cameras given, the model has {self.num_train_images} training images")
        idx = torch.arange(len(cameras), device=self.camera_optimizer.pose_adjustment.device)
        return self.camera_optimizer.apply_to_cameras(cameras, idx)

    def _nearest_train_image(self, camera: Cameras) -> Optional[int]:
        """The training image whose camera centre is nearest ``camera``'s (None without appearance)."""
        if self.appearance is None:
            return None
        return int((self.train_centres - camera.centers[0].to(self.train_centres)).norm(dim=-1).argmin())

    def num_primitives(self) -> int:
        return self.field.encoding.num_entries() + sum(p.encoding.num_entries() for p in self.proposals)


def median_depth(weights: Tensor, t_mid: Tensor) -> Tensor:
    """Distance where a ray's accumulated weight reaches half its total ``[R,1]``: unlike the
    expected depth it ignores a little mass far away (robust for estimating the ground plane)."""
    cw = torch.cumsum(weights, -1)
    half = 0.5 * cw[:, -1:]
    idx = torch.searchsorted(cw.contiguous(), half.contiguous()).clamp(max=t_mid.shape[1] - 1)
    return t_mid.gather(-1, idx)


def ground_height_from_points(heights: Tensor, camera_heights: Tensor, min_points: int = 20) -> Optional[float]:
    """The road's height along ``up`` from sparse points: the densest height below every camera
    (a histogram mode, refined by the median of the points near it). Facades and cars spread their
    points over many heights; the road piles them up in one thin layer."""
    below = heights[heights < camera_heights.min()]
    if len(below) < min_points:
        return None
    lo, hi = float(below.min()), float(below.max())
    if hi - lo < 1e-9:
        return lo
    bins = 64
    hist = torch.histc(below, bins, lo, hi)
    width = (hi - lo) / bins
    centre = lo + (int(hist.argmax()) + 0.5) * width
    near = below[(below - centre).abs() <= 1.5 * width]
    return float(near.median())
