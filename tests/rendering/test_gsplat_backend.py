"""The ``gsplat`` backends (3DGS and 2DGS) against our ``cpu`` kernels on the same street scene.

Runs only where CUDA is usable and gsplat imports (skipped on CPU machines, CI included); there it
checks that the CUDA path renders what the CPU path renders and sends the same gradients back, so a
model trained on a GPU is the model the CPU tests describe. gsplat culls a Gaussian at a slightly
smaller radius than ours (opacity-aware), so pixels may differ by a few 1/255 where a faint tail
is cut; the tolerances are set for that, not for bit equality.
"""

from __future__ import annotations

import pytest
import torch

from nerf2gs_bench.raster import street_scene
from nerf2gs_plugin.rendering import rasterize_gaussians, rasterize_surfels
from nerf2gs_plugin.rendering.backend import gsplat_available

pytestmark = pytest.mark.skipif(not gsplat_available(), reason="needs CUDA and gsplat")

PARAMS = ("means", "quats", "scales", "opacities", "colors")


def _scene(n: int = 3000, w: int = 160, h: int = 90) -> dict:
    scene = street_scene(n, w, h, seed=3)
    # a second camera, moved sideways and forward: batched cameras must agree too
    vm = torch.eye(4).repeat(2, 1, 1)
    vm[1, 0, 3], vm[1, 2, 3] = 0.8, -2.0
    return {**scene, "viewmats": vm, "Ks": scene["Ks"].repeat(2, 1, 1)}


def _run(fn, scene: dict, device: str, backend: str, grad_key: str, **kw):
    """Render on ``device`` with ``backend``; returns outputs and the gradients of a fixed random weighting."""
    leaves = {k: scene[k].to(device).clone().requires_grad_(True) for k in PARAMS}
    rest = {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in scene.items() if k not in PARAMS}
    outs = fn(**leaves, **rest, backend=backend, **kw)
    meta = outs[-1]
    assert meta["backend"] == backend
    meta[grad_key].retain_grad()
    maps = [o for o in outs[:-1] if torch.is_tensor(o)]
    g = torch.Generator().manual_seed(0)
    loss = sum((m * torch.randn(m.shape, generator=g).to(device)).sum() for m in maps[:2])
    loss.backward()
    grads = {k: v.grad.cpu() for k, v in leaves.items()}
    # our 3DGS kernels take quaternions as unit (callers normalise), gsplat normalises inside: only the
    # gradient's component tangent to the unit sphere is defined by the renderer, compare that
    q = scene["quats"]
    grads["quats"] = grads["quats"] - (grads["quats"] * q).sum(-1, keepdim=True) * q
    grads["means2d"] = meta[grad_key].grad.cpu()
    return [m.detach().cpu() for m in maps], grads, meta


# 3DGS: the kernels compute the same thing up to float summation order (measured on an H100: images
# max |diff| 1.1e-5, gradients relative error 1.6e-5..3.6e-5, benchmarks/results/gpu/gpu_checks_log.txt);
# docs/methods.md cites these bounds. 2DGS: our surfel kernel and gsplat's differ in the low-pass blend, so
# only mean agreement and gradient direction are claimed.
TIGHT = dict(mean=1e-6, q999=2e-5, max=5e-5)
LOOSE = dict(mean=2e-3, q999=5e-2, max=None)


def _close_images(a: torch.Tensor, b: torch.Tensor, what: str, tol: dict = LOOSE) -> None:
    diff = (a - b).abs()
    print(f"{what}: mean |diff| {float(diff.mean()):.2e}, 99.9% {float(diff.flatten().quantile(0.999)):.2e}, "
          f"max {float(diff.max()):.2e}")
    assert float(diff.mean()) < tol["mean"], what
    assert float(diff.flatten().quantile(0.999)) < tol["q999"], what
    if tol["max"] is not None:
        assert float(diff.max()) < tol["max"], what


def _close_grads(ours: dict, ref: dict, skip: tuple[str, ...] = (), max_rel: float | None = None) -> None:
    for k, r in ref.items():
        if k in skip:
            continue
        o = ours[k]
        cos = torch.nn.functional.cosine_similarity(o.flatten().double(), r.flatten().double(), dim=0)
        rel = float((o - r).norm() / r.norm().clamp_min(1e-12))
        print(f"grad {k}: cosine {float(cos):.5f}, relative error {rel:.2e}")
        assert float(r.abs().max()) > 0, k
        assert float(cos) > 0.98, k
        if max_rel is not None:
            assert rel < max_rel, k


