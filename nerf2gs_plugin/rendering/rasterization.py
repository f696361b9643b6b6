"""The 3DGS rasterization entry: :func:`rasterize_gaussians` (gsplat-style), three backends behind it.

Pipeline of the ``torch`` backend (the reference): EWA projection and SH colours in torch
(autograd) -> tile binning (vectorised torch, no gradients) -> per-tile front-to-back alpha
compositing in torch (:mod:`.composite_torch`). The ``cpu`` backend runs the same three stages in
the C++/OpenMP extension (``csrc/rasterize_gaussians.cpp``): projection fused with SH evaluation
and compositing each with a C++ backward behind an autograd Function, binning without gradients
(projection falls back to torch autograd when the cameras need gradients or SH degree > 3). On CUDA with gsplat
installed the whole call goes to ``gsplat.rasterization`` and its outputs are mapped to the same
shapes and meta keys.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.rendering.backend import backend_function, resolve_backend
from nerf2gs_plugin.rendering.composite_torch import composite_torch
from nerf2gs_plugin.rendering.projection import Projected, camera_centers, project_gaussians
from nerf2gs_plugin.rendering.sh import eval_sh
from nerf2gs_plugin.rendering.tiles import bin_gaussians
from nerf2gs_plugin.utils.extensions import load_extension

CSRC = Path(__file__).with_name("csrc")
EXT_NAME = "nerf2gs_rasterize_gaussians"
EXT_SOURCES = [CSRC / "rasterize_gaussians.cpp"]
EXT_HEADERS = [CSRC / h for h in ("gaussians_core.h", "binning_core.h", "projection_core.h", "projection_bwd.h", "sh_core.h")]
EXT_CFLAGS = ("-O3", "-fopenmp", "-march=native", "-fno-math-errno")
RENDER_MODES = ("RGB", "D", "ED", "RGB+D", "RGB+ED")
RASTERIZE_MODES = ("classic", "antialiased")


def load_kernel() -> Optional[Any]:
    """The compiled compositing kernel (built on first use), or None when it cannot be built."""
    return load_extension(EXT_NAME, EXT_SOURCES, EXT_HEADERS, EXT_CFLAGS)


class _ProjectCPU(torch.autograd.Function):
    """Projection + SH colours by the extension (forward and backward): means ``[N,3]``, quats ``[N,4]``,
    scales ``[N,3]``, SH ``[N,K,3]`` (or empty: no colours), cameras -> means2d, conics, depths, radii,
    compensations, cov2d, colours (radii and cov2d carry no gradient; cov2d only feeds binning)."""

    @staticmethod
    def forward(ctx, means, quats, scales, sh, viewmats, Ks, width, height, near_plane, far_plane, degree):  # type: ignore[override]
        ctx.set_materialize_grads(False)
        ctx.args = (int(width), int(height), float(near_plane), float(far_plane), int(degree))
        ctx.save_for_backward(means, quats, scales, sh, viewmats, Ks)
        out = load_kernel().project_forward(means, quats, scales, sh, viewmats, Ks, *ctx.args)
        ctx.mark_non_differentiable(out[3], out[5])
        return tuple(out)

    @staticmethod
    def backward(ctx, v_m2, v_con, v_dep, _v_radii, v_comp, _v_cov, v_col):  # type: ignore[override]
        means, quats, scales, sh, viewmats, Ks = ctx.saved_tensors
        c, n = viewmats.shape[0], means.shape[0]
        z = means.new_zeros
        v_m2 = v_m2.contiguous() if v_m2 is not None else z(c, n, 2)
        v_con = v_con.contiguous() if v_con is not None else z(c, n, 3)
        v_dep = v_dep.contiguous() if v_dep is not None else z(c, n)
        v_comp = v_comp.contiguous() if v_comp is not None else z(0)
        v_col = v_col.contiguous() if v_col is not None and sh.numel() > 0 else z(0)
        v_means, v_quats, v_scales, v_sh = load_kernel().project_backward(
            means, quats, scales, sh, viewmats, Ks, *ctx.args, v_m2, v_con, v_dep, v_comp, v_col)
        return v_means, v_quats, v_scales, (v_sh if sh.numel() > 0 else None), None, None, None, None, None, None, None


def project_cpu(
    means: Tensor, quats: Tensor, scales: Tensor, viewmats: Tensor, Ks: Tensor, width: int, height: int,
    near_plane: float = 0.01, far_plane: float = 1e10, sh: Optional[Tensor] = None, sh_degree: int = 0,
) -> tuple[Projected, Optional[Tensor]]:
    """:func:`project_gaussians` (+ :func:`eval_sh` of ``sh [N,K,3]`` at ``sh_degree`` <= 3 when given)
    by the extension, differentiable w.r.t. means, quats, scales and SH (not the cameras) ->
    (projection, colours ``[C,N,3]`` or None)."""
    dt = means.dtype
    use_sh = sh is not None
    sh_t = sh.to(dt).contiguous() if use_sh else means.new_zeros(0)
    m2, con, dep, radii, comp, cov, cols = _ProjectCPU.apply(
        means.contiguous(), quats.to(dt).contiguous(), scales.to(dt).contiguous(), sh_t,
        viewmats.to(dt).contiguous(), Ks.to(dt).contiguous(), width, height, near_plane, far_plane, sh_degree if use_sh else 0)
    return Projected(means2d=m2, conics=con, depths=dep, radii=radii, compensations=comp, cov2d=cov), (cols if use_sh else None)


class _SHCPU(torch.autograd.Function):
    """SH colours by the extension: dirs ``[C, N, 3]`` (unnormalised), coeffs ``[N, K, 3]`` -> ``[C, N, 3]``."""

    @staticmethod
    def forward(ctx, degree, dirs, coeffs):  # type: ignore[override]
        ctx.degree = degree
        ctx.save_for_backward(dirs, coeffs)
        return load_kernel().sh_forward(degree, dirs, coeffs)

    @staticmethod
    def backward(ctx, v_colors):  # type: ignore[override]
        dirs, coeffs = ctx.saved_tensors
        v_coeffs, v_dirs = load_kernel().sh_backward(ctx.degree, dirs, coeffs, v_colors.contiguous())
        return None, v_dirs, v_coeffs


class _CompositeCPU(torch.autograd.Function):
    """C++ tile compositing; gradients wrt means2d, conics, colours/features and opacities."""

    @staticmethod
    def forward(ctx, means2d, conics, colors, opacities, offsets, ids, n_cams, width, height, tile_size, with_median):  # type: ignore[override]
        ext = load_kernel()
        need_last = any(ctx.needs_input_grad[:4])  # only backward reads the last-composited indices
        render, alpha, last, median = ext.forward(means2d, conics, colors, opacities, offsets, ids, n_cams, height, width,
                                                  tile_size, need_last, with_median)
        ctx.save_for_backward(means2d, conics, colors, opacities, offsets, ids, alpha, last)
        ctx.dims = (n_cams, height, width, tile_size)
        ctx.mark_non_differentiable(median)
        return render, alpha, median

    @staticmethod
    def backward(ctx, v_render, v_alpha, _v_median):  # type: ignore[override]
        means2d, conics, colors, opacities, offsets, ids, alpha, last = ctx.saved_tensors
        v_m, v_c, v_col, v_o = load_kernel().backward(
            means2d, conics, colors, opacities, offsets, ids, alpha, last,
            v_render.contiguous(), v_alpha.contiguous(), *ctx.dims,
        )
        return v_m, v_c, v_col, v_o, None, None, None, None, None, None, None


def composite(
    means2d: Tensor, conics: Tensor, colors: Tensor, opacities: Tensor, tile_offsets: Tensor, flat_ids: Tensor,
    n_cams: int, width: int, height: int, tile_size: int, backend: str, with_median: bool = True,
) -> tuple[Tensor, Tensor, Tensor]:
    """Composite flattened pairs (``[CN, 2]``, ``[CN, 3]``, ``[CN, D]``, ``[CN]``) with ``backend``
    ``"cpu"`` or ``"torch"`` -> render ``[C,H,W,D]``, alpha ``[C,H,W]``, median ids ``[C,H,W]`` (all -1 from
    the cpu kernel unless ``with_median``)."""
    if backend == "cpu":
        return _CompositeCPU.apply(means2d.contiguous(), conics.contiguous(), colors.contiguous(), opacities.contiguous(),
                                   tile_offsets, flat_ids, n_cams, width, height, tile_size, with_median)
    return composite_torch(means2d, conics, colors, opacities, tile_offsets, flat_ids, n_cams, width, height, tile_size)


def rasterize_gaussians(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
    viewmats: Tensor, Ks: Tensor, width: int, height: int,
    near_plane: float = 0.01, far_plane: float = 1e10, sh_degree: Optional[int] = None,
    backgrounds: Optional[Tensor] = None, render_mode: str = "RGB", rasterize_mode: str = "classic",
    backend: str = "auto", tile_size: int = 16, return_median: bool = False,
) -> tuple[Tensor, Tensor, dict[str, Any]]:
    """Render ``N`` 3D Gaussians into ``C`` pinhole cameras (differentiable).

    Args:
        means: ``[N, 3]`` world positions.
        quats: ``[N, 4]`` rotations, wxyz, normalised.
        scales: ``[N, 3]`` standard deviations along the rotated axes (activated, > 0).
        opacities: ``[N]`` in [0, 1].
        colors: with ``sh_degree`` set, SH coefficients ``[N, K, 3]`` (``K >= (sh_degree+1)^2``,
            only the first ``(sh_degree+1)^2`` used); else plain features ``[N, D]`` or ``[C, N, D]``.
        viewmats: ``[C, 4, 4]`` world-to-camera, OpenCV axes (x right, y down, z forward).
        Ks: ``[C, 3, 3]`` intrinsics.
        width, height: image size in pixels.
        near_plane, far_plane: camera-space z range; Gaussians outside contribute nothing.
        sh_degree: SH degree to evaluate (0-3), or None for plain features.
        backgrounds: ``[C, D]`` colour composited behind (colour channels only).
        render_mode: ``"RGB"`` (features), ``"D"`` (accumulated depth sum w z), ``"ED"`` (expected
            depth sum w z / alpha), ``"RGB+D"``, ``"RGB+ED"`` (depth as the last channel).
        rasterize_mode: ``"classic"`` or ``"antialiased"`` (opacities times the eps2d compensation).
        backend: ``"auto"``, ``"cpu"``, ``"torch"`` or ``"gsplat"`` (see :mod:`.backend`).
        tile_size: tile edge in pixels.
        return_median: also return ``meta["median_depth"]`` ``[C, H, W, 1]``: the depth of the last
            Gaussian composited while the transmittance was above 0.5 (0 where none).
    Returns:
        render ``[C, H, W, D]`` (``D+1`` for ``RGB+D``/``RGB+ED``, 1 for ``D``/``ED``), alpha
        ``[C, H, W, 1]``, and meta with ``means2d [C, N, 2]`` (pixels; a non-leaf tensor in the graph:
        ``retain_grad()`` it for densification), ``radii [C, N]`` int32 (0 = not visible),
        ``depths [C, N]``, ``conics [C, N, 3]``, ``opacities [C, N]`` (as composited),
        ``tile_offsets``, ``flat_ids``, ``width``, ``height``, ``tile_size``, ``n_cameras``,
        ``backend`` (the one that ran) and, if asked, ``median_depth``.
    """
    if render_mode not in RENDER_MODES:
        raise ConfigError(f"unknown render_mode {render_mode!r}; choose one of {', '.join(RENDER_MODES)}")
    if rasterize_mode not in RASTERIZE_MODES:
        raise ConfigError(f"unknown rasterize_mode {rasterize_mode!r}; choose one of {', '.join(RASTERIZE_MODES)}")
    if not 1 <= int(tile_size) <= 64:
        raise ConfigError(f"tile_size must be in 1..64, got {tile_size}")
    n, n_cams = means.shape[0], viewmats.shape[0]
    if quats.shape != (n, 4) or scales.shape != (n, 3) or opacities.shape != (n,) or Ks.shape != (n_cams, 3, 3):
        raise ValueError(f"shape mismatch: means {tuple(means.shape)}, quats {tuple(quats.shape)}, scales "
                         f"{tuple(scales.shape)}, opacities {tuple(opacities.shape)}, Ks {tuple(Ks.shape)}")
    chosen = resolve_backend(backend, means.device.type, "gaussians")
    return backend_function(chosen, "gaussians")(
        means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane=near_plane, far_plane=far_plane,
        sh_degree=sh_degree, backgrounds=backgrounds, render_mode=render_mode, rasterize_mode=rasterize_mode,
        tile_size=tile_size, return_median=return_median)


def rasterize_gaussians_cpu(*args: Any, **kwargs: Any) -> tuple[Tensor, Tensor, dict[str, Any]]:
    """The ``cpu`` backend (C++/OpenMP kernels); :func:`rasterize_gaussians`' arguments, no ``backend``."""
    return _rasterize_local(*args, chosen="cpu", **kwargs)


