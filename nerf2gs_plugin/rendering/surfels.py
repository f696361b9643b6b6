"""2DGS surfel rasterization: the public entry :func:`rasterize_surfels` and its backends.

Backends: ``torch`` (the pure-torch reference in :mod:`surfels_torch`, autograd), ``cpu`` (the
C++/OpenMP kernels in :mod:`surfels_cpu` when they build: projection + SH, tile lists and
compositing, differentiable; projection stays in torch when the cameras need gradients;
otherwise the torch path with a one-line warning) and ``gsplat`` (``gsplat.rasterization_2dgs`` on CUDA; imported only there).
``"auto"`` picks gsplat on CUDA when importable, else cpu/torch as above.

Differences of the gsplat backend, which follows its own conventions: its depth channel is the
surfels' centre depth (ours: the ray-surfel intersection depth), its distortion is the L1 form
(ours: the L2 form of the 2DGS code on camera z) and its surface normals come from its own
depth_to_normal; both normal maps are converted to the camera frame here.
"""

from __future__ import annotations

from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.rendering.backend import backend_function, resolve_backend
from nerf2gs_plugin.rendering.projection import camera_centers
from nerf2gs_plugin.rendering.sh import eval_sh
from nerf2gs_plugin.rendering.surfels_cpu import (
    composite_surfels_cpu,
    project_surfels_cpu,
    tile_lists_cpu,
)
from nerf2gs_plugin.rendering.surfels_torch import (
    build_tile_lists,
    composite_surfels_torch,
    depth_to_normals,
    project_surfels,
)

RENDER_MODES = ("RGB", "D", "ED", "RGB+D", "RGB+ED")


def _check(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, viewmats: Tensor,
           Ks: Tensor, sh_degree: Optional[int], render_mode: str) -> None:
    n = means.shape[0]
    if means.shape != (n, 3) or quats.shape != (n, 4) or scales.shape != (n, 3) or opacities.shape != (n,):
        raise ValueError(f"surfel shapes disagree: means {tuple(means.shape)}, quats {tuple(quats.shape)}, "
                         f"scales {tuple(scales.shape)}, opacities {tuple(opacities.shape)}")
    c = viewmats.shape[0]
    if viewmats.shape != (c, 4, 4) or Ks.shape != (c, 3, 3):
        raise ValueError(f"camera shapes disagree: viewmats {tuple(viewmats.shape)}, Ks {tuple(Ks.shape)}")
    if sh_degree is not None:
        if colors.dim() != 3 or colors.shape[0] != n or colors.shape[-2] < (sh_degree + 1) ** 2:
            raise ValueError(f"SH degree {sh_degree} needs colors [N, >= {(sh_degree + 1) ** 2}, 3], got {tuple(colors.shape)}")
    elif not ((colors.dim() == 2 and colors.shape[0] == n) or (colors.dim() == 3 and colors.shape[:2] == (c, n))):
        raise ValueError(f"colors must be [N, D] or [C, N, D] without sh_degree, got {tuple(colors.shape)}")
    if render_mode not in RENDER_MODES:
        raise ConfigError(f"unknown render_mode {render_mode!r}; choose one of {', '.join(RENDER_MODES)}")


def rasterize_surfels(
    means: Tensor,
    quats: Tensor,
    scales: Tensor,
    opacities: Tensor,
    colors: Tensor,
    viewmats: Tensor,
    Ks: Tensor,
    width: int,
    height: int,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    sh_degree: Optional[int] = None,
    backgrounds: Optional[Tensor] = None,
    render_mode: str = "RGB+ED",
    backend: str = "auto",
    tile_size: int = 16,
    densify_signal: str = "lowpass",
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, dict[str, Any]]:
    """Render 2D Gaussian surfels into C cameras (differentiable w.r.t. all surfel parameters).

    Inputs: ``means [N,3]``, ``quats [N,4]`` wxyz, ``scales [N,3]`` activated (the third, the
    normal axis, is ignored), ``opacities [N]``, ``colors [N,K,3]`` SH coefficients when
    ``sh_degree`` is set else ``[N,D]``/``[C,N,D]`` features, ``viewmats [C,4,4]`` world->camera
    (OpenCV), ``Ks [C,3,3]``; ``backgrounds [C,D]`` or ``[D]`` for the colour channels.

    Returns ``render [C,H,W,X]`` (X = D, 1 or D+1 per ``render_mode``; "ED" depth is normalised by
    alpha, "D" is accumulated), ``alpha [C,H,W,1]``, ``normals [C,H,W,3]`` (alpha-weighted,
    camera frame, facing the camera), ``surf_normals [C,H,W,3]`` (from the expected depth's finite
    differences, camera frame, unit or zero), ``distort [C,H,W,1]``, ``median [C,H,W,1]`` (depth
    where transmittance crosses 0.5; 0 where empty) and ``meta`` with ``means2d [C,N,2]``
    (projected centres, in the graph), ``gradient_2dgs [C,N,2]`` (zeros whose ``.grad`` is 2DGS's
    densification signal; None without autograd), ``radii [C,N]``, ``depths [C,N]``, ``width``,
    ``height``, ``tile_size``, ``n_cameras``, ``backend``.

    ``densify_signal`` defines ``gradient_2dgs`` on the cpu/torch backends: ``"lowpass"`` as if each
    surfel were the screen-space low-pass Gaussian about its centre (large for large surfels),
    ``"screen"`` the gradient of the surfel moved rigidly on screen (the projected centre's gradient
    in 3DGS's sense; 2DGS and gsplat take ``dL/dT`` of the centre column times depth: on an H100
    their norms correlate 0.96 with ours, mean ratio 0.99, tests/rendering/test_gsplat_backend.py).
    gsplat always uses its own.
    """
    if densify_signal not in ("lowpass", "screen"):
        raise ValueError(f"densify_signal must be 'lowpass' or 'screen', got {densify_signal!r}")
    _check(means, quats, scales, opacities, colors, viewmats, Ks, sh_degree, render_mode)
    chosen = resolve_backend(backend, means.device.type, "surfels")
    return backend_function(chosen, "surfels")(
        means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane=near_plane, far_plane=far_plane,
        sh_degree=sh_degree, backgrounds=backgrounds, render_mode=render_mode, tile_size=tile_size,
        densify_signal=densify_signal)


