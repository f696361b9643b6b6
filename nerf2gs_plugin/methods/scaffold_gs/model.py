"""Scaffold-GS (Lu et al., CVPR 2024): anchor-based neural Gaussians.

Anchors sit on a voxel grid built from the sparse points. Each anchor ``i`` has a feature
``f_i [F]``, a scaling ``l_i [6]`` (log; 3 for the offsets, 3 for the spawned scales) and ``k``
learnable offsets ``O_i [k,3]``. For a view, the anchors inside the frustum spawn ``k`` neural
Gaussians whose opacity, colour (optionally with a per-image appearance code) and covariance come
from small MLPs conditioned on the feature and the view direction; only those with opacity > 0
are rasterized. Anchors grow where the neural Gaussians' screen-space gradients are large (at
several voxel levels) and are pruned when their accumulated opacity is low (:mod:`.anchors`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.engine.callbacks import TrainingCallback, TrainingCallbackAttributes, TrainingCallbackLocation as Loc
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse
from nerf2gs_plugin.engine.model import Model
from nerf2gs_plugin.methods.gaussian_utils import knn_mean_distance
from nerf2gs_plugin.utils.quaternions import normalize_quats
from nerf2gs_plugin.utils.sh import rgb_to_sh
from nerf2gs_plugin.methods.scaffold_gs.anchors import AnchorStats, AnchorStrategy, voxelize
from nerf2gs_plugin.methods.splatfacto.shared import Background, SplatModelConfig, composite, image_loss
from nerf2gs_plugin.utils.schedule import scheduled


@dataclass
class ScaffoldGSModelConfig(SplatModelConfig):
    """The shared splatting settings (initial points, loss, background, rasterizer) come from
    :class:`SplatModelConfig`; the rest are Scaffold-GS's own."""

    _target: type = field(default_factory=lambda: ScaffoldGSModel)
    feat_dim: int = 32
    """Length of each anchor's feature vector."""
    n_offsets: int = 10
    """Neural Gaussians spawned per anchor."""
    voxel_size: float = 0.0
    """Anchor voxel size in normalised units; 0 = the median nearest-neighbour distance of the points."""
    appearance_dim: int = 0
    """Per-training-image appearance code fed to the colour MLP (0 = off)."""
    hidden_dim: int = 32
    """Width of the opacity, covariance and colour MLPs."""
    volume_reg: float = 0.01
    """Weight of the volume (scale product) regulariser of the neural Gaussians."""
    frustum_margin: float = 0.15
    """Anchors projecting this fraction of the image outside the frame still spawn Gaussians."""
    # ---- anchor growing / pruning (Scaffold-GS names; CPU-scale values, paper values in config.py)
    start_stat: int = scheduled(50)
    """Step from which the growing statistics are gathered."""
    update_from: int = scheduled(150)
    """First anchor growing / pruning step."""
    update_interval: int = scheduled(100, "interval")
    """Grow and prune anchors every this many steps."""
    update_until: int = scheduled(1500)
    """Last anchor growing / pruning step."""
    grow_threshold: float = 0.0002
    """Mean screen-space gradient of a neural Gaussian above which an anchor grows there."""
    update_depth: int = 3
    """Voxel levels at which anchors grow (each finer by update-hierarchy-factor)."""
    update_init_factor: int = 16
    """Voxel size of the coarsest growing level, in anchor voxels."""
    update_hierarchy_factor: int = 4
    """Ratio of voxel sizes between growing levels."""
    success_threshold: float = 0.8
    """An anchor is grown from or pruned once seen in this fraction of update-interval steps."""
    min_opacity: float = 0.005
    """Prune anchors whose neural Gaussians' mean opacity is below this."""
    max_anchors: int = 20000
    """Soft budget on anchors for a CPU (0 = unlimited)."""
    pixel_steps_per_anchor: float = 540000.0
    """0 = off. Else the anchors' soft budget is the pixel count of the training views (real and extra, at
    training resolution) x the growing steps (update-until - update-from) over this, the larger of this and the
    growth budget below, at most max-anchors. An anchor spawns n-offsets (10) neural Gaussians: 540,000 is
    Splatfacto's 54,000 pixel-steps per Gaussian for each of them. On the synthetic streets it binds only with
    NeRF views at the default scale (their views from above double the pixels, and the growth budget alone
    stopped below the uncapped best: benchmarks/results/prune_margin/)."""
    anchor_growth: float = 1.25
    """0 = off (both off: the fixed max-anchors). Else the anchors' soft budget is this many times the initial
    anchors (the voxelised sparse points: what the capture's structure gave), the larger of this and the pixel
    budget above when both are on, at most max-anchors. Scaffold-GS's neural Gaussians carry the detail: more
    growth bought little for over twice the anchors on two synthetic streets (benchmarks/results/views_budget/)."""


