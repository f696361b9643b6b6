"""Splatfacto: nerfstudio's 3D Gaussian splatting, on this project's rasterizer.

Parameters (an ``nn.ParameterDict`` ``gauss``; each key is also an optimizer group):
``means [N,3]``, ``scales [N,3]`` (log), ``quats [N,4]`` (wxyz, unnormalised), ``opacities [N]``
(logit), ``features_dc [N,3]`` and ``features_rest [N,K-1,3]`` (SH, K = (sh_degree+1)^2).
The SH degree used for rendering rises by one every ``sh_degree_interval`` steps up to
``sh_degree``. Densification follows :mod:`.strategy` (default or MCMC).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable, Literal, Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.engine.callbacks import TrainingCallback, TrainingCallbackAttributes, TrainingCallbackLocation as Loc
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse
from nerf2gs_plugin.engine.model import Model
from nerf2gs_plugin.fields.appearance import AppearanceTransforms
from nerf2gs_plugin.methods.capture_path import CapturePath, capture_path
from nerf2gs_plugin.methods.gaussian_utils import knn_mean_distance, logit
from nerf2gs_plugin.utils.quaternions import normalize_quats, random_quats
from nerf2gs_plugin.utils.sh import num_sh_bases, rgb_to_sh
from nerf2gs_plugin.methods.splatfacto.shared import Background, SplatModelConfig, composite, image_loss
from nerf2gs_plugin.methods.splatfacto.strategy import (
    DefaultStrategy,
    DefaultStrategyConfig,
    MCMCStrategy,
    MCMCStrategyConfig,
)
from nerf2gs_plugin.methods.strategy_base import Strategy
from nerf2gs_plugin.utils.schedule import scheduled

HIDDEN_OPACITY_LOGIT = -30.0
"""An opacity logit that the rasterizer skips (sigmoid ~1e-13, far below its 1/255 alpha floor)."""

MAX_SPARSE_ON_PATH = 0.05
"""More of the sparse points than this within the path clearance: the clearance is switched off."""


def cpu_scale_strategy(**changes: Any) -> DefaultStrategyConfig:
    """Splatfacto's densification at the CPU scale (2DGS's with its own changes)."""
    base = DefaultStrategyConfig(warmup_length=300, reset_alpha_every=1000, stop_split_at=1500, stop_screen_size_at=400,
                                 max_pause_after_reset=300, max_gaussians=60000, pixel_steps_per_gaussian=54000.0,
                                 gaussians_per_sparse_point=2.0, prune_weight_fraction=0.1, path_clearance_m=1.0)
    return dataclasses.replace(base, **changes)


@dataclass
class SplatfactoModelConfig(SplatModelConfig):
    """Defaults are the CPU scale (the step counts and the paper-scale values are in methods/splatfacto/config.py)."""

    _target: type = field(default_factory=lambda: SplatfactoModel)
    sh_degree: int = 3
    """Maximum degree of the spherical harmonics of the colour."""
    sh_degree_interval: int = scheduled(300)
    """Raise the SH degree every this many steps (nerfstudio: 1000 of 30000)."""
    init_opacity: float = 0.1
    """Opacity of the initial Gaussians."""
    strategy_type: Literal["default", "mcmc"] = "default"
    """Densification: default (clone / split / prune, settings under strategy) or mcmc (settings under mcmc)."""
    strategy: DefaultStrategyConfig = field(default_factory=lambda: cpu_scale_strategy())
    """The default strategy at CPU scale (paper values in config.py). Growth stops at a soft budget read from
    the scene (strategy_base.SceneBudget): the larger of the training views' pixels x the densification
    window / 54,000 and 2 Gaussians per sparse point, at most 60k; once densification stops the Gaussians
    carrying the lightest 10% of the training views' blending weight are pruned (benchmarks/results/size_prune.md);
    every prune keeps 1 m around the capture path free (benchmarks/results/path_clearance.md). The pixel
    term meets the model-size target on two synthetic streets (benchmarks/results/views_budget/), the
    point term keeps a real courtyard's Gaussians (castle-P30's validation photos: benchmarks/results/scene_budget/)."""
    depth_loss_weight: float = 0.1
    """Sparse-point depth (0: off): weight of mean_p A_p * min(|D_p - z_p| / z_p, 1) over the sparse
    points a training view sees (methods/point_visibility.py), D the rendered expected depth and A the
    accumulation at the point's pixel (a weight only, no gradient), z the point's depth: gsplat's depth_loss in
    the bounded form of StreetNeRF's point depth. A Gaussian that floats in front of a surface the SfM saw pulls
    D short of z.
    0.1 chosen on the validation views of two streets and castle-P30 (benchmarks/results/depth_loss.md; it
    lifts the veil of near-camera Gaussians over one photo); the paper scale keeps the same value."""
    densify_from_extra_views: bool = True
    """False: the default strategy's clone / split statistics (screen-space gradients) come from the input
    views only; the additional views (from above) still move the Gaussians but do not decide where new ones
    grow (what only a NeRF's render shows, e.g. the far background from above, seeds no Gaussians)."""
    background_from_extra_views: bool = True
    """False: the additional views (from above) do not train the background: where the target leaves them
    transmittance the background shows but takes no gradient, so a view-direction sky fitted to the ground
    seen from above cannot spill into the street views' sky (the Gaussians must fill those pixels instead)."""
    extra_view_appearance: Literal["off", "per-view", "shared"] = "off"
    """A learned affine colour transform (3x3 + bias, identity at the start) applied to the render of an
    additional (NeRF-rendered) view before its loss: the NeRF's exposure and white balance in those views
    go into the transform, so they teach the Gaussians geometry and leave colour to the input views.
    per-view: one per additional view; shared: one for all of them; renders outside training use none.
    Off: neither keeps more street-level quality on real captures (benchmarks/results/street_level_view_colour.md)."""
    extra_view_appearance_reg: float = 1.0
    """Weight of the mean squared distance of the transform in use from the identity (keeps it small)."""
    mcmc: MCMCStrategyConfig = field(default_factory=lambda: MCMCStrategyConfig(
        cap_max=30000, refine_start_iter=300, refine_stop_iter=2500))
    """The MCMC strategy at CPU scale (with --pipeline.model.strategy-type mcmc): 30k-Gaussian hard budget."""


class SplatfactoModel(Model):
    config: SplatfactoModelConfig
    primitive_kind = "Gaussians"

    # ------------------------------------------------------------------ setup
    def populate_modules(self, train_data: DataparserOutputs) -> None:
        cfg = self.config
        gen = torch.Generator().manual_seed(0)
        means, colors = self._initial_points(train_data, gen)
        mcmc = cfg.strategy_type == "mcmc"
        if mcmc and means.shape[0] > cfg.mcmc.cap_max:
            sel = torch.randperm(means.shape[0], generator=gen)[: cfg.mcmc.cap_max]
            means, colors = means[sel], colors[sel]
        n = means.shape[0]
        dist = knn_mean_distance(means).clamp_min(1e-4)
        init_op = cfg.mcmc.init_opacity if mcmc else cfg.init_opacity
        if mcmc:  # gsplat's MCMC recipe: opaque but small initial Gaussians
            dist = dist * cfg.mcmc.init_scale
        k = num_sh_bases(cfg.sh_degree)
        self.gauss = nn.ParameterDict({
            "means": nn.Parameter(means),
            "scales": nn.Parameter(torch.log(dist)[:, None].repeat(1, 3)),
            "quats": nn.Parameter(random_quats(n, gen)),
            "opacities": nn.Parameter(torch.full((n,), float(logit(init_op)))),
            "features_dc": nn.Parameter(rgb_to_sh(colors)),
            "features_rest": nn.Parameter(torch.zeros(n, k - 1, 3)),
        })
        self.background = Background(cfg.background, cfg.sky_sh_degree)
        self.register_buffer("step", torch.zeros((), dtype=torch.long))
        self._meta: Optional[dict[str, Any]] = None
        self._extra_batch = False  # the last training batch was an additional view (set by get_loss_dict)
        self.extra_appearance: Optional[AppearanceTransforms] = None  # set by add_extra_views
        self._sparse_points = len(train_data.points3D_xyz) if train_data.points3D_xyz is not None else 0
        self._path = self._capture_path(train_data, means if train_data.points3D_xyz is not None else None)
        self._depth_targets = self._sparse_depth_targets(train_data) if cfg.depth_loss_weight > 0 else None
        self._depth_target_heights = train_data.cameras.height.tolist()  # the size the targets' pixels are at
        self._setup_strategy()

    @torch.no_grad()
    def add_initial_points(self, xyz: Tensor, rgb: Tensor) -> int:
        """New Gaussians at ``xyz`` as the initial ones are made (kNN scale among all, initial opacity,
        colour ``rgb``); before training only (the optimizers are built from the parameters after)."""
        if len(xyz) == 0:
            return 0
        g = self.gauss
        dev = g["means"].device
        xyz = xyz.to(dev, torch.float32)
        every = torch.cat([g["means"].detach(), xyz])
        dist = knn_mean_distance(every).clamp_min(1e-4)[-len(xyz):]
        mcmc = self.config.strategy_type == "mcmc"
        if mcmc:
            dist = dist * self.config.mcmc.init_scale
        init_op = self.config.mcmc.init_opacity if mcmc else self.config.init_opacity
        n, k = len(xyz), g["features_rest"].shape[1]
        scales = torch.log(dist)[:, None].repeat(1, g["scales"].shape[1])  # 2DGS: two tangent scales
        new = {"means": xyz, "scales": scales, "quats": random_quats(n, torch.Generator().manual_seed(1)).to(dev),
               "opacities": torch.full((n,), float(logit(init_op)), device=dev), "features_dc": rgb_to_sh(rgb.to(dev).float()),
               "features_rest": torch.zeros(n, k, 3, device=dev)}
        for name, rows in new.items():
            g[name] = nn.Parameter(torch.cat([g[name].detach(), rows.to(g[name].dtype)]))
        self._setup_strategy()
        return n

    def _initial_points(self, data: DataparserOutputs, gen: torch.Generator) -> tuple[Tensor, Tensor]:
        """Sparse points (normalised world) and their colours in [0,1]; random in the box if none."""
        if data.points3D_xyz is not None and len(data.points3D_xyz) > 0:
            xyz = data.points3D_xyz.float().clone()
            rgb = data.points3D_rgb.float() / 255.0 if data.points3D_rgb is not None else torch.full_like(xyz, 0.5)
            return xyz, rgb
        from nerf2gs_plugin.warn import warn

        warn("no sparse points", f"starting from {self.config.num_random} random Gaussians in the scene box", stacklevel=3)
        lo, hi = self.scene_box[0], self.scene_box[1]
        xyz = lo + (hi - lo) * torch.rand(self.config.num_random, 3, generator=gen)
        return xyz, torch.rand(self.config.num_random, 3, generator=gen)

    def _capture_path(self, data: DataparserOutputs, sparse: Optional[Tensor]) -> Optional[tuple[CapturePath, float]]:
        """The path to keep clear (``strategy.path_clearance_m``) and one metre in world units; None
        (with a warning) when the sparse points themselves crowd it: then the metric scale is wrong
        (or the path runs through the scene) and the clearance would cut real content."""
        metres = self.config.strategy.path_clearance_m
        if metres <= 0 or len(data.cameras) == 0:
            return None
        path, metre = capture_path(data.cameras.camera_to_worlds[:, :3, 3]), data.metres_to_world(1.0)
        if sparse is not None and sparse.shape[0] > 0:
            inside = float(path.near(sparse.float(), metres * metre).float().mean())
            if inside > MAX_SPARSE_ON_PATH:
                from nerf2gs_plugin.warn import warn

                warn(f"{inside:.0%} of the sparse points lie within {metres:g} m of the camera path",
                     "not keeping the path clear (is the metric scale right? "
                     "--pipeline.datamanager.dataparser.metres-per-unit, "
                     "or --pipeline.model.strategy.path-clearance-m 0 to say so)", stacklevel=3)
                return None
        return path, metre

    def _sparse_depth_targets(self, data: DataparserOutputs) -> Optional[list[tuple[Tensor, Tensor, Tensor]]]:
        """Per training view: (v [K], u [K] pixel rows / columns, z [K] camera-axis depth) of the sparse
        points it sees; rebuilt from the data, never in checkpoints. None (with a warning) without points."""
        from nerf2gs_plugin.methods.point_visibility import visible_point_rays
        from nerf2gs_plugin.warn import warn

        if data.points3D_xyz is None or len(data.points3D_xyz) == 0:
            warn("the dataset has no sparse points", "Splatfacto trains without its depth loss", stacklevel=4)
            return None
        pr = visible_point_rays(data.cameras, data.points3D_xyz)
        forward = -data.cameras.camera_to_worlds[:, :3, 2]  # OpenGL: the camera looks along -z
        z = pr.t_star * (pr.rays.directions * forward[pr.camera_indices]).sum(-1)
        return [(pr.coords[sel, 1], pr.coords[sel, 0], z[sel]) for sel in (pr.camera_indices == i for i in range(len(data.cameras)))]

    def _depth_targets_of(self, image_idx: int) -> Optional[tuple[Tensor, Tensor, Tensor]]:
        """The view's sparse-point depth targets, or None for a view without any (an augmented view from above)."""
        if self._depth_targets is None or image_idx >= len(self._depth_targets) or len(self._depth_targets[image_idx][2]) == 0:
            return None
        return self._depth_targets[image_idx]

    def _depth_loss(self, outputs: dict[str, Tensor], image_idx: int) -> Optional[Tensor]:
        """See ``depth_loss_weight``; None for a view without targets (an augmented view from above)."""
        if self._depth_targets_of(image_idx) is None:
            return None
        dev = outputs["depth"].device
        if self._depth_targets[image_idx][2].device != dev:  # built on the CPU at setup: moved once, not every step
            self._depth_targets = [tuple(t.to(dev) for t in view) for view in self._depth_targets]
        v, u, z = self._depth_targets[image_idx]
        h, w = outputs["depth"].shape[:2]
        f = round(self._depth_target_heights[image_idx] / h)
        if f > 1:  # a coarse step (the datamanager's resolution schedule): the points' pixels at its size
            v, u = v // f, u // f
            inside = (v < h) & (u < w)
            v, u, z = v[inside], u[inside], z[inside]
        d, a = outputs["depth"][v, u, 0], outputs["accumulation"][v, u, 0]
        # the accumulation only weights (detached): transparency must not be a way out of the loss
        return self.config.depth_loss_weight * (a.detach() * ((d - z).abs() / z).clamp(max=1.0)).mean()

    def _make_strategy(self) -> Strategy:
        c = self.config
        if c.strategy_type == "mcmc":
            return MCMCStrategy(c.mcmc)
        return DefaultStrategy(c.strategy, num_train_images=self.num_train_images)

    def _setup_strategy(self) -> None:
        self.strategy = self._make_strategy()
        if isinstance(self.strategy, DefaultStrategy):
            self.strategy.weights_fn = self.training_blend_weights
            self.strategy.fidelity_fn = self.training_prune_fidelity
            self.strategy.budget.pixels_fn = self.training_pixels
            self.strategy.budget.points = self._sparse_points
            if self._path is not None:
                self.strategy.clear_path(*self._path)

    def get_param_groups(self) -> dict[str, list[nn.Parameter]]:
        groups = {name: [p] for name, p in self.gauss.items()}
        groups["background"] = self.background.parameters_list()
        if self.extra_appearance is not None:
            groups["extra_appearance"] = list(self.extra_appearance.parameters())
        return groups

    def add_extra_views(self, count: int) -> None:
        """``count`` additional views follow the input views (see ``extra_view_appearance``)."""
        mode = self.config.extra_view_appearance
        if mode != "off" and count > 0:
            self.extra_appearance = AppearanceTransforms(count if mode == "per-view" else 1).to(self.device)

    def _extra_view_colour(self, rgb: Tensor, image_idx: int) -> tuple[Tensor, Tensor]:
        """An additional view's render in its colour transform, and the transform's regulariser."""
        app = self.extra_appearance
        j = min(image_idx - self.num_train_images, app.num_images - 1)
        return app.apply_one(rgb, j), self.config.extra_view_appearance_reg * app.deviation(j)

    # ------------------------------------------------------------------ rendering
    @property
    def current_sh_degree(self) -> int:
        return min(int(self.step) // max(self.config.sh_degree_interval, 1), self.config.sh_degree)

    def _render(self, camera: Cameras, training: bool, depth: bool = True) -> dict[str, Tensor]:
        """``depth`` False: no depth channel (and no ``depth`` output); colour and accumulation are the same."""
        from nerf2gs_plugin.rendering import rasterize_gaussians

        g = self.gauss
        h, w = int(camera.height[0]), int(camera.width[0])
        dev = g["means"].device
        camera = camera.to(dev)
        bg = self.background(camera, training)
        if g["means"].shape[0] == 0:
            zeros = torch.zeros(h, w, 1, device=dev)
            return {"rgb": (zeros + bg).expand(h, w, 3), "depth": zeros, "accumulation": zeros}
        mode = "RGB+ED" if depth else "RGB"
        colors = torch.cat([g["features_dc"][:, None, :], g["features_rest"]], dim=1)
        render, alpha, meta = rasterize_gaussians(
            g["means"], normalize_quats(g["quats"]), torch.exp(g["scales"]), torch.sigmoid(g["opacities"]), colors,
            camera.viewmats(), camera.Ks(), w, h, near_plane=self.config.near_plane, far_plane=self.config.far_plane,
            sh_degree=self.current_sh_degree, render_mode=mode, rasterize_mode=self.config.rasterize_mode,
            backend=self.config.backend,
        )
        if training:
            self.strategy.step_pre_backward(self.gauss, None, int(self.step), meta)
        self._meta = meta if training else None
        alpha = alpha[0]
        rgb = composite(render[0, ..., :3], alpha, bg).clamp(0.0, 1.0)
        out = {"rgb": rgb, "accumulation": alpha, "background": bg}
        if depth:
            out["depth"] = render[0, ..., 3:4]
        if training and not self.config.background_from_extra_views:
            out["foreground"] = render[0, ..., :3]  # to composite again on a detached background (an extra view)
        return out

    def _render_features(self, camera: Cameras, features: Tensor) -> Tensor:
        """``[1, H, W, D]``: plain per-primitive ``features [N, D]`` composited by the rasterizer of
        :meth:`_render` (the parameters detached, so only ``features`` can carry a gradient)."""
        from nerf2gs_plugin.rendering import rasterize_gaussians

        g = {k: v.detach() for k, v in self.gauss.items()}
        h, w = int(camera.height[0]), int(camera.width[0])
        render, _, _ = rasterize_gaussians(
            g["means"], normalize_quats(g["quats"]), torch.exp(g["scales"]), torch.sigmoid(g["opacities"]), features,
            camera.viewmats(), camera.Ks(), w, h, near_plane=self.config.near_plane, far_plane=self.config.far_plane,
            render_mode="RGB", rasterize_mode=self.config.rasterize_mode, backend=self.config.backend,
        )
        return render

    def blend_weights(self, cameras: Cameras) -> Tensor:
        """``[N]``: each primitive's alpha x transmittance summed over every pixel of ``cameras``. It
        is the gradient of the summed render of all-ones features, so the rasterizer's own backward
        counts it (one view at a time; no primitives x pixels tensor)."""
        n, dev = self.num_primitives(), self.gauss["means"].device
        total = torch.zeros(n, device=dev)
        for i in range(len(cameras)):
            ones = torch.ones(n, 1, device=dev, requires_grad=True)
            with torch.enable_grad():
                render = self._render_features(cameras[i].to(dev), ones)
                (grad,) = torch.autograd.grad(render.sum(), ones)
            total += grad[:, 0]
        return total

    def training_blend_weights(self) -> Optional[Tensor]:
        """:meth:`blend_weights` over every training view (real and extra), or None before the
        training callbacks named them (the strategy's weight prune then does nothing)."""
        return None if self._train_cameras is None else self.blend_weights(self._train_cameras())

    @torch.no_grad()
    def prune_fidelity(self, cameras: Cameras, batches: Callable[[int], dict[str, Any]], cull: Tensor) -> tuple[float, float]:
        """``(change, error)`` in dB over the pixels of ``cameras`` that the primitives must explain (neither
        sky- nor transient-masked in ``batches(i)``): PSNR of the renders without the primitives of ``cull [N]``
        (bool) against the renders with all, and PSNR of the renders with all against the images. The hidden
        primitives get a zero opacity for the second render and theirs back after it (one view at a time)."""
        opacities = self.gauss["opacities"]
        saved = opacities.data[cull].clone()
        change, error, count = 0.0, 0.0, 0
        for i in range(len(cameras)):
            camera, batch = cameras[i], batches(i)
            full = self.render_camera(camera)["rgb"]
            opacities.data[cull] = HIDDEN_OPACITY_LOGIT
            try:
                without = self.render_camera(camera)["rgb"]
            finally:
                opacities.data[cull] = saved
            keep = torch.ones_like(full[..., :1], dtype=torch.bool)
            for kind in ("sky_mask", "transient_mask"):
                if batch.get(kind) is not None:
                    keep &= ~batch[kind].to(keep.device)
            change += float((((full - without) ** 2) * keep).sum())
            error += float((((full - batch["image"].to(full)) ** 2) * keep).sum())
            count += 3 * int(keep.sum())
        n = max(count, 1)
        return float(psnr_from_mse(torch.tensor(change / n))), float(psnr_from_mse(torch.tensor(error / n)))

    def training_prune_fidelity(self, cull: Tensor) -> Optional[tuple[float, float]]:
        """:meth:`prune_fidelity` over every training view (real and extra), or None before the training
        callbacks named them."""
        if self._train_cameras is None or self._train_batch is None:
            return None
        return self.prune_fidelity(self._train_cameras(), self._train_batch, cull)

    def get_outputs(self, inputs: Cameras) -> dict[str, Tensor]:
        return self._render(inputs, training=self.training)

    def get_train_outputs(self, inputs: Cameras, batch: dict[str, Any]) -> dict[str, Tensor]:
        """Without the depth channel where no loss reads it (a view without sparse-point depth targets, e.g. a
        bird's-eye view): the compositing kernel then carries 3 channels instead of 4, forward and backward."""
        idx = batch.get("image_idx")
        needs_depth = idx is None or self._depth_targets_of(int(idx)) is not None
        return self._render(inputs, training=self.training, depth=needs_depth)

    @torch.no_grad()
    def render_camera(self, camera: Cameras) -> dict[str, Tensor]:
        out = self._render(camera, training=False)
        out.pop("background", None)
        return out

    # ------------------------------------------------------------------ losses
    def get_metrics_dict(self, outputs: dict[str, Tensor], batch: dict[str, Any]) -> dict[str, Tensor]:
        mse = ((outputs["rgb"].detach() - batch["image"].to(outputs["rgb"])) ** 2).mean()
        return {"psnr": psnr_from_mse(mse), "gaussian_count": torch.tensor(float(self.num_primitives()))}

    def get_loss_dict(self, outputs: dict[str, Tensor], batch: dict[str, Any], metrics_dict: dict[str, Tensor]) -> dict[str, Tensor]:
        c = self.config
        self._extra_batch = self.training and "image_idx" in batch and int(batch["image_idx"]) >= self.num_train_images
        if self._extra_batch and "foreground" in outputs:
            bg = outputs["background"].detach()
            outputs = {**outputs, "rgb": composite(outputs["foreground"], outputs["accumulation"], bg).clamp(0.0, 1.0)}
        reg = None
        if self._extra_batch and self.extra_appearance is not None:
            rgb, reg = self._extra_view_colour(outputs["rgb"], int(batch["image_idx"]))
            outputs = {**outputs, "rgb": rgb}
        sky_bg = outputs.get("background") if c.background == "random" else None
        losses = image_loss(outputs, batch, c.ssim_lambda, c.mask_transients, c.sky_alpha_weight, sky_bg)
        if reg is not None:
            losses["extra_appearance_reg"] = reg
        depth = self._depth_loss(outputs, int(batch["image_idx"])) if self.training and "image_idx" in batch else None
        if depth is not None:
            losses["depth_loss"] = depth
        if c.strategy_type == "mcmc":
            g = self.gauss
            losses["opacity_reg"] = c.mcmc.opacity_reg * torch.sigmoid(g["opacities"]).abs().mean()
            losses["scale_reg"] = c.mcmc.scale_reg * torch.exp(g["scales"]).abs().mean()
        return losses

    # ------------------------------------------------------------------ training callbacks
    def get_training_callbacks(self, attrs: TrainingCallbackAttributes) -> list[TrainingCallback]:
        optimizers = attrs.optimizers
        self.name_training_views(attrs)

        def set_step(step: int) -> None:
            self.step.fill_(step)

        def densify_info() -> Optional[dict[str, Any]]:
            """The rasterizer's meta of this batch, or None when its statistics must not count."""
            info, self._meta = self._meta, None
            return None if self._extra_batch and not self.config.densify_from_extra_views else info

        def after_step(step: int) -> None:
            self.strategy.step_post_backward(self.gauss, optimizers, step, densify_info())

        def after_batch(step: int) -> None:  # a batch of several in this step: its statistics only
            info = densify_info()
            if info is not None:
                self.strategy.accumulate(self.gauss, step, info)

        return [TrainingCallback([Loc.BEFORE_STEP], set_step), TrainingCallback([Loc.AFTER_STEP], after_step),
                TrainingCallback([Loc.AFTER_BATCH], after_batch)]

    # ------------------------------------------------------------------ bookkeeping
    def training_state(self) -> dict[str, Tensor]:
        return self.strategy.state_dict()

    def load_training_state(self, state: dict[str, Tensor]) -> None:
        self.strategy.load_state_dict(state)

    def num_primitives(self) -> int:
        return int(self.gauss["means"].shape[0])

    def load_model_state(self, state: dict[str, Tensor]) -> None:
        """Resize the Gaussian parameters to the checkpoint's count (and take its additional views'
        colour transforms, if it trained any), then load."""
        saved_app = state.get("extra_appearance.transforms")
        if saved_app is not None:
            self.extra_appearance = AppearanceTransforms(saved_app.shape[0]).to(self.device)
        for name in list(self.gauss.keys()):
            saved = state.get(f"gauss.{name}")
            if saved is not None and saved.shape != self.gauss[name].shape:
                self.gauss[name] = nn.Parameter(torch.zeros(saved.shape, dtype=saved.dtype, device=self.gauss[name].device))
        self.load_state_dict(state)
        self._setup_strategy()

    def export_gaussians(self) -> dict[str, Tensor]:
        """The standard 3DGS quantities for :func:`write_gaussian_ply`."""
        g = {k: v.detach() for k, v in self.gauss.items()}
        return {
            "means": g["means"], "log_scales": g["scales"], "quats": normalize_quats(g["quats"]),
            "opacity_logits": g["opacities"], "features_dc": g["features_dc"], "features_rest": g["features_rest"],
        }
