"""Ray sampling, volume rendering and the proposal/distortion losses (mip-NeRF 360, nerfacto).

Samples live in a normalised *spacing* ``s in [0, 1]`` between a ray's near and far distance;
``t`` (metric distance along the ray, world units) relates to it through the piecewise
linear/disparity map ``g(t) = t/2`` for ``t < 1`` and ``1 - 1/(2t)`` beyond, so uniform ``s`` puts
half the samples within one unit of the camera and the other half out to (almost) infinity,
matching the contraction of the field.

Shapes: ``R`` rays, ``n`` intervals per ray; edges are ``[R, n+1]``, weights ``[R, n]``.
"""

from __future__ import annotations

from typing import Optional

import torch
from torch import Tensor


def _g(t: Tensor) -> Tensor:
    return torch.where(t < 1.0, t / 2.0, 1.0 - 1.0 / (2.0 * t.clamp_min(1e-6)))


def _g_inv(u: Tensor) -> Tensor:
    return torch.where(u < 0.5, 2.0 * u, 1.0 / (2.0 - 2.0 * u).clamp_min(1e-6))


def s_to_t(s: Tensor, near: Tensor, far: Tensor) -> Tensor:
    """Spacing ``s [R,k]`` -> distance ``t [R,k]`` for per-ray ``near/far [R,1]``."""
    g0, g1 = _g(near), _g(far)
    return _g_inv(g0 + s * (g1 - g0))


def uniform_edges(num_rays: int, n: int, device: torch.device, jitter: bool, generator: Optional[torch.Generator] = None) -> Tensor:
    """``n`` stratified intervals over [0,1]: ``[R, n+1]`` edges (jittered when training)."""
    bins = torch.linspace(0.0, 1.0, n + 1, device=device).expand(num_rays, n + 1)
    if not jitter:
        return bins.contiguous()
    centers = (bins[:, 1:] + bins[:, :-1]) / 2
    upper = torch.cat([centers, bins[:, -1:]], -1)
    lower = torch.cat([bins[:, :1], centers], -1)
    u = torch.rand(num_rays, n + 1, device=device, generator=generator)
    return lower + (upper - lower) * u


def pdf_edges(edges: Tensor, weights: Tensor, n: int, jitter: bool, padding: float = 0.01) -> Tensor:
    """Importance-sample ``n`` new intervals from the piecewise-constant pdf ``weights`` over
    ``edges`` (inverse CDF, stratified) -> sorted ``[R, n+1]`` edges, no gradient."""
    w = weights.detach() + padding
    w = w / w.sum(-1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(w[:, :1]), torch.cumsum(w, -1).clamp(max=1.0)], -1)
    R = edges.shape[0]
    if jitter:
        u = torch.linspace(0.0, 1.0 - 1.0 / (n + 1), n + 1, device=edges.device) + torch.rand(R, n + 1, device=edges.device) / (n + 1)
    else:
        u = torch.linspace(0.0, 1.0, n + 1, device=edges.device).expand(R, n + 1)
    u = u.contiguous()
    inds = torch.searchsorted(cdf.contiguous(), u, right=True)
    below = (inds - 1).clamp(0, cdf.shape[-1] - 1)
    above = inds.clamp(0, cdf.shape[-1] - 1)
    c0, c1 = cdf.gather(-1, below), cdf.gather(-1, above)
    b0, b1 = edges.gather(-1, below), edges.gather(-1, above)
    frac = torch.nan_to_num((u - c0) / (c1 - c0), 0.0).clamp(0.0, 1.0)
    out = b0 + frac * (b1 - b0)
    return torch.sort(out, -1).values.detach()


def render_weights(density: Tensor, t_edges: Tensor) -> Tensor:
    """Alpha compositing weights ``[R,n]`` from densities ``[R,n]`` and distance edges ``[R,n+1]``."""
    delta = (t_edges[:, 1:] - t_edges[:, :-1]).clamp_min(0.0)
    sd = density * delta
    trans = torch.exp(-torch.cat([torch.zeros_like(sd[:, :1]), torch.cumsum(sd[:, :-1], -1)], -1))
    return (1.0 - torch.exp(-sd)) * trans


def outer_weights(s_query: Tensor, s_env: Tensor, w_env: Tensor) -> Tensor:
    """For each query interval, the summed envelope weight of every envelope interval that
    overlaps it (the upper bound of mip-NeRF 360, Eq. 13): ``[R, n_query]``."""
    cw = torch.cat([torch.zeros_like(w_env[:, :1]), torch.cumsum(w_env, -1)], -1)
    starts, ends = s_query[:, :-1].contiguous(), s_query[:, 1:].contiguous()
    n_env = w_env.shape[-1]
    lo = (torch.searchsorted(s_env[:, :-1].contiguous(), starts, right=True) - 1).clamp(0, n_env - 1)
    hi = torch.searchsorted(s_env[:, 1:].contiguous(), ends, right=True).clamp(0, n_env - 1)
    return cw[:, 1:].gather(-1, hi) - cw[:, :-1].gather(-1, lo)


def interlevel_loss(s_fine: Tensor, w_fine: Tensor, proposals: list[tuple[Tensor, Tensor]]) -> Tensor:
    """Proposal supervision: each proposal's weights must bound the (detached) final weights."""
    w = w_fine.detach()
    loss = w.new_zeros(())
    for s_p, w_p in proposals:
        bound = outer_weights(s_fine, s_p, w_p)
        loss = loss + ((w - bound).clamp_min(0.0) ** 2 / (w + 1e-7)).sum(-1).mean()
    return loss


def distortion_loss(s_edges: Tensor, weights: Tensor) -> Tensor:
    """mip-NeRF 360 distortion loss in spacing space, O(n) per ray; mean over rays."""
    mid = (s_edges[:, 1:] + s_edges[:, :-1]) / 2
    width = s_edges[:, 1:] - s_edges[:, :-1]
    wm = weights * mid
    w_cum, wm_cum = torch.cumsum(weights, -1), torch.cumsum(wm, -1)
    bi = 2.0 * (wm[:, 1:] * w_cum[:, :-1] - weights[:, 1:] * wm_cum[:, :-1]).sum(-1)
    uni = (weights**2 * width).sum(-1) / 3.0
    return (bi + uni).mean()