def rasterize_gaussians_torch(*args: Any, **kwargs: Any) -> tuple[Tensor, Tensor, dict[str, Any]]:
    """The ``torch`` reference backend; :func:`rasterize_gaussians`' arguments, no ``backend``."""
    return _rasterize_local(*args, chosen="torch", **kwargs)


def _rasterize_local(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, viewmats: Tensor, Ks: Tensor,
    width: int, height: int, near_plane: float, far_plane: float, sh_degree: Optional[int],
    backgrounds: Optional[Tensor], render_mode: str, rasterize_mode: str, tile_size: int, return_median: bool,
    chosen: str,
) -> tuple[Tensor, Tensor, dict[str, Any]]:
    """The cpu and torch backends: the same three stages, in C++ or in torch."""
    n, n_cams = means.shape[0], viewmats.shape[0]
    cams_grad = torch.is_grad_enabled() and (viewmats.requires_grad or Ks.requires_grad)
    if chosen == "cpu" and not cams_grad and (sh_degree or 0) <= 3:  # one C++ pass instead of ~100 torch ops
        proj, opac, feats = _project_fused(means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane,
                                           far_plane, sh_degree, rasterize_mode, render_mode)
    else:
        proj = project_gaussians(means, quats, scales, viewmats, Ks, width, height, near_plane, far_plane)
        opac = opacities[None].expand(n_cams, n)
        if rasterize_mode == "antialiased":
            opac = opac * proj.compensations
        feats = _features(colors, sh_degree, means, viewmats, n_cams, render_mode, fused=chosen == "cpu")  # [C, N, D']
    depth_ch = proj.depths[..., None]
    if render_mode in ("D", "ED"):
        feats = depth_ch
    elif render_mode in ("RGB+D", "RGB+ED"):
        feats = torch.cat([feats, depth_ch], dim=-1)
    n_color = feats.shape[-1] - (1 if render_mode != "RGB" else 0)

    binning = load_kernel().bin_gaussians if chosen == "cpu" else bin_gaussians
    offsets, ids = binning(proj.means2d.detach().contiguous(), proj.cov2d.detach().contiguous(), opac.detach().contiguous(),
                           proj.depths.detach().contiguous(), proj.radii.contiguous(), width, height, tile_size)
    render, alpha, median_ids = composite(
        proj.means2d.reshape(-1, 2), proj.conics.reshape(-1, 3), feats.reshape(n_cams * n, feats.shape[-1]), opac.reshape(-1),
        offsets, ids, n_cams, width, height, tile_size, chosen, with_median=return_median,
    )
    alpha = alpha[..., None]  # [C, H, W, 1]
    if render_mode in ("ED", "RGB+ED"):
        render = torch.cat([render[..., :-1], render[..., -1:] / alpha.clamp_min(1e-10)], dim=-1)
    if backgrounds is not None and n_color > 0:
        bg = backgrounds.reshape(n_cams, 1, 1, -1)
        if bg.shape[-1] != n_color:
            raise ValueError(f"backgrounds have {bg.shape[-1]} channels, the render has {n_color}")
        render = torch.cat([render[..., :n_color] + (1.0 - alpha) * bg, render[..., n_color:]], dim=-1)
    meta: dict[str, Any] = {
        "means2d": proj.means2d, "radii": proj.radii, "depths": proj.depths, "conics": proj.conics,
        "opacities": opac, "tile_offsets": offsets, "flat_ids": ids, "width": width, "height": height,
        "tile_size": tile_size, "n_cameras": n_cams, "backend": chosen,
    }
    if return_median:
        flat_depth = torch.cat([proj.depths.reshape(-1), proj.depths.new_zeros(1)])  # index -1 -> 0
        meta["median_depth"] = flat_depth[median_ids][..., None]
    return render, alpha, meta


