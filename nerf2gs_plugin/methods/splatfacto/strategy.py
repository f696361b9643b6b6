"""Densification strategies shared by Splatfacto and 2DGS (the :class:`Strategy` contract of
:mod:`nerf2gs_plugin.methods.strategy_base`).

Both operate on an ``nn.ParameterDict`` whose tensors all have the primitive count ``N`` as their
first dimension, with keys ``means [N,3]``, ``scales [N,S]`` (log; S = 3 for 3D Gaussians, 2 for
surfels), ``quats [N,4]`` (wxyz) and ``opacities [N]`` (logit); every key is also the name of
its optimizer group, so :meth:`Optimizers.replace_param` keeps the Adam moments in step.

* :class:`DefaultStrategy` - the 3DGS/splatfacto recipe: accumulate the screen-space gradient of
  the projected means; clone small / split large Gaussians whose average gradient is high; prune
  by opacity and size; reset opacities periodically, pausing refinement after a reset for
  ``min(num_images, cap)`` steps (nerfstudio pauses for ``num_images`` steps, which silently stops
  refinement on large image sets). With ``prune_weight_fraction`` > 0 it also prunes once after
  densification by each Gaussian's blending weight over the training views (see
  :func:`light_mask`), so the model ends at what the views show rather than at a fixed budget.
* :class:`MCMCStrategy` - 3DGS as MCMC (Kheradmand et al. 2024): dead Gaussians are relocated
  onto live ones, new ones are added up to a hard budget ``cap_max``, and position noise scaled
  by the covariance explores the scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.methods.capture_path import CapturePath
from nerf2gs_plugin.methods.gaussian_utils import logit
from nerf2gs_plugin.methods.strategy_base import Strategy, SceneBudget
from nerf2gs_plugin.utils.quaternions import quat_to_rotmat
from nerf2gs_plugin.utils.schedule import scheduled


# ---------------------------------------------------------------------------------------- edits
def _set(params: nn.ParameterDict, optimizers: Any, name: str, value: Tensor, keep: Optional[Tensor], n_new: int) -> None:
    new = nn.Parameter(value.detach().contiguous(), requires_grad=params[name].requires_grad)
    params[name] = new
    if optimizers is not None and name in optimizers:
        optimizers.replace_param(name, new, keep=keep, n_new=n_new)


def append_rows(params: nn.ParameterDict, optimizers: Any, new_rows: dict[str, Tensor], keep: Optional[Tensor] = None) -> None:
    """Keep the rows ``keep`` (bool mask or index; all when None) and append ``new_rows``."""
    for name in list(params.keys()):
        old = params[name].detach()
        kept = old if keep is None else old[keep]
        add = new_rows[name].to(old)
        _set(params, optimizers, name, torch.cat([kept, add]), keep, add.shape[0])


def keep_rows(params: nn.ParameterDict, optimizers: Any, keep: Tensor) -> None:
    for name in list(params.keys()):
        _set(params, optimizers, name, params[name].detach()[keep], keep, 0)


def zero_state_rows(params: nn.ParameterDict, optimizers: Any, rows: Tensor, names: Optional[list[str]] = None) -> None:
    """Zero the Adam moments of ``rows`` (after relocating or resetting primitives)."""
    if optimizers is None:
        return
    for name in names or list(params.keys()):
        if name not in optimizers:
            continue
        state = optimizers[name].state.get(params[name])
        if state:
            for key in ("exp_avg", "exp_avg_sq"):
                if key in state:
                    state[key][rows] = 0


def _scales3(log_scales: Tensor) -> Tensor:
    """Linear 3-axis scales; surfels (2 axes) get a zero normal axis."""
    s = torch.exp(log_scales)
    if s.shape[1] == 2:
        s = torch.cat([s, torch.zeros_like(s[:, :1])], dim=1)
    return s


# ---------------------------------------------------------------------------------------- default
@dataclass
class DefaultStrategyConfig:
    """nerfstudio's names and (30k-step) values, stated here only: the paper-scale configs use these
    defaults as they are; the model config sets the CPU-scale ones."""

    warmup_length: int = scheduled(500)
    """No densification before this step."""
    refine_every: int = scheduled(100, "interval")
    """Densify and prune every this many steps."""
    reset_alpha_every: int = scheduled(3000)
    """Reset opacities every this many steps (0 = never)."""
    stop_split_at: int = scheduled(15000)
    """No densification after this step."""
    densify_grad_thresh: float = 0.0008
    """Screen-space gradient above which a Gaussian is cloned or split."""
    densify_size_thresh: float = 0.01
    """Gaussians larger than this (scene units) are split, smaller are cloned."""
    n_split_samples: int = 2
    """Gaussians a split Gaussian becomes."""
    cull_alpha_thresh: float = 0.1
    """Prune Gaussians with opacity below this."""
    cull_scale_thresh: float = 0.5
    """Prune Gaussians larger than this (scene units)."""
    cull_screen_size: float = 0.15
    """Prune Gaussians whose screen radius exceeds this fraction of the image size."""
    split_screen_size: float = 0.05
    """Split Gaussians whose screen radius exceeds this fraction of the image size."""
    stop_screen_size_at: int = scheduled(4000)
    """No screen-size culling or splitting after this step."""
    continue_cull_post_densification: bool = True
    """Keep pruning after the last densification step."""
    max_pause_after_reset: int = scheduled(1000)
    """Cap on nerfstudio's pause after an opacity reset (num_images + refine_every steps)."""
    max_gaussians: int = 0
    """Soft budget of Gaussians (0 = unlimited, as nerfstudio)."""
    pixel_steps_per_gaussian: float = 0.0
    """0 = off (nerfstudio). Else the soft budget is the pixel count of the training views (every real and
    extra view at its training resolution) times the densification window (stop-split-at - warmup-length
    steps) over this (the smaller of the two when max-gaussians is set too): a capture with more or larger
    views, or a longer densification, makes room for more Gaussians, a constant does not."""
    gaussians_per_sparse_point: float = 0.0
    """0 = off. Else the soft budget is at least this many Gaussians per sparse (SfM) point of the capture
    (the larger of this and the pixel budget above, at most max-gaussians): what the views show, not only
    how many pixels they have: a real courtyard's photos give several times the points of a synthetic
    street's views of the same pixel count, and need more Gaussians per pixel."""
    prune_weight_fraction: float = 0.0
    """0 = off (nerfstudio). Else, at the first refinement at or after stop-split-at, render every
    training view once and prune the Gaussians that together carry this fraction of the total
    blending weight (alpha x transmittance summed over all training pixels), lightest first
    (LightGaussian / Taming-3DGS significance): the count left follows the scene and its views."""
    prune_margin_db: float = 0.0
    """0 = off: the weight prune drops exactly prune-weight-fraction. Else it drops the largest of
    prune-weight-fraction x (1, 3/4, 1/2, 3/8, 1/4, 1/8) whose change to the training views' renders stays
    this many dB below the model's own error on them (PSNR of the pruned renders against the unpruned ones
    >= PSNR of the unpruned renders against the images + this; sky and transient pixels left out), nothing
    when none does. A model still far from its images loses little by the prune, one that fits them
    closely (a longer training) keeps the light Gaussians that draw what is left: a margin of m dB lets the
    prune lower the training PSNR by at most 10 log10(1 + 10^(-m/10)) dB (1.8 dB at 3) before training goes on."""
    path_clearance_m: float = 0.0
    """0 = off (nerfstudio). Else every prune also drops the Gaussians whose centre lies within this
    many metres of the capture path (the training cameras joined in order, see
    :mod:`nerf2gs_plugin.methods.capture_path`): space the car or walker occupied, where only floaters sit."""


