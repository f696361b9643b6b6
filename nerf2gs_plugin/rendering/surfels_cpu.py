"""The C++/OpenMP 2DGS compositing kernel (``csrc/surfels.cpp``) behind a torch autograd Function.

Projection, SH and tile binning stay in torch (per surfel, cheap); only the per-pixel loop, where
the time goes, runs in C++, forward and backward. It computes exactly what
:func:`surfels_torch.composite_surfels_torch` computes (the tests compare values and gradients).
"""

from __future__ import annotations

from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.rendering.backend import extension_error, load_extension
from nerf2gs_plugin.rendering.surfels_torch import SurfelProjection, TileLists, _adjugate, _det

EXT_NAME = "nerf2gs_surfels"
EXT_SOURCES = ["surfels.cpp"]
EXT_HEADERS: list[str] = []  # the kernel is self-contained


def extension() -> Optional[Any]:
    """The compiled kernel (built on first use, cached under ``TORCH_EXTENSIONS_DIR``), or None."""
    return load_extension(EXT_NAME, EXT_SOURCES, EXT_HEADERS)


def available() -> bool:
    return extension() is not None


def error() -> Optional[str]:
    return extension_error(EXT_NAME)


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx: Any, adj: Tensor, det: Tensor, m2: Tensor, zc: Tensor, op: Tensor, feats: Tensor,
                densify: Tensor, box: Tensor, ids: Tensor, starts: Tensor, counts: Tensor, dims: tuple) -> Tensor:
        ext = extension()
        out, auxf, auxi = ext.forward(adj, det, m2, zc, op, box, feats, ids, starts, counts, *dims)
        ctx.save_for_backward(adj, det, m2, zc, op, box, feats, ids, starts, counts, out, auxf, auxi)
        ctx.dims = dims
        return out

    @staticmethod
    def backward(ctx: Any, gout: Tensor) -> tuple:
        adj, det, m2, zc, op, box, feats, ids, starts, counts, out, auxf, auxi = ctx.saved_tensors
        g = extension().backward(adj, det, m2, zc, op, box, feats, ids, starts, counts, *ctx.dims, out, auxf, auxi,
                                 gout.contiguous())
        F = feats.shape[1]
        return (g[:, 0:9], g[:, 9], g[:, 10:12], g[:, 12], g[:, 13], g[:, 16:16 + F], g[:, 14:16],
                None, None, None, None, None)


def composite_surfels_cpu(proj: SurfelProjection, lists: TileLists, opacities: Tensor, colors: Tensor,
                          width: int, height: int, near_plane: float,
                          densify: Optional[Tensor] = None) -> dict[str, Tensor]:
    """Same contract as :func:`surfels_torch.composite_surfels_torch`, computed by the C++ kernel."""
    C, N = proj.radii.shape
    D = colors.shape[-1]
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
                           lists.starts.contiguous(), lists.counts.contiguous(), dims)
    parts = out.split([D, 3, 1, 1, 1, 1], dim=-1)  # one backward node for all six maps
    return dict(zip(("colors", "normals", "depth", "alpha", "distort", "median"), parts))