def _project_fused(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, viewmats: Tensor, Ks: Tensor,
    width: int, height: int, near_plane: float, far_plane: float, sh_degree: Optional[int], rasterize_mode: str,
    render_mode: str,
) -> tuple[Projected, Tensor, Tensor]:
    """The cpu backend's projection (+ SH colours) by the C++ extension with its C++ backward,
    numerically the same as :func:`project_gaussians` + :func:`eval_sh`."""
    n_cams, n = viewmats.shape[0], means.shape[0]
    use_sh = sh_degree is not None and render_mode not in ("D", "ED")
    if use_sh and (colors.dim() != 3 or colors.shape[0] != n or colors.shape[-1] != 3):
        raise ValueError(f"SH colours must be [N, K, 3], got {tuple(colors.shape)}")
    if use_sh and colors.shape[1] < (sh_degree + 1) ** 2:
        raise ValueError(f"SH degree {sh_degree} needs {(sh_degree + 1) ** 2} coefficients, got {colors.shape[1]}")
    proj, cols = project_cpu(means, quats, scales, viewmats, Ks, width, height, near_plane, far_plane,
                             sh=colors if use_sh else None, sh_degree=int(sh_degree or 0))
    opac = opacities[None].expand(n_cams, n)
    if rasterize_mode == "antialiased":
        opac = opac * proj.compensations
    feats = cols if use_sh else _features(colors, None if render_mode in ("D", "ED") else sh_degree, means, viewmats, n_cams, render_mode)
    return proj, opac, feats


