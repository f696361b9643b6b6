"""The C++/OpenMP 2DGS kernels (``csrc/surfels.cpp``) behind torch autograd Functions.

Compositing (forward and backward) computes exactly what
:func:`surfels_torch.composite_surfels_torch` computes; projection fused with SH colours (forward
and backward, ``csrc/surfels_proj_core.h``) computes what :func:`surfels_torch.project_surfels` and
:func:`sh.eval_sh` compute, and the tile lists what :func:`surfels_torch.build_tile_lists` builds
(the tests compare values and gradients). Without them a training step spent most of its time in
~150 small autograd ops of the projection.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.rendering.surfels_torch import SurfelProjection, TileLists, _adjugate, _det
from nerf2gs_plugin.utils.extensions import extension_error, load_extension

EXT_NAME = "nerf2gs_surfels"
CSRC = Path(__file__).with_name("csrc")
EXT_SOURCES = [CSRC / "surfels.cpp"]
EXT_HEADERS = [CSRC / h for h in ("surfels_proj_core.h", "binning_core.h", "projection_bwd.h", "projection_core.h", "sh_core.h")]
EXT_CFLAGS = ("-O3", "-fopenmp", "-march=native", "-fno-math-errno")


def extension() -> Optional[Any]:
    """The compiled kernel (built on first use, cached under ``TORCH_EXTENSIONS_DIR``), or None."""
    return load_extension(EXT_NAME, EXT_SOURCES, EXT_HEADERS, EXT_CFLAGS)


def available() -> bool:
    return extension() is not None


def error() -> Optional[str]:
    return extension_error(EXT_NAME)


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx: Any, adj: Tensor, det: Tensor, m2: Tensor, zc: Tensor, op: Tensor, feats: Tensor,
                densify: Tensor, box: Tensor, ids: Tensor, starts: Tensor, counts: Tensor, dims: tuple,
                screen_signal: bool) -> Tensor:
        ext = extension()
        out, auxf, auxi = ext.forward(adj, det, m2, zc, op, box, feats, ids, starts, counts, *dims)
        ctx.save_for_backward(adj, det, m2, zc, op, box, feats, ids, starts, counts, out, auxf, auxi)
        ctx.dims, ctx.screen_signal = dims, screen_signal
        return out

    @staticmethod
    def backward(ctx: Any, gout: Tensor) -> tuple:
        adj, det, m2, zc, op, box, feats, ids, starts, counts, out, auxf, auxi = ctx.saved_tensors
        g = extension().backward(adj, det, m2, zc, op, box, feats, ids, starts, counts, *ctx.dims, out, auxf, auxi,
                                 gout.contiguous(), ctx.screen_signal)
        F = feats.shape[1]
        return (g[:, 0:9], g[:, 9], g[:, 10:12], g[:, 12], g[:, 13], g[:, 16:16 + F], g[:, 14:16],
                None, None, None, None, None, None)


@dataclass
class SurfelProjectionCPU:
    """What the C++ projection gives the compositor (C cameras, N surfels; shapes as SurfelProjection)."""

    adj: Tensor  # [C*N, 9] adjugate of the homography T, row-major (differentiable)
    det: Tensor  # [C*N] det(T) (differentiable)
    means2d: Tensor  # [C, N, 2] (differentiable)
    depths: Tensor  # [C, N] centre camera z (differentiable)
    normals: Tensor  # [C, N, 3] camera-facing unit normals (differentiable)
    radii: Tensor  # [C, N] int32, 0 = culled
    bbox: Tensor  # [C, N, 4] footprint box (no grad)


class _Project(torch.autograd.Function):
    @staticmethod
    def forward(ctx: Any, means: Tensor, quats: Tensor, scales: Tensor, opac: Tensor, sh: Tensor, viewmats: Tensor,
                Ks: Tensor, args: tuple) -> tuple:
        ctx.set_materialize_grads(False)
        ctx.args = args
        ctx.save_for_backward(means, quats, scales, sh, viewmats, Ks)
        out = extension().project(means, quats, scales, opac, sh, viewmats, Ks, *args)
        ctx.mark_non_differentiable(out[5], out[6])
        return tuple(out)

    @staticmethod
    def backward(ctx: Any, v_adj, v_det, v_m2, v_dep, v_nrm, _v_radii, _v_box, v_col) -> tuple:
        means, quats, scales, sh, viewmats, Ks = ctx.saved_tensors
        cn = viewmats.shape[0] * means.shape[0]
        z = means.new_zeros

        def c(t: Optional[Tensor], *shape: int) -> Tensor:
            return t.contiguous() if t is not None else z(*shape)

        v_col = v_col.contiguous() if v_col is not None and sh.numel() > 0 else z(0)
        gm, gq, gs, gsh = extension().project_backward(means, quats, scales, sh, viewmats, Ks, *ctx.args,
                                                       c(v_adj, cn, 9), c(v_det, cn), c(v_m2, cn, 2), c(v_dep, cn),
                                                       c(v_nrm, cn, 3), v_col)
        return gm, gq, gs, None, (gsh if sh.numel() > 0 else None), None, None, None


def project_surfels_cpu(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, viewmats: Tensor, Ks: Tensor,
                        width: int, height: int, near_plane: float, far_plane: float, sh: Optional[Tensor] = None,
                        sh_degree: int = 0) -> tuple[SurfelProjectionCPU, Optional[Tensor]]:
    """:func:`surfels_torch.project_surfels` (+ SH colours ``[C,N,3]`` of ``sh [N,K,3]`` at degree <= 3)
    by the extension; differentiable w.r.t. means, quats, scales and SH (not the cameras)."""
    dt = means.dtype
    sh_t = sh.to(dt).contiguous() if sh is not None else means.new_zeros(0)
    args = (int(width), int(height), float(near_plane), float(far_plane), int(sh_degree) if sh is not None else 0)
    adj, det, m2, dep, nrm, radii, bbox, cols = _Project.apply(
        means.contiguous(), quats.to(dt).contiguous(), scales.to(dt).contiguous(), opacities.detach().to(dt).contiguous(),
        sh_t, viewmats.to(dt).contiguous(), Ks.to(dt).contiguous(), args)
    return SurfelProjectionCPU(adj, det, m2, dep, nrm, radii, bbox), (cols if sh is not None else None)


def tile_lists_cpu(proj: Any, width: int, height: int, tile_size: int) -> TileLists:
    """:func:`surfels_torch.build_tile_lists` by the extension (same lists, same order)."""
    C, N = proj.radii.shape
    ids, starts, counts = extension().tile_lists(proj.bbox.detach().contiguous(), proj.depths.detach().contiguous(),
                                                 proj.radii.contiguous(), int(width), int(height), int(tile_size))
    return TileLists(flat_ids=ids, starts=starts, counts=counts, tiles_w=-(-width // tile_size),
                     tiles_h=-(-height // tile_size), tile_size=tile_size)


def composite_surfels_cpu(proj: SurfelProjection | SurfelProjectionCPU, lists: TileLists, opacities: Tensor, colors: Tensor,
                          width: int, height: int, near_plane: float,
                          densify: Optional[Tensor] = None, densify_signal: str = "lowpass") -> dict[str, Tensor]:
    """Same contract as :func:`surfels_torch.composite_surfels_torch`, computed by the C++ kernel."""
    C, N = proj.radii.shape
    D = colors.shape[-1]
    if isinstance(proj, SurfelProjectionCPU):
        adj, det, dt = proj.adj, proj.det, proj.adj.dtype
    else:
        T = proj.T.reshape(C * N, 3, 3)
        dt = T.dtype
        adj3 = _adjugate(T)
        det = _det(T, adj3).contiguous()
        adj = adj3.reshape(C * N, 9).contiguous()
    m2 = proj.means2d.reshape(C * N, 2).contiguous()
    zc = proj.depths.reshape(C * N).contiguous()
    op = opacities.to(dt)[None, :].expand(C, N).reshape(C * N).contiguous()
    feats = torch.cat([colors.reshape(C * N, D), proj.normals.reshape(C * N, 3)], dim=-1).to(dt).contiguous()
    dens = densify.reshape(C * N, 2) if densify is not None else torch.zeros(C * N, 2, dtype=dt)
    dims = (C, height, width, lists.tile_size, lists.tiles_w, lists.tiles_h, float(near_plane))
    box = proj.bbox.reshape(C * N, 4).to(dt).contiguous()
    out = _Composite.apply(adj, det, m2, zc, op, feats, dens, box, lists.flat_ids.contiguous(),
                           lists.starts.contiguous(), lists.counts.contiguous(), dims, densify_signal == "screen")
    parts = out.split([D, 3, 1, 1, 1, 1], dim=-1)  # one backward node for all six maps
    return dict(zip(("colors", "normals", "depth", "alpha", "distort", "median"), parts))