class DefaultStrategy(Strategy):
    """Clone / split / prune / opacity-reset; statistics come from ``info[grad_key].grad``."""

    grad_key = "means2d"
    reduced_stats = {"grad_accum": "sum", "count": "sum", "max_radii": "max"}

    def __init__(self, cfg: DefaultStrategyConfig, num_train_images: int = 1, scene_scale: float = 1.0) -> None:
        self.cfg = cfg
        self.num_train_images = num_train_images  # of the dataset, not a setting: not in the config
        self.scene_scale = scene_scale
        self.weights_fn: Optional[Callable[[], Optional[Tensor]]] = None
        """Set by the model: each primitive's blending weight summed over the training pixels ``[N]``
        (None when it has no training views to render); read by the weight prune only."""
        self.fidelity_fn: Optional[Callable[[Tensor], Optional[tuple[float, float]]]] = None
        """Set by the model: ``(change, error)`` in dB over the training views: PSNR of their renders without
        the primitives of a bool mask ``[N]`` against those with all, and of those with all against the images
        (None without training views); read by the weight prune when ``prune_margin_db`` > 0."""
        self.weight_prunes: list[dict[str, float]] = []
        """What each weight prune did: ``fraction`` of the weight dropped, ``change_db`` and ``error_db`` (nan
        unmeasured) and ``pruned`` primitives (for inspection and the tests)."""
        self.budget = SceneBudget(cfg.pixel_steps_per_gaussian, cfg.stop_split_at - cfg.warmup_length, cfg.max_gaussians,
                                  cfg.gaussians_per_sparse_point)
        """The soft budget in force (``budget.value``): max-gaussians, or read from the views and the sparse
        points (the model sets its ``pixels_fn`` and ``points``)."""
        self.path: Optional[CapturePath] = None
        self.path_radius = 0.0
        """Set by the model (:meth:`clear_path`): the capture path and its clearance in world units."""
        self.initialize_state()

    def initialize_state(self) -> None:
        self.grad_accum: Optional[Tensor] = None  # [N] sum of NDC-space gradient norms
        self.count: Optional[Tensor] = None  # [N] times visible
        self.max_radii: Optional[Tensor] = None  # [N] max radius / max(W, H)

    def step_post_backward(self, params: nn.ParameterDict, optimizers: Any, step: int,
                           info: Optional[dict[str, Any]]) -> dict[str, int]:
        if info is not None:
            self.update_stats(params["means"].shape[0], info)
        return self.refine(step, params, optimizers)

    def accumulate(self, params: nn.ParameterDict, step: int, info: dict[str, Any]) -> None:
        self.update_stats(params["means"].shape[0], info)

    @property
    def pause_after_reset(self) -> int:
        """Steps without refinement after an opacity reset: nerfstudio's ``num_images + refine_every``,
        capped so that it stays below the reset interval whatever the image count."""
        c = self.cfg
        pause = min(self.num_train_images, c.max_pause_after_reset) + c.refine_every
        return min(pause, max(c.reset_alpha_every // 2, 0))

    def clear_path(self, path: Optional[CapturePath], metre: float) -> None:
        """Keep ``cfg.path_clearance_m`` metres (``metre`` world units each) around ``path`` free."""
        self.path, self.path_radius = path, self.cfg.path_clearance_m * metre

    def _reset_stats(self, n: int, device: torch.device) -> None:
        self.grad_accum = torch.zeros(n, device=device)
        self.count = torch.zeros(n, device=device)
        self.max_radii = torch.zeros(n, device=device)

    @torch.no_grad()
    def update_stats(self, n: int, meta: dict[str, Any]) -> None:
        """After backward: accumulate the projected-mean gradient of the visible primitives."""
        means2d = self.grad_tensor(meta)
        if means2d is None or means2d.grad is None:
            return
        if self.grad_accum is None or self.grad_accum.shape[0] != n:
            self._reset_stats(n, means2d.device)
        w, h = float(meta["width"]), float(meta["height"])
        g = means2d.grad.detach().clone()  # [C, N, 2] pixels -> NDC units (as gsplat)
        g[..., 0] *= w / 2.0
        g[..., 1] *= h / 2.0
        radii = meta["radii"]
        if radii.ndim == 3:  # [C, N, 2] per-axis radii
            radii = radii.amax(-1)
        vis = radii > 0  # [C, N]
        norms = g.norm(dim=-1)
        self.grad_accum += (norms * vis).sum(0)
        self.count += vis.sum(0).float()
        self.max_radii = torch.maximum(self.max_radii, (radii.float() / max(w, h)).amax(0))

    def _in_pause(self, step: int) -> bool:
        c = self.cfg
        return c.reset_alpha_every > 0 and step >= c.reset_alpha_every and step % c.reset_alpha_every < self.pause_after_reset

    @torch.no_grad()
    def refine(self, step: int, params: nn.ParameterDict, optimizers: Any) -> dict[str, int]:
        """After the optimizer step: grow/prune on refinement steps, reset opacities. Returns counts."""
        c = self.cfg
        out = {"cloned": 0, "split": 0, "pruned": 0}
        if step < c.warmup_length or step % c.refine_every != 0 or step == 0:
            return out
        with self.all_ranks(params["means"].device):
            if step < c.stop_split_at:
                if not self._in_pause(step) and self.count is not None and self.count.shape[0] == params["means"].shape[0]:
                    out.update(self.grow(step, params, optimizers))
                    out["pruned"] = self.prune(step, params, optimizers)
                if c.reset_alpha_every > 0 and step % c.reset_alpha_every == 0:
                    self.reset_opacities(params, optimizers)
            elif c.continue_cull_post_densification:
                out["pruned"] = self.prune(step, params, optimizers)
            if c.prune_weight_fraction > 0 and c.stop_split_at <= step < c.stop_split_at + c.refine_every:
                out["pruned"] += self.prune_by_weight(params, optimizers)
            self._reset_stats(params["means"].shape[0], params["means"].device)
        return out

    def grow(self, step: int, params: nn.ParameterDict, optimizers: Any) -> dict[str, int]:
        c = self.cfg
        n = params["means"].shape[0]
        avg = self.grad_accum / self.count.clamp_min(1)
        high = (avg > c.densify_grad_thresh) & (self.count > 0)
        max_scale = torch.exp(params["scales"]).amax(-1)
        small = max_scale <= c.densify_size_thresh * self.scene_scale
        clone = high & small
        split = high & ~small
        if step < c.stop_screen_size_at:
            split |= self.max_radii > c.split_screen_size
        budget = self.budget.value
        if budget > 0:  # soft budget: only the highest-gradient candidates, then nothing
            room = max(budget - n, 0)
            clone, split = _limit(clone, split, avg, room, c.n_split_samples)
        n_clone, n_split = int(clone.sum()), int(split.sum())
        if n_clone:
            append_rows(params, optimizers, {k: v.detach()[clone] for k, v in params.items()})
            split = torch.cat([split, torch.zeros(n_clone, dtype=torch.bool, device=split.device)])
        if n_split:
            append_rows(params, optimizers, self._split_rows(params, split), keep=~split)
        return {"cloned": n_clone, "split": n_split}

    def _split_rows(self, params: nn.ParameterDict, split: Tensor) -> dict[str, Tensor]:
        """Each selected Gaussian -> ``n_split_samples`` samples from itself, scales / 1.6."""
        k = self.cfg.n_split_samples
        rows = {name: v.detach()[split].repeat_interleave(k, dim=0) for name, v in params.items()}
        s3 = _scales3(rows["scales"])
        R = quat_to_rotmat(rows["quats"])
        offs = torch.einsum("nij,nj->ni", R, s3 * torch.randn_like(s3))
        rows["means"] = rows["means"] + offs
        rows["scales"] = rows["scales"] - math.log(1.6)
        return rows

    def prune(self, step: int, params: nn.ParameterDict, optimizers: Any) -> int:
        c = self.cfg
        cull = torch.sigmoid(params["opacities"]) < c.cull_alpha_thresh
        if c.reset_alpha_every > 0 and step > c.reset_alpha_every:
            cull |= torch.exp(params["scales"]).amax(-1) > c.cull_scale_thresh * self.scene_scale
            if step < c.stop_screen_size_at and self.max_radii is not None and self.max_radii.shape[0] == cull.shape[0]:
                cull |= self.max_radii > c.cull_screen_size
        if self.path is not None:
            cull |= self.path.near(params["means"].detach(), self.path_radius)
        if bool(cull.all()):  # never empty the scene
            cull[torch.sigmoid(params["opacities"]).argmax()] = False
        n = int(cull.sum())
        if n:
            keep_rows(params, optimizers, ~cull)
        return n

    def prune_by_weight(self, params: nn.ParameterDict, optimizers: Any) -> int:
        """Drop the lightest Gaussians carrying ``prune_weight_fraction`` of the training views'
        blending weight (:func:`light_mask`), or less under ``prune_margin_db``; nothing without
        :attr:`weights_fn` or its weights."""
        weights = self.weights_fn() if self.weights_fn is not None else None
        if weights is None or weights.shape[0] != params["means"].shape[0]:
            return 0
        cull, record = self._weight_cull(weights)
        if bool(cull.all()):  # never empty the scene
            cull[weights.argmax()] = False
        n = int(cull.sum())
        if n:
            keep_rows(params, optimizers, ~cull)
        self.weight_prunes.append({**record, "pruned": float(n)})
        return n

    def _weight_cull(self, weights: Tensor) -> tuple[Tensor, dict[str, float]]:
        """The prune mask ``[N]`` and what decided it (fraction, change and error measured)."""
        c = self.cfg
        unmeasured = {"fraction": c.prune_weight_fraction, "change_db": math.nan, "error_db": math.nan}
        if c.prune_margin_db <= 0 or self.fidelity_fn is None:
            return light_mask(weights, c.prune_weight_fraction), unmeasured
        record = {"fraction": 0.0, "change_db": math.nan, "error_db": math.nan}
        for ratio in PRUNE_MARGIN_RATIOS:
            fraction = c.prune_weight_fraction * ratio
            cull = light_mask(weights, fraction)
            if not bool(cull.any()):
                return cull, {**record, "fraction": fraction}
            measured = self.fidelity_fn(cull)
            if measured is None:  # no views to measure on: the fraction as configured
                return light_mask(weights, c.prune_weight_fraction), unmeasured
            record = {"fraction": fraction, "change_db": measured[0], "error_db": measured[1]}
            if measured[0] >= measured[1] + c.prune_margin_db:
                return cull, record
        return torch.zeros_like(weights, dtype=torch.bool), {**record, "fraction": 0.0}

    def reset_opacities(self, params: nn.ParameterDict, optimizers: Any) -> None:
        """Clamp opacities to ``2 * cull_alpha_thresh`` and clear their Adam moments."""
        cap = float(logit(min(self.cfg.cull_alpha_thresh * 2.0, 0.99)))
        params["opacities"].data.clamp_(max=cap)
        zero_state_rows(params, optimizers, slice(None), ["opacities"])


PRUNE_MARGIN_RATIOS = (1.0, 0.75, 0.5, 0.375, 0.25, 0.125)
"""The weight prune's fractions tried under ``prune_margin_db``, largest first (x prune-weight-fraction)."""


def light_mask(weights: Tensor, fraction: float) -> Tensor:
    """``[N]`` bool: the primitives that together carry at most ``fraction`` of the summed ``weights``,
    lightest first (unseen ones, weight 0, always). How many that is depends on how the weight is
    spread: a scene whose views rest on few primitives loses many, one that needs them all few."""
    order = torch.argsort(weights, stable=True)
    cum = torch.cumsum(weights[order].double(), 0)
    light = torch.zeros(weights.shape[0], dtype=torch.bool, device=weights.device)
    if cum.numel():
        light[order[cum <= fraction * cum[-1]]] = True
    return light


def _limit(clone: Tensor, split: Tensor, score: Tensor, room: int, k: int) -> tuple[Tensor, Tensor]:
    """Keep the highest-score candidates whose growth (1 per clone, k-1 per split) fits ``room``."""
    cand = clone | split
    cost = clone.float() + split.float() * max(k - 1, 1)
    if float(cost.sum()) <= room:
        return clone, split
    order = torch.argsort(torch.where(cand, score, torch.full_like(score, -1.0)), descending=True)
    fits = torch.cumsum(cost[order], 0) <= room
    chosen = torch.zeros_like(cand)
    chosen[order[fits]] = True
    return clone & chosen, split & chosen


# ---------------------------------------------------------------------------------------- MCMC
@dataclass
class MCMCStrategyConfig:
    """gsplat's MCMC recipe (30k-step values; the model config sets the CPU-scale ones)."""

    cap_max: int = 100_000
    """Hard budget of Gaussians."""
    noise_lr: float = 5e5
    """Scale of the position noise, times the means' learning rate."""
    refine_start_iter: int = scheduled(500)
    """First relocation / growth step."""
    refine_stop_iter: int = scheduled(25_000)
    """Last relocation / growth step."""
    refine_every: int = scheduled(100, "interval")
    """Densify and prune every this many steps."""
    min_opacity: float = 0.005
    """Gaussians below this opacity are relocated."""
    grow_factor: float = 0.05
    """Grow the count by this fraction per refinement, up to cap-max."""
    init_opacity: float = 0.5
    """Initial opacity (the model's; MCMC starts from opaque but small Gaussians)."""
    init_scale: float = 0.1
    """Initial scale as a fraction of the kNN distance (the model's)."""
    opacity_reg: float = 0.01
    """Weight of the mean-opacity loss (the model's)."""
    scale_reg: float = 0.01
    """Weight of the mean-scale loss (the model's)."""


_N_MAX = 51


def _binoms(device: torch.device) -> Tensor:
    b = torch.zeros(_N_MAX, _N_MAX)
    for n in range(_N_MAX):
        for k in range(n + 1):
            b[n, k] = math.comb(n, k)
    return b.to(device)


def relocation_values(opacities: Tensor, scales: Tensor, ratios: Tensor) -> tuple[Tensor, Tensor]:
    """Opacity and scale of a Gaussian split into ``ratios`` copies so that the sum of the
    copies renders like the original (3DGS-MCMC, Eq. 9). ``opacities [M]`` in (0,1),
    ``scales [M,S]`` linear, ``ratios [M]`` >= 1."""
    n = ratios.clamp(1, _N_MAX).long()
    new_o = 1.0 - (1.0 - opacities).clamp_min(1e-12) ** (1.0 / n.float())
    B = _binoms(opacities.device)  # [i-1, k]
    k = torch.arange(_N_MAX, device=opacities.device)
    coef = B * ((-1.0) ** k.float() / torch.sqrt(k.float() + 1))[None, :]  # [I, K]
    powers = new_o[:, None] ** (k[None, :] + 1).float()  # [M, K]
    per_i = powers @ coef.T  # [M, I]: sum over k for each i (B is zero for k > i-1)
    i_mask = (torch.arange(1, _N_MAX + 1, device=opacities.device)[None, :] <= n[:, None]).float()
    denom = (per_i * i_mask).sum(-1)
    new_s = (opacities / denom.clamp_min(1e-12))[:, None] * scales
    return new_o, new_s


class MCMCStrategy(Strategy):
    """Relocate / add / noise; reads no gradient statistics (its ``step_pre_backward`` keeps the
    projected centres' gradient only because every strategy does: it costs nothing)."""

    def __init__(self, cfg: MCMCStrategyConfig) -> None:
        self.cfg = cfg

    def initialize_state(self) -> None:
        """Nothing accumulates between steps."""

    def step_post_backward(self, params: nn.ParameterDict, optimizers: Any, step: int,
                           info: Optional[dict[str, Any]]) -> dict[str, int]:
        return self.refine(step, params, optimizers)

    @staticmethod
    def means_lr(optimizers: Any, step: int) -> float:
        """The means' learning rate at ``step`` (scales the exploration noise); nerfstudio's initial
        one when no ``means`` optimizer config is known."""
        configs = getattr(optimizers, "configs", {})
        return configs["means"].lr_at(step) if "means" in configs else 1.6e-4

    def _sample(self, probs: Tensor, n: int) -> Tensor:
        return torch.multinomial(probs / probs.sum(), n, replacement=True)

    def _relocate_to(self, params: nn.ParameterDict, sampled: Tensor) -> None:
        """Share the opacity/scale of each ``sampled`` source among its new copies."""
        ratios = torch.bincount(sampled, minlength=params["means"].shape[0])[sampled] + 1
        o = torch.sigmoid(params["opacities"].data[sampled])
        new_o, new_s = relocation_values(o, torch.exp(params["scales"].data[sampled]), ratios)
        new_o = new_o.clamp(self.cfg.min_opacity, 1 - 1e-6)
        params["opacities"].data[sampled] = torch.log(new_o / (1 - new_o))
        params["scales"].data[sampled] = torch.log(new_s.clamp_min(1e-12))

    @torch.no_grad()
    def relocate(self, params: nn.ParameterDict, optimizers: Any) -> int:
        op = torch.sigmoid(params["opacities"])
        dead = op <= self.cfg.min_opacity
        n_dead = int(dead.sum())
        if n_dead == 0 or n_dead == op.shape[0]:
            return 0
        alive_idx = (~dead).nonzero().squeeze(1)
        sampled = alive_idx[self._sample(op[alive_idx], n_dead)]
        self._relocate_to(params, sampled)
        dead_idx = dead.nonzero().squeeze(1)
        for name in params.keys():
            params[name].data[dead_idx] = params[name].data[sampled]
        zero_state_rows(params, optimizers, torch.cat([sampled, dead_idx]))
        return n_dead

    @torch.no_grad()
    def add(self, params: nn.ParameterDict, optimizers: Any) -> int:
        n = params["means"].shape[0]
        target = min(self.cfg.cap_max, int(math.ceil((1.0 + self.cfg.grow_factor) * n)))
        n_add = max(0, target - n)
        if n_add == 0:
            return 0
        op = torch.sigmoid(params["opacities"])
        sampled = self._sample(op.clamp_min(1e-12), n_add)
        self._relocate_to(params, sampled)
        zero_state_rows(params, optimizers, sampled)
        append_rows(params, optimizers, {k: v.detach()[sampled] for k, v in params.items()})
        return n_add

    @torch.no_grad()
    def inject_noise(self, params: nn.ParameterDict, lr_means: float) -> None:
        """Covariance-shaped position noise, strong for transparent Gaussians only."""
        op = torch.sigmoid(params["opacities"])
        s3 = _scales3(params["scales"]).clamp_min(1e-8)
        R = quat_to_rotmat(params["quats"])
        gate = torch.sigmoid(100.0 * ((1.0 - op) - 0.995))  # ~1 when opacity < 0.005
        z = torch.randn_like(params["means"]) * (gate * lr_means * self.cfg.noise_lr)[:, None]
        noise = torch.einsum("nij,nj->ni", R, (s3 * s3) * torch.einsum("nji,nj->ni", R, z))
        params["means"].data += noise

    def refine(self, step: int, params: nn.ParameterDict, optimizers: Any) -> dict[str, int]:
        c = self.cfg
        out = {"relocated": 0, "added": 0}
        if c.refine_start_iter < step < c.refine_stop_iter and step % c.refine_every == 0:
            with self.all_ranks(params["means"].device):  # the same relocation samples on every rank
                out["relocated"] = self.relocate(params, optimizers)
                out["added"] = self.add(params, optimizers)
        self.inject_noise(params, self.means_lr(optimizers, step))
        return out