def rasterize_surfels_cpu(*args: Any, **kwargs: Any) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, dict[str, Any]]:
    """The ``cpu`` backend (C++/OpenMP kernels); :func:`rasterize_surfels`' arguments, no ``backend``."""
    return _rasterize_local(*args, chosen="cpu", **kwargs)


def rasterize_surfels_torch(*args: Any, **kwargs: Any) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, dict[str, Any]]:
    """The ``torch`` reference backend; :func:`rasterize_surfels`' arguments, no ``backend``."""
    return _rasterize_local(*args, chosen="torch", **kwargs)


def _rasterize_local(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, viewmats: Tensor, Ks: Tensor,
    width: int, height: int, near_plane: float, far_plane: float, sh_degree: Optional[int],
    backgrounds: Optional[Tensor], render_mode: str, tile_size: int, densify_signal: str, chosen: str,
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, dict[str, Any]]:
    """The cpu and torch backends: projection, tile lists and compositing in C++ or in torch."""
    C, N = viewmats.shape[0], means.shape[0]
    cams_grad = torch.is_grad_enabled() and (viewmats.requires_grad or Ks.requires_grad)
    if chosen == "cpu" and not cams_grad and (sh_degree is None or sh_degree <= 3):
        # projection + SH + tile lists in C++ (with a C++ backward): the torch ops cost more than compositing
        use_sh = sh_degree is not None
        proj, feats = project_surfels_cpu(means, quats, scales, opacities, viewmats, Ks, width, height, near_plane,
                                          far_plane, sh=colors if use_sh else None, sh_degree=sh_degree or 0)
        if not use_sh:
            feats = colors if colors.dim() == 3 else colors[None].expand(C, -1, -1)
        lists = tile_lists_cpu(proj, width, height, tile_size)
    else:
        proj = project_surfels(means, quats, scales, opacities, viewmats, Ks, width, height, near_plane, far_plane)
        if sh_degree is not None:
            dirs = means[None, :, :] - camera_centers(viewmats)[:, None, :]
            feats = eval_sh(sh_degree, colors[None], dirs)  # [C,N,3]
        else:
            feats = colors if colors.dim() == 3 else colors[None].expand(C, -1, -1)
        lists = build_tile_lists(proj, width, height, tile_size)
    grad_on = torch.is_grad_enabled() and any(
        t.requires_grad for t in (means, quats, scales, opacities, colors, viewmats))
    densify = torch.zeros(C, N, 2, device=means.device, dtype=means.dtype, requires_grad=True) if grad_on else None
    if chosen == "cpu":
        maps = composite_surfels_cpu(proj, lists, opacities, feats, width, height, near_plane, densify, densify_signal)
    else:
        maps = composite_surfels_torch(proj, lists, opacities, feats, width, height, near_plane, densify, densify_signal)
    alpha = maps["alpha"]
    rgb = maps["colors"]
    if backgrounds is not None:
        bg = backgrounds if backgrounds.dim() == 2 else backgrounds[None].expand(C, -1)
        rgb = rgb + (1.0 - alpha) * bg[:, None, None, :]
    expected = maps["depth"] / alpha.clamp_min(1e-10)
    surf_normals = depth_to_normals(expected, Ks)
    depth_ch = expected if render_mode.endswith("ED") else maps["depth"]
    if render_mode in ("RGB",):
        render = rgb
    elif render_mode in ("D", "ED"):
        render = depth_ch
    else:
        render = torch.cat([rgb, depth_ch], dim=-1)
    meta = {"means2d": proj.means2d, "gradient_2dgs": densify, "radii": proj.radii, "depths": proj.depths,
            "width": width, "height": height, "tile_size": tile_size, "n_cameras": C, "backend": chosen,
            "n_pairs": int(lists.flat_ids.numel())}
    return render, alpha, maps["normals"], surf_normals, maps["distort"], maps["median"], meta
