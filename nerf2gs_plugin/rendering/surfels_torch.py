"""2DGS surfel rasterization in pure torch (autograd): projection, per-tile lists, compositing.

This is the reference the C++ path is checked against and the fallback everywhere else.

Geometry (Huang et al. 2024, "2D Gaussian Splatting"): a surfel with centre ``p``, tangent axes
``t_u = s_u R[:, 0]``, ``t_v = s_v R[:, 1]`` maps its local ``(u, v, 1)`` to homogeneous pixels by
the 3x3 homography ``T = K [t_u | t_v | p]`` (camera frame). A pixel ``(x, y)`` is the
intersection of two planes whose common point in surfel space is ``adj(T) (x, y, 1)``: with
``q = adj(T) (x, y, 1)``, ``(u, v) = (q_x, q_y) / q_z`` and the ray hits the surfel at camera depth
``det(T) / q_z``. The surfel Gaussian ``exp(-(u^2 + v^2) / 2)`` is combined with 2DGS's
screen-space low-pass ``exp(-|x - c|^2)`` (a Gaussian of std sqrt(2)/2 px about the projected
centre ``c``) by taking the larger of the two, i.e. the smaller "distance"; where the low-pass
wins the depth is the centre's depth. Alphas are clamped at 0.99, skipped under 1/255, and a
pixel stops once its transmittance would fall under 1e-4 (as 2DGS/gsplat).

Memory: Gaussians are binned into ``tile_size``^2 tiles with depth-sorted lists; tiles are
composited in batches padded to the longest list in the batch (tiles grouped by list length;
large images recompute each batch in backward instead of keeping its temporaries),
so no tensor is ever Gaussians x pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import torch
from torch import Tensor
from torch.utils.checkpoint import checkpoint

from nerf2gs_plugin.utils.quaternions import quat_to_rotmat

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4
LOWPASS_INV_SQ = 2.0  # 1 / (sqrt(2)/2)^2: the screen-space filter of 2DGS
# pairs x pixels held per compositing batch (bounds the peak of the temporaries)
PAIR_PIXEL_BUDGET = 1 << 22
# above this many pairs x pixels per image batch, batches are recomputed in backward (checkpointing)
RECOMPUTE_ABOVE = 1 << 25


@dataclass
class SurfelProjection:
    """Per camera and surfel screen-space quantities (C cameras, N surfels)."""

    T: Tensor  # [C, N, 3, 3] homography surfel (u, v, 1) -> homogeneous pixels (differentiable)
    means2d: Tensor  # [C, N, 2] projected centres in pixels (differentiable)
    depths: Tensor  # [C, N] camera z of the centres (differentiable)
    normals: Tensor  # [C, N, 3] unit normals in the camera frame, flipped to face the camera
    radii: Tensor  # [C, N] int32 pixel radius of the footprint; 0 = culled
    bbox: Tensor  # [C, N, 4] (x0, y0, x1, y1) pixel box of the footprint (no grad)


def project_surfels(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, viewmats: Tensor,
                    Ks: Tensor, width: int, height: int, near_plane: float, far_plane: float) -> SurfelProjection:
    """Surfels ``[N]`` into ``C`` cameras: homographies, centres, normals and footprint boxes.

    The box is the exact bounding box of the projected disc out to where ``opacity * G`` drops to
    1/255 (the image of a circle is the conic whose dual is ``T diag(1, 1, -1/r^2) T^T``), merged
    with the low-pass footprint about the centre. A disc that reaches the camera plane is given the
    whole image (conservative; the per-pixel depth test culls what is behind).
    """
    R = quat_to_rotmat(quats)  # normalises  # [N,3,3]
    rv, tv = viewmats[:, :3, :3], viewmats[:, :3, 3]
    p = torch.einsum("cij,nj->cni", rv, means) + tv[:, None, :]  # [C,N,3]
    tu = torch.einsum("cij,nj->cni", rv, R[..., 0] * scales[:, None, 0])
    tvv = torch.einsum("cij,nj->cni", rv, R[..., 1] * scales[:, None, 1])
    n = torch.einsum("cij,nj->cni", rv, R[..., 2])
    facing = torch.where((n * p).sum(-1, keepdim=True) > 0, -1.0, 1.0).to(n.dtype).detach()
    n = n * facing
    M = torch.stack([tu, tvv, p], dim=-1)  # [C,N,3,3] columns t_u, t_v, p
    T = Ks[:, None, :, :] @ M
    z = p[..., 2]
    in_range = (z > near_plane) & (z < far_plane)
    w_safe = torch.where(in_range, T[..., 2, 2], torch.ones_like(z))
    means2d = T[..., :2, 2] / w_safe[..., None]

    with torch.no_grad():
        Td = T.detach()
        # opacity-aware cut-off: alpha = o G >= 1/255  <=>  u^2 + v^2 <= 2 ln(255 o)
        r2 = (2.0 * torch.log((opacities.detach() * 255.0).clamp_min(1.0)))[None, :].expand_as(z)
        q = torch.stack([torch.ones_like(r2), torch.ones_like(r2), -1.0 / r2.clamp_min(1e-12)], dim=-1)
        D = (Td * q[..., None, :]) @ Td.transpose(-1, -2)  # dual conic of the disc's image
        d22 = D[..., 2, 2]
        ellipse = d22 < 0
        d22s = torch.where(ellipse, d22, -torch.ones_like(d22))
        cx, cy = D[..., 0, 2] / d22s, D[..., 1, 2] / d22s
        hx = (cx * cx - D[..., 0, 0] / d22s).clamp_min(0).sqrt()
        hy = (cy * cy - D[..., 1, 1] / d22s).clamp_min(0).sqrt()
        lp = (r2 / LOWPASS_INV_SQ).sqrt()  # low-pass footprint radius
        m2 = means2d.detach()
        x0 = torch.minimum(cx - hx, m2[..., 0] - lp)
        x1 = torch.maximum(cx + hx, m2[..., 0] + lp)
        y0 = torch.minimum(cy - hy, m2[..., 1] - lp)
        y1 = torch.maximum(cy + hy, m2[..., 1] + lp)
        big = float(max(width, height)) * 4
        x0 = torch.where(ellipse, x0, torch.full_like(x0, -big))
        y0 = torch.where(ellipse, y0, torch.full_like(y0, -big))
        x1 = torch.where(ellipse, x1, torch.full_like(x1, big))
        y1 = torch.where(ellipse, y1, torch.full_like(y1, big))
        bbox = torch.stack([x0, y0, x1, y1], dim=-1)
        finite = torch.isfinite(bbox).all(-1) & torch.isfinite(Td).flatten(-2).all(-1)
        onscreen = (x1 > 0) & (x0 < width) & (y1 > 0) & (y0 < height)
        visible = in_range & finite & onscreen & (opacities.detach() >= ALPHA_MIN)[None, :]
        rad = torch.maximum(x1 - x0, y1 - y0) * 0.5
        radii = torch.where(visible, rad.clamp(max=float(max(width, height))).ceil(), torch.zeros_like(rad))
        radii = radii.to(torch.int32)
        bbox = torch.where(visible[..., None], bbox, torch.zeros_like(bbox))
    return SurfelProjection(T=T, means2d=means2d, depths=z, normals=n, radii=radii, bbox=bbox)


@dataclass
class TileLists:
    """Depth-sorted (surfel, tile) pairs grouped by tile, for C cameras of TH x TW tiles."""

    flat_ids: Tensor  # [P] indices into C*N (camera-major), sorted by tile then depth
    starts: Tensor  # [C*TH*TW] first pair of each tile
    counts: Tensor  # [C*TH*TW] pairs per tile
    tiles_w: int
    tiles_h: int
    tile_size: int


def build_tile_lists(proj: SurfelProjection, width: int, height: int, tile_size: int) -> TileLists:
    """Bin visible surfels into the tiles their box overlaps; sort each tile's list by centre depth."""
    C, N = proj.radii.shape
    tw, th = math.ceil(width / tile_size), math.ceil(height / tile_size)
    dev = proj.radii.device
    with torch.no_grad():
        vis = (proj.radii > 0).reshape(-1)
        box = proj.bbox.reshape(-1, 4)
        # pixel i has centre i + 0.5: it is inside [x0, x1] when x0 - 0.5 <= i <= x1 - 0.5
        tx0 = torch.floor((box[:, 0] - 0.5) / tile_size).clamp(0, tw - 1).long()
        tx1 = torch.floor((box[:, 2] - 0.5) / tile_size).clamp(0, tw - 1).long()
        ty0 = torch.floor((box[:, 1] - 0.5) / tile_size).clamp(0, th - 1).long()
        ty1 = torch.floor((box[:, 3] - 0.5) / tile_size).clamp(0, th - 1).long()
        nx, ny = tx1 - tx0 + 1, ty1 - ty0 + 1
        cnt = torch.where(vis, nx * ny, torch.zeros_like(nx))
        ids = torch.arange(C * N, device=dev)
        rep = torch.repeat_interleave(ids, cnt)
        first = torch.cumsum(cnt, 0) - cnt
        local = torch.arange(rep.numel(), device=dev) - first[rep]
        tx = tx0[rep] + local % nx[rep]
        ty = ty0[rep] + local // nx[rep]
        tile = (rep // N) * (th * tw) + ty * tw + tx
        depth = proj.depths.detach().reshape(-1)[rep]
        order = torch.argsort(depth, stable=True)
        order = order[torch.argsort(tile[order], stable=True)]
        flat_ids = rep[order]
        counts = torch.bincount(tile, minlength=C * th * tw)
        starts = torch.cumsum(counts, 0) - counts
    return TileLists(flat_ids=flat_ids, starts=starts, counts=counts, tiles_w=tw, tiles_h=th, tile_size=tile_size)


def _excl_cumsum(x: Tensor) -> Tensor:
    return torch.cumsum(x, -1) - x


def _composite_batch(ids: Tensor, valid: Tensor, pix: Tensor, attr: dict[str, Tensor], near_plane: float,
                     densify: Optional[Tensor], screen_signal: bool = False) -> Tensor:
    """Composite B tiles. ``ids [B,K]`` surfel rows, ``valid [B,K]``, ``pix [B,P,2]`` pixel centres.

    Returns ``[B, P, D + 7]``: colours (D), accumulated depth, alpha, normals (3), distortion, median.
    """
    B, K = ids.shape
    a = pix[..., 0:1]  # [B,P,1]
    b = pix[..., 1:2]
    # q = adj(T) (a, b, 1) for every pixel and surfel of a tile as one batched matmul
    hm = attr["adj"][ids].permute(0, 3, 2, 1).reshape(B, 3, 3 * K)  # [B, j, i*K + k] = adj_k[i, j]
    pixh = torch.cat([pix, torch.ones_like(a)], dim=-1)  # [B,P,3]
    qx, qy, qz = torch.bmm(pixh, hm).view(B, -1, 3, K).unbind(2)  # each [B,P,K]
    ok = (qz.abs() * 1e6 > qx.abs() + qy.abs()) & (qz != 0) & valid[:, None, :]
    inv = 1.0 / torch.where(ok, qz, torch.ones_like(qz))
    u, v = qx * inv, qy * inv
    rho3 = u * u + v * v
    m2 = attr["means2d"][ids][:, None]  # [B,1,K,2]
    dx, dy = m2[..., 0] - a, m2[..., 1] - b
    rho2 = LOWPASS_INV_SQ * (dx * dx + dy * dy)
    use3 = rho3 <= rho2
    rho = torch.where(use3, rho3, rho2)
    zc = attr["depths"][ids][:, None]  # [B,1,K]
    depth = torch.where(use3, attr["det"][ids][:, None] * inv, zc)
    g = torch.exp(-0.5 * rho)
    if densify is not None:
        # 2DGS's densification signal, dG/dc for the projected centre c (its gradient is the signal):
        # "lowpass" as if every surfel were the screen-space low-pass Gaussian about c; "screen" the
        # surfel moved rigidly on screen, -grad_x G = G (u grad_x u + v grad_x v) where the surfel wins
        dn = densify[ids][:, None]  # [B,1,K,2], all zeros
        sx, sy = -LOWPASS_INV_SQ * dx.detach(), -LOWPASS_INV_SQ * dy.detach()
        if screen_signal:
            h = attr["adj"][ids].detach()[:, None]  # [B,1,K,3,3]
            ud, vd, invd = u.detach(), v.detach(), inv.detach()
            sx3 = (ud * (h[..., 0, 0] - ud * h[..., 2, 0]) + vd * (h[..., 1, 0] - vd * h[..., 2, 0])) * invd
            sy3 = (ud * (h[..., 0, 1] - ud * h[..., 2, 1]) + vd * (h[..., 1, 1] - vd * h[..., 2, 1])) * invd
            sx, sy = torch.where(use3, sx3, sx), torch.where(use3, sy3, sy)
        g = g + g.detach() * (sx * dn[..., 0] + sy * dn[..., 1])
    alpha = (attr["opacities"][ids][:, None] * g).clamp(max=ALPHA_MAX)
    ok = ok & (alpha >= ALPHA_MIN) & (depth > near_plane) & torch.isfinite(depth)
    alpha = torch.where(ok, alpha, torch.zeros_like(alpha))
    with torch.no_grad():  # early termination: drop what comes once transmittance would be < T_MIN
        t_after = torch.exp(torch.cumsum(torch.log1p(-alpha), -1))
        alpha_keep = t_after >= T_MIN
    alpha = torch.where(alpha_keep, alpha, torch.zeros_like(alpha))
    log_t = torch.log1p(-alpha)
    t_before = torch.exp(_excl_cumsum(log_t))
    w = alpha * t_before  # [B,P,K]
    feats = torch.cat([attr["colors"][ids], attr["normals"][ids]], dim=-1)  # [B,K,D+3]
    cn = torch.einsum("bpk,bkd->bpd", w, feats)
    dsum = (w * depth).sum(-1, keepdim=True)
    acc = 1.0 - torch.exp(log_t.sum(-1, keepdim=True))
    # depth distortion (2DGS): sum_i w_i sum_{j<i} w_j (z_i - z_j)^2, with cumulative moments
    wa = _excl_cumsum(w)
    m1 = _excl_cumsum(w * depth)
    m2_ = _excl_cumsum(w * depth * depth)
    dist = (w * (depth * depth * wa + m2_ - 2.0 * depth * m1)).sum(-1, keepdim=True)
    # median depth: the last contributing surfel while transmittance before it is still > 0.5
    with torch.no_grad():
        mk = (alpha > 0) & (t_before > 0.5)
        k = torch.arange(1, mk.shape[-1] + 1, device=mk.device)
        idx = (mk * k).argmax(-1, keepdim=True)
        has = mk.any(-1, keepdim=True)
    median = torch.gather(depth, -1, idx) * has
    D = attr["colors"].shape[-1]
    return torch.cat([cn[..., :D], dsum, acc, cn[..., D:], dist, median], dim=-1)


def composite_surfels_torch(proj: SurfelProjection, lists: TileLists, opacities: Tensor, colors: Tensor,
                            width: int, height: int, near_plane: float,
                            densify: Optional[Tensor] = None, densify_signal: str = "lowpass") -> dict[str, Tensor]:
    """Per-pixel compositing of the tile lists (autograd through everything).

    ``opacities [N]``; ``colors [C,N,D]``; ``densify [C,N,2]`` zeros (or None) whose gradient becomes
    2DGS's densification signal, as defined by ``densify_signal`` (see :func:`_composite_batch`).
    Returns per-camera maps: ``colors [C,H,W,D]``, ``depth [C,H,W,1]`` (accumulated, not
    normalised), ``alpha``, ``normals [C,H,W,3]``, ``distort``, ``median``.
    """
    C, N = proj.radii.shape
    D = colors.shape[-1]
    ts, tw, th = lists.tile_size, lists.tiles_w, lists.tiles_h
    dev, dt = proj.T.device, proj.T.dtype
    T = proj.T.reshape(C * N, 3, 3)
    adj = _adjugate(T)
    attr = {
        "adj": adj,
        "det": _det(T, adj),
        "means2d": proj.means2d.reshape(C * N, 2),
        "depths": proj.depths.reshape(C * N),
        "normals": proj.normals.reshape(C * N, 3),
        "opacities": opacities[None, :].expand(C, N).reshape(C * N),
        "colors": colors.reshape(C * N, D),
    }
    dens = densify.reshape(C * N, 2) if densify is not None else None
    screen = densify_signal == "screen"
    n_pix = ts * ts
    nonempty = torch.nonzero(lists.counts > 0).flatten()
    out = torch.zeros(C * th * tw, n_pix, D + 7, device=dev, dtype=dt)
    if nonempty.numel() > 0:
        cnts = lists.counts[nonempty]
        order = torch.argsort(cnts)
        tiles_sorted, cnts_sorted = nonempty[order], cnts[order].tolist()
        local = torch.arange(ts, device=dev, dtype=dt) + 0.5
        py, px = torch.meshgrid(local, local, indexing="ij")
        offs = torch.stack([px.reshape(-1), py.reshape(-1)], dim=-1)  # [P,2]
        results, done_tiles = [], []
        padded = sum(cnts_sorted) * n_pix
        recompute = torch.is_grad_enabled() and padded > RECOMPUTE_ABOVE
        i = 0
        while i < len(cnts_sorted):
            # grow the batch while (tiles x longest list x pixels) fits the budget
            j = i + 1
            while j < len(cnts_sorted) and (j + 1 - i) * cnts_sorted[j] * n_pix <= PAIR_PIXEL_BUDGET:
                j += 1
            tiles = tiles_sorted[i:j]
            kmax = cnts_sorted[j - 1]
            kk = torch.arange(kmax, device=dev)
            valid = kk[None, :] < lists.counts[tiles][:, None]
            pos = (lists.starts[tiles][:, None] + kk[None, :]).clamp(max=max(lists.flat_ids.numel() - 1, 0))
            ids = torch.where(valid, lists.flat_ids[pos], torch.zeros_like(pos))
            t_in_cam = tiles % (th * tw)
            origin = torch.stack([(t_in_cam % tw) * ts, (t_in_cam // tw) * ts], dim=-1).to(dt)  # [B,2]
            pix = origin[:, None, :] + offs[None]
            if recompute:  # bounded memory: keep only the batch inputs, redo the batch in backward
                results.append(checkpoint(_composite_batch, ids, valid, pix, attr, near_plane, dens, screen,
                                          use_reentrant=False))
            else:
                results.append(_composite_batch(ids, valid, pix, attr, near_plane, dens, screen))
            done_tiles.append(tiles)
            i = j
        out = out.index_copy(0, torch.cat(done_tiles), torch.cat(results, 0))
    img = out.reshape(C, th, tw, ts, ts, D + 7).permute(0, 1, 3, 2, 4, 5).reshape(C, th * ts, tw * ts, D + 7)
    img = img[:, :height, :width]
    parts = img.split([D, 1, 1, 3, 1, 1], dim=-1)
    return dict(zip(("colors", "depth", "alpha", "normals", "distort", "median"), parts))


def _adjugate(T: Tensor) -> Tensor:
    """Adjugate of ``[M,3,3]``: its columns are the cross products of T's rows (``T adj(T) = det I``)."""
    r0, r1, r2 = T[:, 0], T[:, 1], T[:, 2]
    return torch.stack([torch.cross(r1, r2, dim=-1), torch.cross(r2, r0, dim=-1), torch.cross(r0, r1, dim=-1)], dim=-1)


def _det(T: Tensor, adj: Tensor) -> Tensor:
    """``det(T)`` as ``row0 . (row1 x row2)`` (a polynomial: finite gradients for singular T)."""
    return (T[:, 0] * adj[:, :, 0]).sum(-1)


def depth_to_normals(depth: Tensor, Ks: Tensor) -> Tensor:
    """Camera-frame normals of a z-depth map ``[C,H,W,1]`` by central differences -> ``[C,H,W,3]``.

    Points are back-projected through pixel centres; the normal is ``normalize(dP/dy x dP/dx)``,
    which faces the camera for a visible surface; the one-pixel border is zero (as 2DGS).
    """
    C, Hh, Ww, _ = depth.shape
    dev, dt = depth.device, depth.dtype
    ys = torch.arange(Hh, device=dev, dtype=dt) + 0.5
    xs = torch.arange(Ww, device=dev, dtype=dt) + 0.5
    fx, fy = Ks[:, 0, 0, None, None], Ks[:, 1, 1, None, None]
    cx, cy = Ks[:, 0, 2, None, None], Ks[:, 1, 2, None, None]
    d = depth[..., 0]
    X = (xs[None, None, :] - cx) / fx * d
    Y = (ys[None, :, None] - cy) / fy * d
    P = torch.stack([X, Y, d], dim=-1)  # [C,H,W,3]
    if Hh < 3 or Ww < 3:
        return torch.zeros_like(P)
    ddy = P[:, 2:, 1:-1] - P[:, :-2, 1:-1]
    ddx = P[:, 1:-1, 2:] - P[:, 1:-1, :-2]
    n = torch.nn.functional.normalize(torch.cross(ddy, ddx, dim=-1), dim=-1)
    return torch.nn.functional.pad(n, (0, 0, 1, 1, 1, 1))
