"""Pure-torch tile compositing: the reference the C++ kernel is tested against, and the fallback.

Differentiable by autograd. Memory stays bounded: tiles are processed in batches whose padded
``tiles x pixels x list-length`` block stays under ``budget`` elements (a tile whose list is
longer than that is walked in list chunks with the transmittance carried over), and each batch is
checkpointed, so backward recomputes it rather than keeping every batch's intermediates. The semantics are
those of the kernel (and gsplat): ``alpha = min(0.99, o exp(-sigma))``, pairs with
``alpha < 1/255`` or ``sigma < 0`` are skipped, and compositing stops before the Gaussian that
would bring the transmittance to ``<= 1e-4``.
"""

from __future__ import annotations

import torch
from torch import Tensor
from torch.utils.checkpoint import checkpoint

from nerf2gs_plugin.rendering.tiles import tile_grid

ALPHA_MIN, ALPHA_MAX, T_MIN = 1.0 / 255.0, 0.99, 1e-4


def composite_torch(
    means2d: Tensor, conics: Tensor, colors: Tensor, opacities: Tensor, tile_offsets: Tensor, flat_ids: Tensor,
    n_cams: int, width: int, height: int, tile_size: int, budget: int = 1 << 21,
) -> tuple[Tensor, Tensor, Tensor]:
    """Composite flattened pairs front to back per tile.

    Args:
        means2d ``[CN, 2]``, conics ``[CN, 3]``, colors ``[CN, D]``, opacities ``[CN]``: per
        (camera, Gaussian) pair; tile_offsets ``[C*TY*TX+1]``, flat_ids ``[M]``: from
        :func:`~nerf2gs_plugin.rendering.tiles.bin_gaussians`.
    Returns:
        render ``[C, H, W, D]``, alpha ``[C, H, W]`` and median_ids ``[C, H, W]`` (int64 pair index of
        the last Gaussian composited while the transmittance was above 0.5; -1 for none).
    """
    dev, dt = means2d.device, means2d.dtype
    d = colors.shape[-1]
    tx_n, ty_n = tile_grid(width, height, tile_size)
    n_tiles = n_cams * tx_n * ty_n
    p = tile_size * tile_size
    lengths = (tile_offsets[1:] - tile_offsets[:-1]).tolist()
    # pixel coordinates of every tile's pixels and where they land in the flat [C*H*W] image
    ar = torch.arange(p, device=dev)
    off_x, off_y = ar % tile_size, torch.div(ar, tile_size, rounding_mode="floor")
    renders, alphas, medians, pix_idx = [], [], [], []
    t = 0
    while t < n_tiles:
        # grow the batch while the padded block fits the budget
        b, lmax = 1, max(lengths[t], 1)
        while t + b < n_tiles and (b + 1) * p * max(lmax, lengths[t + b], 1) <= budget:
            lmax = max(lmax, lengths[t + b], 1)
            b += 1
        tiles = torch.arange(t, t + b, device=dev)
        cam = torch.div(tiles, tx_n * ty_n, rounding_mode="floor")
        local = tiles % (tx_n * ty_n)
        x = (local % tx_n)[:, None] * tile_size + off_x[None]  # [B, P]
        y = torch.div(local, tx_n, rounding_mode="floor")[:, None] * tile_size + off_y[None]
        inside = (x < width) & (y < height)
        pix_idx.append(((cam[:, None] * height + y) * width + x)[inside])
        args = (means2d, conics, colors, opacities, flat_ids, tile_offsets[t:t + b + 1], x.to(dt) + 0.5, y.to(dt) + 0.5, budget)
        if torch.is_grad_enabled() and any(v.requires_grad for v in (means2d, conics, colors, opacities)):
            # recompute the batch in backward instead of keeping its [B, P, L] intermediates alive
            r, a, m = checkpoint(_composite_tiles, *args, use_reentrant=False)
        else:
            r, a, m = _composite_tiles(*args)
        renders.append(r[inside])
        alphas.append(a[inside])
        medians.append(m[inside])
        t += b
    idx = torch.cat(pix_idx)
    n_pix = n_cams * height * width
    render = torch.zeros(n_pix, d, device=dev, dtype=dt).index_put((idx,), torch.cat(renders))
    alpha = torch.zeros(n_pix, device=dev, dtype=dt).index_put((idx,), torch.cat(alphas))
    median = torch.full((n_pix,), -1, device=dev, dtype=torch.long).index_put((idx,), torch.cat(medians))
    shape = (n_cams, height, width)
    return render.reshape(*shape, d), alpha.reshape(shape), median.reshape(shape)