def _features(
    colors: Tensor, sh_degree: Optional[int], means: Tensor, viewmats: Tensor, n_cams: int, render_mode: str,
    fused: bool = False,
) -> Tensor:
    """Per camera and Gaussian features ``[C, N, D]``: SH evaluated along mean - camera centre, or as given."""
    n = means.shape[0]
    if render_mode in ("D", "ED"):
        return means.new_zeros(n_cams, n, 0)
    if sh_degree is not None:
        if colors.dim() != 3 or colors.shape[0] != n or colors.shape[-1] != 3:
            raise ValueError(f"SH colours must be [N, K, 3], got {tuple(colors.shape)}")
        dirs = means[None] - camera_centers(viewmats)[:, None]  # [C, N, 3]
        if fused and not viewmats.requires_grad and 0 <= sh_degree <= 3 and dirs.dtype == colors.dtype:
            return _SHCPU.apply(int(sh_degree), dirs.contiguous(), colors.contiguous())
        return eval_sh(sh_degree, colors, dirs)
    if colors.dim() == 2 and colors.shape[0] == n:
        return colors[None].expand(n_cams, n, colors.shape[-1])
    if colors.dim() == 3 and colors.shape[:2] == (n_cams, n):
        return colors
    raise ValueError(f"colours must be [N, D] or [C, N, D] (or [N, K, 3] with sh_degree), got {tuple(colors.shape)}")