def test_gsplat_3dgs_matches_cpu() -> None:
    scene = _scene()
    kw = dict(render_mode="RGB+ED", backgrounds=torch.tensor([0.2, 0.4, 0.6]).repeat(2, 1))
    cpu_maps, cpu_grads, _ = _run(rasterize_gaussians, {**scene}, "cpu", "cpu", "means2d", **kw)
    kw["backgrounds"] = kw["backgrounds"].cuda()
    gs_maps, gs_grads, meta = _run(rasterize_gaussians, {**scene}, "cuda", "gsplat", "means2d", **kw)
    assert gs_maps[0].shape == cpu_maps[0].shape == (2, 90, 160, 4)
    assert float(cpu_maps[1].mean()) > 0.1  # the scene is not empty
    _close_images(gs_maps[0][..., :3], cpu_maps[0][..., :3], "3DGS rgb", TIGHT)
    _close_images(gs_maps[1], cpu_maps[1], "3DGS alpha", TIGHT)
    depth_rel = ((gs_maps[0][..., 3] - cpu_maps[0][..., 3]).abs() / cpu_maps[0][..., 3].clamp_min(1e-3)).median()
    assert float(depth_rel) < 1e-3
    assert meta["radii"].shape == (2, scene["means"].shape[0])
    _close_grads(gs_grads, cpu_grads, max_rel=1e-4)  # means2d included: the densification signal matches too


def _densify_norms(ours: torch.Tensor, ref: torch.Tensor) -> tuple[float, float]:
    """Correlation and mean ratio of per-surfel densification norms (what the strategy thresholds).

    gsplat 1.5 takes 2DGS's definition, ``dL/dM[0,2], dL/dM[1,2]`` (the ray transform's centre
    column) times depth, from the pixels where the surfel itself wins over the low-pass. Measured on
    an H100: on this street scene (mostly sub-pixel surfels, where the low-pass wins) correlation
    0.63, ratio 0.20 for both our signals; with surfels 6x larger our ``screen`` signal 0.959 / 0.992,
    ``lowpass`` 0.693 / 0.052."""
    a, b = ours.norm(dim=-1).flatten().double(), ref.norm(dim=-1).flatten().double()
    on = (a > 0) | (b > 0)
    corr = torch.corrcoef(torch.stack([a[on], b[on]]))[0, 1]
    ratio = a[on].mean() / b[on].mean()
    print(f"2DGS densification norms: correlation {float(corr):.3f}, mean ratio gsplat/cpu {float(ratio):.3f}")
    return float(corr), float(ratio)


def test_gsplat_2dgs_matches_cpu() -> None:
    scene = _scene()
    kw = dict(render_mode="RGB+ED")
    cpu_maps, cpu_grads, _ = _run(rasterize_surfels, {**scene}, "cpu", "cpu", "gradient_2dgs", **kw)
    gs_maps, gs_grads, meta = _run(rasterize_surfels, {**scene}, "cuda", "gsplat", "gradient_2dgs", **kw)
    rgb_c, alpha_c, normals_c = cpu_maps[0][..., :3], cpu_maps[1], cpu_maps[2]
    rgb_g, alpha_g, normals_g = gs_maps[0][..., :3], gs_maps[1], gs_maps[2]
    assert float(alpha_c.mean()) > 0.1
    _close_images(rgb_g, rgb_c, "2DGS rgb")
    _close_images(alpha_g, alpha_c, "2DGS alpha")
    _close_images(normals_g, normals_c, "2DGS normals (camera frame)")
    assert meta["radii"].shape == (2, scene["means"].shape[0])
    _close_grads(gs_grads, cpu_grads, skip=("means2d",))
    corr, ratio = _densify_norms(gs_grads["means2d"], cpu_grads["means2d"])
    assert corr > 0.5 and 0.1 < ratio < 10.0
    # most of these surfels are under a pixel, where the low-pass wins and both our signals coincide;
    # with surfels 6x larger the "screen" signal (the centre moved on screen, 2DGS's definition) and
    # the "lowpass" one part
    big = {**scene, "scales": scene["scales"] * 6.0}
    _, gs_big, _ = _run(rasterize_surfels, big, "cuda", "gsplat", "gradient_2dgs", **kw)
    for signal in ("lowpass", "screen"):
        _, ours, _ = _run(rasterize_surfels, big, "cpu", "cpu", "gradient_2dgs", densify_signal=signal, **kw)
        print(f"large surfels, {signal}:", end=" ")
        corr, ratio = _densify_norms(gs_big["means2d"], ours["means2d"])
        if signal == "screen":  # the same signal as gsplat's, up to its read of a partial sum
            assert corr > 0.9 and 0.8 < ratio < 1.25