def _composite_tiles(
    means2d: Tensor, conics: Tensor, colors: Tensor, opacities: Tensor, flat_ids: Tensor, offsets: Tensor,
    px: Tensor, py: Tensor, budget: int,
) -> tuple[Tensor, Tensor, Tensor]:
    """A batch of ``B`` tiles with pixel centres ``px, py [B, P]`` -> ``[B, P, D]``, ``[B, P]``, ``[B, P]``."""
    b, p = px.shape
    dev, dt = px.device, px.dtype
    starts, lens = offsets[:-1], offsets[1:] - offsets[:-1]
    lmax = int(lens.max()) if b else 0
    chunk = max(1, budget // max(b * p, 1))
    trans = torch.ones(b, p, device=dev, dtype=dt)  # transmittance carried across list chunks
    done = torch.zeros(b, p, device=dev, dtype=torch.bool)
    out = torch.zeros(b, p, colors.shape[-1], device=dev, dtype=dt)
    median = torch.full((b, p), -1, device=dev, dtype=torch.long)
    for l0 in range(0, lmax, chunk):
        pos = torch.arange(l0, min(l0 + chunk, lmax), device=dev)  # [L]
        present = pos[None] < lens[:, None]  # [B, L]
        ids = flat_ids[(starts[:, None] + pos[None]).clamp_max(max(flat_ids.numel() - 1, 0))]
        ids = torch.where(present, ids, torch.zeros_like(ids))
        mx, my = means2d[ids, 0], means2d[ids, 1]  # [B, L]
        ca, cb, cc = conics[ids, 0], conics[ids, 1], conics[ids, 2]
        dx = mx[:, None, :] - px[:, :, None]  # [B, P, L]
        dy = my[:, None, :] - py[:, :, None]
        sigma = 0.5 * (ca[:, None] * dx * dx + cc[:, None] * dy * dy) + cb[:, None] * dx * dy
        alpha = torch.clamp_max(opacities[ids][:, None] * torch.exp(-sigma), ALPHA_MAX)
        valid = present[:, None] & (sigma >= 0) & (alpha >= ALPHA_MIN) & ~done[..., None]
        alpha = torch.where(valid, alpha, torch.zeros_like(alpha))
        t_after = trans[..., None] * torch.cumprod(1.0 - alpha, dim=-1)  # [B, P, L]
        keep = valid & (t_after > T_MIN)  # a prefix of the valid ones
        t_before = t_after / (1.0 - alpha)
        w = torch.where(keep, alpha * t_before, torch.zeros_like(alpha))
        out = out + torch.einsum("bpl,bld->bpd", w, colors[ids])
        with torch.no_grad():
            loc = (pos - l0)[None, None].expand_as(keep)
            med_pos = torch.where(keep & (t_before > 0.5), loc, torch.full_like(loc, -1))
            mp = med_pos.amax(-1)
            median = torch.where(mp >= 0, ids.gather(1, mp.clamp_min(0)), median)
        trans = trans * torch.where(keep, 1.0 - alpha, torch.ones_like(alpha)).prod(-1)
        done = done | (valid & ~keep).any(-1)
    return out, 1.0 - trans, median
