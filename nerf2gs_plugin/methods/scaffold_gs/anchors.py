"""Scaffold-GS anchors: voxelisation, training statistics, multi-level growing, pruning.

Statistics (as the original): per neural-Gaussian slot ``[M*k]`` the summed NDC gradient norm of
its projected mean and how often it was rasterized; per anchor ``[M]`` the summed (clamped)
neural opacity and how often the anchor was in the frustum. A slot takes part in growing once
it was seen more than ``update_interval * success_threshold / 2`` times; an anchor is judged for
pruning once seen more than ``update_interval * success_threshold`` times. Only the statistics
that took part are reset, so rarely seen anchors keep accumulating.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.methods.splatfacto.strategy import append_rows, keep_rows
from nerf2gs_plugin.methods.strategy_base import Strategy, SceneBudget


def voxelize(points: Tensor, voxel: float) -> Tensor:
    """Unique voxel centres ``[M, 3]`` (``round(p / voxel) * voxel``) of points ``[P, 3]``."""
    grid = torch.unique(torch.round(points / voxel).long(), dim=0)
    return grid.float() * voxel


def _keys(coords: Tensor, lo: Tensor, span: int) -> Tensor:
    c = coords - lo
    return (c[:, 0] * span + c[:, 1]) * span + c[:, 2]


@dataclass
class AnchorStats:
    grad_accum: Optional[Tensor] = None  # [M*k]
    denom: Optional[Tensor] = None  # [M*k]
    opacity_accum: Optional[Tensor] = None  # [M]
    anchor_denom: Optional[Tensor] = None  # [M]

    def reset(self, m: int, k: int, device: torch.device) -> None:
        self.grad_accum = torch.zeros(m * k, device=device)
        self.denom = torch.zeros(m * k, device=device)
        self.opacity_accum = torch.zeros(m, device=device)
        self.anchor_denom = torch.zeros(m, device=device)

    @torch.no_grad()
    def update(self, m: int, k: int, last: dict[str, Any]) -> None:
        """After backward: ``last`` holds the meta of the rasterized neural Gaussians, the visible
        anchor indices ``[Mv]``, the opacity>0 mask ``[Mv*k]`` and the opacities ``[Mv*k]``."""
        meta, idx, keep, opacity = last["meta"], last["anchor_idx"], last["keep"], last["opacity"]
        return self._update(m, k, meta, idx, keep, opacity, meta.get("means2d"))

    @torch.no_grad()
    def _update(self, m: int, k: int, meta: dict[str, Any], idx: Tensor, keep: Tensor, opacity: Tensor,
                grad_of: Optional[Tensor]) -> None:
        if self.denom is None or self.denom.shape[0] != m * k:
            self.reset(m, k, idx.device)
        self.opacity_accum.index_add_(0, idx, opacity.clamp_min(0).reshape(-1, k).sum(1))
        self.anchor_denom[idx] += 1
        g = grad_of.grad if grad_of is not None else None
        if g is None:
            return
        g = g[0].detach().clone()
        g[:, 0] *= float(meta["width"]) / 2.0
        g[:, 1] *= float(meta["height"]) / 2.0
        radii = meta["radii"][0]
        if radii.ndim == 2:
            radii = radii.amax(-1)
        slots = (idx[:, None] * k + torch.arange(k, device=idx.device)).reshape(-1)[keep]
        vis = radii > 0
        self.grad_accum.index_add_(0, slots[vis], g[vis].norm(dim=-1))
        self.denom.index_add_(0, slots[vis], torch.ones_like(slots[vis], dtype=torch.float32))

    def pad(self, n_new: int, k: int) -> None:
        dev = self.denom.device
        self.grad_accum = torch.cat([self.grad_accum, torch.zeros(n_new * k, device=dev)])
        self.denom = torch.cat([self.denom, torch.zeros(n_new * k, device=dev)])
        self.opacity_accum = torch.cat([self.opacity_accum, torch.zeros(n_new, device=dev)])
        self.anchor_denom = torch.cat([self.anchor_denom, torch.zeros(n_new, device=dev)])

    def keep(self, keep: Tensor, k: int) -> None:
        self.grad_accum = self.grad_accum.reshape(-1, k)[keep].reshape(-1)
        self.denom = self.denom.reshape(-1, k)[keep].reshape(-1)
        self.opacity_accum = self.opacity_accum[keep]
        self.anchor_denom = self.anchor_denom[keep]


@torch.no_grad()
def grow_anchors(c: Any, st: AnchorStats, a: Any, voxel: float, optimizers: Any, max_anchors: Optional[int] = None) -> int:
    """New anchors where neural Gaussians have large average gradients, level by level: level
    ``i`` uses threshold ``t * (h/2)^i`` and voxel ``v * f / h^i`` (h = hierarchy factor, f = init
    factor), keeps each candidate with probability ``1 - 0.5^(i+1)``, and adds only voxels that
    hold no anchor yet. New anchors take the max feature of their candidates. ``c``: the model
    config (its growing settings), ``a``: the anchor ParameterDict, ``voxel``: the base voxel size,
    ``max_anchors``: the budget in force (``c.max_anchors`` when None; 0 = none)."""
    k = c.n_offsets
    cap = c.max_anchors if max_anchors is None else max_anchors
    m0 = a["anchors"].shape[0]
    grads = st.grad_accum / st.denom.clamp_min(1)
    seen = st.denom > c.update_interval * c.success_threshold * 0.5
    xyz = (a["anchors"][:, None] + a["offsets"] * torch.exp(a["scaling"][:, None, :3])).reshape(-1, 3)
    feats = a["anchor_feat"].detach().repeat_interleave(k, dim=0)
    added = 0
    for level in range(c.update_depth):
        room = cap - a["anchors"].shape[0] if cap > 0 else None
        if room is not None and room <= 0:
            break
        thr = c.grow_threshold * (c.update_hierarchy_factor // 2) ** level
        cand = (grads >= thr) & seen & (torch.rand_like(grads) > 0.5 ** (level + 1))
        if not bool(cand.any()):
            continue
        size = voxel * c.update_init_factor / (c.update_hierarchy_factor**level)
        sel = torch.round(xyz[cand] / size).long()
        uniq, inverse = torch.unique(sel, dim=0, return_inverse=True)
        existing = torch.round(a["anchors"].detach() / size).long()
        lo = torch.minimum(uniq.amin(0), existing.amin(0))
        span = int(torch.maximum(uniq.amax(0), existing.amax(0)).sub(lo).max()) + 1
        new = ~torch.isin(_keys(uniq, lo, span), _keys(existing, lo, span))
        if not bool(new.any()):
            continue
        feat = torch.full((uniq.shape[0], feats.shape[1]), -torch.inf, device=feats.device)
        feat = feat.scatter_reduce(0, inverse[:, None].expand(-1, feats.shape[1]), feats[cand], "amax")
        new_idx = new.nonzero().squeeze(1)
        if room is not None and new_idx.numel() > room:
            new_idx = new_idx[torch.randperm(new_idx.numel(), device=new_idx.device)[:room]]
        n = new_idx.numel()
        rows = {
            "anchors": uniq[new_idx].float() * size,
            "anchor_feat": feat[new_idx],
            "offsets": torch.zeros(n, k, 3, device=feats.device),
            "scaling": torch.full((n, 6), float(torch.log(torch.tensor(size))), device=feats.device),
        }
        append_rows(a, optimizers, rows)
        added += n
    # the slots that took part start over; new anchors start with empty statistics
    st.grad_accum[seen] = 0
    st.denom[seen] = 0
    if added:
        st.pad(added, k)
    assert a["anchors"].shape[0] == m0 + added
    return added


@torch.no_grad()
def prune_anchors(c: Any, st: AnchorStats, a: Any, optimizers: Any) -> int:
    """Drop anchors seen often enough whose average neural opacity is below ``min_opacity``."""
    judged = st.anchor_denom > c.update_interval * c.success_threshold
    prune = (st.opacity_accum < c.min_opacity * st.anchor_denom) & judged
    if bool(prune.all()):
        prune[0] = False  # never empty the scene
    n = int(prune.sum())
    st.opacity_accum[judged] = 0
    st.anchor_denom[judged] = 0
    if n:
        keep = ~prune
        keep_rows(a, optimizers, keep)
        st.keep(keep, c.n_offsets)
    return n


class AnchorStrategy(Strategy):
    """Scaffold-GS's anchor growing and pruning as a :class:`Strategy`: statistics from the neural
    Gaussians' projected centres (``grad_key = "means2d"``) from ``start_stat``, refinement every
    ``update_interval`` steps in ``(update_from, update_until)``. ``info`` is the model's record of
    the step: the rasterizer's ``meta`` plus the visible anchors, the kept slots and opacities."""

    grad_key = "means2d"
    reduced_stats = {"stats.grad_accum": "sum", "stats.denom": "sum", "stats.opacity_accum": "sum", "stats.anchor_denom": "sum"}

    def __init__(self, config: Any, voxel: float) -> None:
        self.config = config  # the model config: its anchor growing / pruning settings
        self.voxel = voxel
        self.budget = SceneBudget(config.pixel_steps_per_anchor, config.update_until - config.update_from,
                                  config.max_anchors, config.anchor_growth)
        """Its ``pixels_fn`` (the training views' pixel count) and ``points`` (the initial anchors) are set by the model."""
        self.initialize_state()

    def initialize_state(self) -> None:
        self.stats = AnchorStats()

    def step_post_backward(self, params: Any, optimizers: Any, step: int, info: Optional[dict[str, Any]]) -> dict[str, int]:
        c = self.config
        if info is not None:
            self.accumulate(params, step, info)
        if c.update_from < step < c.update_until and step % c.update_interval == 0:
            with self.all_ranks(params["anchors"].device):
                return self.refine(params, optimizers)
        return {"grown": 0, "pruned": 0}

    def accumulate(self, params: Any, step: int, info: dict[str, Any]) -> None:
        c = self.config
        if c.start_stat <= step < c.update_until:
            meta = info["meta"]
            m, k = params["anchors"].shape[0], c.n_offsets
            self.stats._update(m, k, meta, info["anchor_idx"], info["keep"], info["opacity"], self.grad_tensor(meta))

    @torch.no_grad()
    def refine(self, params: Any, optimizers: Any) -> dict[str, int]:
        """Grow anchors from offset gradients, then prune transparent anchors."""
        k = self.config.n_offsets
        if self.stats.denom is None or self.stats.denom.shape[0] != params["anchors"].shape[0] * k:
            return {"grown": 0, "pruned": 0}
        grown = grow_anchors(self.config, self.stats, params, self.voxel, optimizers, self.budget.value)
        pruned = prune_anchors(self.config, self.stats, params, optimizers)
        return {"grown": grown, "pruned": pruned}