class ScaffoldGSModel(Model):
    config: ScaffoldGSModelConfig
    primitive_kind = "anchors"

    def populate_modules(self, train_data: DataparserOutputs) -> None:
        c = self.config
        gen = torch.Generator().manual_seed(0)
        if train_data.points3D_xyz is not None and len(train_data.points3D_xyz) > 0:
            pts = train_data.points3D_xyz.float()
        else:
            from nerf2gs_plugin.warn import warn

            warn("no sparse points", f"placing anchors on {c.num_random} random points in the scene box", stacklevel=3)
            lo, hi = self.scene_box[0], self.scene_box[1]
            pts = lo + (hi - lo) * torch.rand(c.num_random, 3, generator=gen)
        voxel = c.voxel_size if c.voxel_size > 0 else float(knn_mean_distance(pts, k=1).median().clamp_min(1e-4))
        self.register_buffer("voxel", torch.tensor(voxel))
        anchors = voxelize(pts, voxel)
        self._initial_anchors = anchors.shape[0]  # the budget's content term (rebuilt from the data on a reload)
        m, k = anchors.shape[0], c.n_offsets
        dist = knn_mean_distance(anchors).clamp_min(1e-4)
        self.anchor = nn.ParameterDict({
            "anchors": nn.Parameter(anchors, requires_grad=False),  # fixed positions, as Scaffold-GS
            "anchor_feat": nn.Parameter(torch.zeros(m, c.feat_dim)),
            "offsets": nn.Parameter(torch.zeros(m, k, 3)),
            "scaling": nn.Parameter(torch.log(dist)[:, None].repeat(1, 6)),
        })
        inp = c.feat_dim + 3
        h = c.hidden_dim
        self.mlp_opacity = nn.Sequential(nn.Linear(inp, h), nn.ReLU(True), nn.Linear(h, k), nn.Tanh())
        self.mlp_cov = nn.Sequential(nn.Linear(inp, h), nn.ReLU(True), nn.Linear(h, 7 * k))
        self.mlp_color = nn.Sequential(nn.Linear(inp + c.appearance_dim, h), nn.ReLU(True), nn.Linear(h, 3 * k), nn.Sigmoid())
        self.appearance = nn.Embedding(max(self.num_train_images, 1), c.appearance_dim) if c.appearance_dim > 0 else None
        self.register_buffer("train_c2w", train_data.cameras.camera_to_worlds.clone(), persistent=False)
        self.background = Background(c.background, c.sky_sh_degree)
        self.register_buffer("step", torch.zeros((), dtype=torch.long))
        self.strategy = self._make_strategy()
        self._last: Optional[dict[str, Any]] = None

    @torch.no_grad()
    def add_initial_points(self, xyz: Tensor, rgb: Tensor) -> int:
        """New anchors on the voxels of ``xyz`` that hold none yet, made as the sparse points' anchors are
        (zero feature and offsets, kNN scaling among all); before training only. ``rgb`` is unused: an
        anchor's colours come from its feature. The growth budget stays the sparse points' (as Splatfacto's)."""
        if len(xyz) == 0:
            return 0
        a = self.anchor
        old = a["anchors"].detach()
        voxel = float(self.voxel)
        cells = torch.unique(torch.round(xyz.to(old.device, torch.float32) / voxel).long(), dim=0)
        taken = torch.round(old / voxel).long()
        new = cells[~(cells[:, None] == taken[None]).all(-1).any(1)] if len(taken) else cells
        n = len(new)
        if n == 0:
            return 0
        anchors = new.float() * voxel
        dist = knn_mean_distance(torch.cat([old, anchors])).clamp_min(1e-4)[-n:]
        rows = {"anchors": anchors, "anchor_feat": torch.zeros(n, a["anchor_feat"].shape[1], device=old.device),
                "offsets": torch.zeros(n, *a["offsets"].shape[1:], device=old.device),
                "scaling": torch.log(dist)[:, None].repeat(1, a["scaling"].shape[1])}
        for name, extra in rows.items():
            a[name] = nn.Parameter(torch.cat([a[name].detach(), extra.to(a[name].dtype)]), requires_grad=a[name].requires_grad)
        self.strategy = self._make_strategy()
        return n

    def _make_strategy(self) -> AnchorStrategy:
        strategy = AnchorStrategy(self.config, float(self.voxel))  # the buffer's (float32) value, as after a reload
        strategy.budget.pixels_fn = self.training_pixels
        strategy.budget.points = self._initial_anchors
        return strategy

    def get_param_groups(self) -> dict[str, list[nn.Parameter]]:
        groups = {name: [p] for name, p in self.anchor.items()}
        groups.update({
            "mlp_opacity": list(self.mlp_opacity.parameters()),
            "mlp_cov": list(self.mlp_cov.parameters()),
            "mlp_color": list(self.mlp_color.parameters()),
            "background": list(self.background.parameters()),
        })
        if self.appearance is not None:
            groups["appearance"] = list(self.appearance.parameters())
        return groups

    # ------------------------------------------------------------------ neural Gaussians
    def visible_anchors(self, camera: Cameras) -> Tensor:
        """Indices of the anchors in (a margin around) the camera frustum ``[Mv]``."""
        a = self.anchor["anchors"]
        w2c = camera.viewmats()[0]
        p = a @ w2c[:3, :3].T + w2c[:3, 3]
        z = p[:, 2]
        K = camera.Ks()[0]
        zc = z.clamp_min(1e-6)
        u, v = K[0, 0] * p[:, 0] / zc + K[0, 2], K[1, 1] * p[:, 1] / zc + K[1, 2]
        w, h = float(camera.width[0]), float(camera.height[0])
        mu, mv = self.config.frustum_margin * w, self.config.frustum_margin * h
        ok = (z > self.config.near_plane) & (u > -mu) & (u < w + mu) & (v > -mv) & (v < h + mv)
        return ok.nonzero().squeeze(1)

    def decode(self, idx: Tensor, cam_center: Tensor, app: Optional[Tensor] = None) -> dict[str, Tensor]:
        """Spawn the neural Gaussians of anchors ``idx`` seen from ``cam_center`` (``[3]`` or ``[Mv,3]``).

        Returns flat ``[Mv*k]`` tensors: means [.,3], scales [.,3] (linear), quats [.,4],
        opacity [.] (tanh, may be <= 0), colors [.,3]."""
        k = self.config.n_offsets
        a = self.anchor
        anchors, feat, scaling = a["anchors"][idx], a["anchor_feat"][idx], torch.exp(a["scaling"][idx])
        ob = anchors - cam_center
        dist = ob.norm(dim=-1, keepdim=True).clamp_min(1e-8)
        x = torch.cat([feat, ob / dist], dim=-1)  # [Mv, F+3]
        opacity = self.mlp_opacity(x).reshape(-1)
        xc = x if app is None else torch.cat([x, app.expand(x.shape[0], -1)], dim=-1)
        colors = self.mlp_color(xc).reshape(-1, 3)
        sr = self.mlp_cov(x).reshape(-1, 7)
        rep = scaling.repeat_interleave(k, dim=0)  # [Mv*k, 6]
        means = (a["offsets"][idx] * scaling[:, None, :3]).reshape(-1, 3) + anchors.repeat_interleave(k, dim=0)
        scales = rep[:, 3:] * torch.sigmoid(sr[:, :3])
        quats = normalize_quats(sr[:, 3:7])
        return {"means": means, "scales": scales, "quats": quats, "opacity": opacity, "colors": colors}

    def _appearance(self, camera: Cameras, image_idx: Optional[int]) -> Optional[Tensor]:
        if self.appearance is None:
            return None
        if image_idx is not None and 0 <= image_idx < self.num_train_images:
            return self.appearance.weight[image_idx][None]
        return self.appearance.weight.mean(0, keepdim=True)  # unseen views: the average code

    def _render(self, camera: Cameras, training: bool, image_idx: Optional[int] = None) -> dict[str, Tensor]:
        from nerf2gs_plugin.rendering import rasterize_gaussians

        dev = self.anchor["anchors"].device
        camera = camera.to(dev)
        h, w = int(camera.height[0]), int(camera.width[0])
        bg = self.background(camera, training)
        idx = self.visible_anchors(camera)
        center = camera.centers[0]
        neural = self.decode(idx, center, self._appearance(camera, image_idx)) if idx.numel() else None
        keep = neural["opacity"] > 0 if neural is not None else None
        if neural is None or not bool(keep.any()):
            zeros = torch.zeros(h, w, 1, device=dev)
            self._last = None
            return {"rgb": (zeros + bg).expand(h, w, 3), "depth": zeros, "accumulation": zeros,
                    "scales": torch.zeros(0, 3, device=dev), "background": bg}
        sel = {name: v[keep] for name, v in neural.items()}
        render, alpha, meta = rasterize_gaussians(
            sel["means"], sel["quats"], sel["scales"], sel["opacity"], sel["colors"], camera.viewmats(), camera.Ks(), w, h,
            near_plane=self.config.near_plane, far_plane=self.config.far_plane, render_mode="RGB+ED",
            rasterize_mode=self.config.rasterize_mode, backend=self.config.backend,
        )
        if training and meta["means2d"].requires_grad:
            self.strategy.step_pre_backward(self.anchor, None, int(self.step), meta)
            self._last = {"meta": meta, "anchor_idx": idx, "keep": keep, "opacity": neural["opacity"].detach()}
        else:
            self._last = None
        alpha = alpha[0]
        rgb = composite(render[0, ..., :3], alpha, bg).clamp(0.0, 1.0)
        return {"rgb": rgb, "depth": render[0, ..., 3:4], "accumulation": alpha, "scales": sel["scales"], "background": bg}

    def get_outputs(self, inputs: Cameras) -> dict[str, Tensor]:
        return self._render(inputs, training=self.training, image_idx=self._image_index(inputs))

    def _image_index(self, camera: Cameras) -> Optional[int]:
        """Which training image a camera is (for its appearance code): the pose that matches exactly."""
        if self.appearance is None:
            return None
        c2w = camera.camera_to_worlds[0].to(self.train_c2w)
        err = (self.train_c2w - c2w).abs().flatten(1).amax(1)
        i = int(err.argmin())
        return i if float(err[i]) < 1e-6 else None

    @torch.no_grad()
    def render_camera(self, camera: Cameras) -> dict[str, Tensor]:
        out = self._render(camera, training=False)
        return {k: out[k] for k in ("rgb", "depth", "accumulation")}

    # ------------------------------------------------------------------ losses
    def get_metrics_dict(self, outputs: dict[str, Tensor], batch: dict[str, Any]) -> dict[str, Tensor]:
        mse = ((outputs["rgb"].detach() - batch["image"].to(outputs["rgb"])) ** 2).mean()
        return {"psnr": psnr_from_mse(mse), "anchor_count": torch.tensor(float(self.num_primitives()))}

    def get_loss_dict(self, outputs: dict[str, Tensor], batch: dict[str, Any], metrics_dict: dict[str, Tensor]) -> dict[str, Tensor]:
        c = self.config
        sky_bg = outputs.get("background") if c.background == "random" else None
        losses = image_loss(outputs, batch, c.ssim_lambda, c.mask_transients, c.sky_alpha_weight, sky_bg)
        if c.volume_reg > 0 and outputs["scales"].shape[0]:
            weight = torch.as_tensor(batch.get("weight", 1.0), dtype=outputs["rgb"].dtype, device=outputs["rgb"].device)
            losses["volume_reg"] = weight * c.volume_reg * outputs["scales"].prod(dim=1).mean()
        return losses

    # ------------------------------------------------------------------ growing / pruning
    def get_training_callbacks(self, attrs: TrainingCallbackAttributes) -> list[TrainingCallback]:
        optimizers = attrs.optimizers

        self.name_training_views(attrs)

        def before(step: int) -> None:
            self.step.fill_(step)

        def after_step(step: int) -> None:
            info, self._last = self._last, None
            self.strategy.step_post_backward(self.anchor, optimizers, step, info)

        def after_batch(step: int) -> None:  # a batch of several in this step: its statistics only
            info, self._last = self._last, None
            if info is not None:
                self.strategy.accumulate(self.anchor, step, info)

        return [TrainingCallback([Loc.BEFORE_STEP], before), TrainingCallback([Loc.AFTER_STEP], after_step),
                TrainingCallback([Loc.AFTER_BATCH], after_batch)]

    @property
    def stats(self) -> AnchorStats:
        """The anchor statistics (held by the strategy)."""
        return self.strategy.stats

    # ------------------------------------------------------------------ bookkeeping
    def training_state(self) -> dict[str, Tensor]:
        return self.strategy.state_dict()

    def load_training_state(self, state: dict[str, Tensor]) -> None:
        self.strategy.load_state_dict(state)

    def num_primitives(self) -> int:
        return int(self.anchor["anchors"].shape[0])

    def load_model_state(self, state: dict[str, Tensor]) -> None:
        for name in list(self.anchor.keys()):
            saved = state.get(f"anchor.{name}")
            if saved is not None and saved.shape != self.anchor[name].shape:
                old = self.anchor[name]
                self.anchor[name] = nn.Parameter(torch.zeros(saved.shape, dtype=saved.dtype, device=old.device), requires_grad=old.requires_grad)
        self.load_state_dict(state)
        self.strategy = self._make_strategy()

    export_needs_cameras = True

    @torch.no_grad()
    def export_gaussians(self, cameras: Optional[Cameras] = None, view: int = 0) -> dict[str, Tensor]:
        """Neural Gaussians as 3DGS quantities, decoded for training view ``view`` (its frustum),
        or for ``view = -1`` from every anchor with its view direction averaged over the cameras."""
        dev = self.anchor["anchors"].device
        if cameras is None or len(cameras) == 0:
            raise ValueError("Scaffold-GS export needs the training cameras")
        cameras = cameras.to(dev)
        if view >= 0:
            cam = cameras[min(view, len(cameras) - 1)]
            idx = self.visible_anchors(cam)
            center = cam.centers[0]
            neural = self.decode(idx, center, self._appearance(cam, view))
        else:
            idx = torch.arange(self.num_primitives(), device=dev)
            dirs = torch.nn.functional.normalize(self.anchor["anchors"][:, None] - cameras.centers[None], dim=-1).mean(1)
            dist = (self.anchor["anchors"][:, None] - cameras.centers[None]).norm(dim=-1).mean(1, keepdim=True)
            pseudo_center = self.anchor["anchors"] - torch.nn.functional.normalize(dirs, dim=-1) * dist
            neural = self.decode(idx, pseudo_center, self._appearance(cameras[0], None))
        keep = neural["opacity"] > 0
        op = neural["opacity"][keep].clamp(1e-6, 1 - 1e-6)
        n = int(keep.sum())
        return {
            "means": neural["means"][keep], "log_scales": torch.log(neural["scales"][keep].clamp_min(1e-12)),
            "quats": neural["quats"][keep], "opacity_logits": torch.log(op / (1 - op)),
            "features_dc": rgb_to_sh(neural["colors"][keep]), "features_rest": torch.zeros(n, 0, 3, device=dev),
        }
