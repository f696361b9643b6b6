"""3DGS rasterizer: cpu kernel vs torch reference, gradcheck, analytic cases, fallback."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from nerf2gs_plugin.rendering import backend as backend_mod
from nerf2gs_plugin.rendering import rasterize_gaussians
from nerf2gs_plugin.rendering.composite_torch import composite_torch
from nerf2gs_plugin.rendering.rasterization import load_kernel
from nerf2gs_plugin.rendering.sh import eval_sh
from nerf2gs_plugin.rendering.tiles import bin_gaussians
from nerf2gs_plugin.rendering.projection import project_gaussians

needs_kernel = pytest.mark.skipif(load_kernel() is None, reason="C++ rasterizer could not be built here")


def _scene(n: int, n_cams: int = 2, w: int = 40, h: int = 30, k: int = 16, dtype=torch.float32, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) * torch.tensor([1.0, 0.7, 1.0]) + torch.tensor([0.0, 0.0, 4.0])
    quats = torch.nn.functional.normalize(torch.randn(n, 4, generator=g), dim=-1)
    scales = torch.rand(n, 3, generator=g) * 0.3 + 0.02
    opac = torch.rand(n, generator=g)
    colors = torch.randn(n, k, 3, generator=g) * 0.5
    viewmats = torch.eye(4).repeat(n_cams, 1, 1)
    viewmats[1:, 0, 3] = 0.3
    ks = torch.tensor([[40.0, 0, w / 2], [0, 40.0, h / 2], [0, 0, 1]]).repeat(n_cams, 1, 1)
    cast = [t.to(dtype) for t in (means, quats, scales, opac, colors, viewmats, ks)]
    return cast + [w, h]


def _render_and_grads(backend: str, scene, **kw):
    leaves = [t.clone().requires_grad_(True) for t in scene[:5]]
    render, alpha, meta = rasterize_gaussians(*leaves, *scene[5:], backend=backend, return_median=True, **kw)
    meta["means2d"].retain_grad()
    weights = torch.linspace(-1.0, 1.0, render.numel(), dtype=render.dtype).reshape(render.shape)
    loss = (render * weights).sum() + 0.3 * (alpha**2).sum() + 0.1 * meta["median_depth"].sum()
    loss.backward()
    return render.detach(), alpha.detach(), meta, [t.grad for t in leaves]


def _rel(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(((a - b).abs().max() / (b.abs().max() + 1e-12)).detach())


@needs_kernel
@pytest.mark.parametrize("sh_degree", [0, 1, 2, 3])
@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_cpu_matches_torch_forward_and_gradients(sh_degree: int, mode: str) -> None:
    scene = _scene(120, seed=sh_degree)
    bg = torch.tensor([[0.1, 0.2, 0.3], [0.9, 0.5, 0.0]])
    kw = dict(sh_degree=sh_degree, rasterize_mode=mode, render_mode="RGB+ED", backgrounds=bg)
    rc, ac, mc, gc = _render_and_grads("cpu", scene, **kw)
    rt, at, mt, gt = _render_and_grads("torch", scene, **kw)
    assert mc["backend"] == "cpu" and mt["backend"] == "torch"
    assert rc.shape == (2, 30, 40, 4) and ac.shape == (2, 30, 40, 1)
    assert float(ac.max()) > 0.5  # the scene is not trivially empty
    assert _rel(rc, rt) < 1e-4 and _rel(ac, at) < 1e-4
    assert _rel(mc["median_depth"], mt["median_depth"]) < 1e-4
    assert _rel(mc["means2d"].grad, mt["means2d"].grad) < 1e-4
    for a, b in zip(gc, gt):
        assert a is not None and float(b.abs().max()) > 0
        assert _rel(a, b) < 1e-4


@needs_kernel
def test_cpu_matches_torch_plain_features_and_depth_modes() -> None:
    scene = _scene(80, seed=5)
    feats = torch.rand(80, 5)
    for mode in ("RGB", "D", "ED", "RGB+D"):
        s = scene[:4] + [feats] + scene[5:]
        rc, ac, _, gc = _render_and_grads("cpu", s, render_mode=mode)
        rt, at, _, gt = _render_and_grads("torch", s, render_mode=mode)
        assert rc.shape[-1] == {"RGB": 5, "D": 1, "ED": 1, "RGB+D": 6}[mode]
        assert _rel(rc, rt) < 1e-4 and _rel(ac, at) < 1e-4
        for a, b in zip(gc, gt):
            if b is not None:
                assert _rel(a, b) < 1e-4


def _smooth_scene(dtype=torch.float64):
    """Three large, half-transparent Gaussians covering a tiny image: no threshold is near, so
    finite differences see a smooth function."""
    means = torch.tensor([[0.0, 0.0, 3.0], [0.3, -0.2, 3.5], [-0.2, 0.3, 4.0]], dtype=dtype)
    quats = torch.nn.functional.normalize(torch.tensor([[1.0, 0.1, 0.2, 0.0], [0.9, 0.0, 0.3, 0.1], [1.0, -0.2, 0.0, 0.3]], dtype=dtype), dim=-1)
    scales = torch.tensor([[1.5, 2.0, 1.0], [2.0, 1.4, 1.2], [1.8, 1.7, 2.2]], dtype=dtype)
    opac = torch.tensor([0.5, 0.6, 0.4], dtype=dtype)
    colors = torch.tensor([[0.2, 0.7, 0.1], [0.9, 0.3, 0.5], [0.4, 0.4, 0.8]], dtype=dtype)
    viewmats = torch.eye(4, dtype=dtype)[None]
    ks = torch.tensor([[[10.0, 0, 6], [0, 10.0, 5], [0, 0, 1]]], dtype=dtype)
    return means, quats, scales, opac, colors, viewmats, ks


@pytest.mark.parametrize("backend", ["torch", pytest.param("cpu", marks=needs_kernel)])
def test_gradcheck_double(backend: str) -> None:
    means, quats, scales, opac, colors, viewmats, ks = _smooth_scene()

    def f(m, q, s, o, c):
        r, a, _ = rasterize_gaussians(m, q, s, o, c, viewmats, ks, 12, 10, render_mode="RGB+ED", backend=backend, tile_size=8)
        return r[:, ::3, ::3], a[:, ::3, ::3]

    inputs = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac, colors)]
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
@pytest.mark.parametrize("backend", ["torch", pytest.param("cpu", marks=needs_kernel)])
def test_isotropic_gaussian_profile(backend: str, mode: str) -> None:
    f, z, s, o, w, h = 50.0, 5.0, 0.2, 0.8, 33, 25
    means = torch.tensor([[0.0, 0.0, z]])
    ks = torch.tensor([[[f, 0, 16.5], [0, f, 12.5], [0, 0, 1]]])
    r, a, meta = rasterize_gaussians(
        means, torch.tensor([[1.0, 0, 0, 0]]), torch.full((1, 3), s), torch.tensor([o]), torch.ones(1, 3),
        torch.eye(4)[None], ks, w, h, render_mode="RGB+ED", rasterize_mode=mode, backend=backend,
    )
    var = (f * s / z) ** 2 + 0.3  # pixels^2, with the low-pass term
    peak = o * ((f * s / z) ** 2 / var if mode == "antialiased" else 1.0)
    yy, xx = torch.meshgrid(torch.arange(h) + 0.5, torch.arange(w) + 0.5, indexing="ij")
    expected = peak * torch.exp(-((xx - 16.5) ** 2 + (yy - 12.5) ** 2) / (2 * var))
    expected = torch.where(expected >= 1 / 255, expected, torch.zeros_like(expected))
    assert torch.allclose(a[0, ..., 0], expected, atol=1e-5)
    assert torch.allclose(r[0, ..., 0], expected, atol=1e-5)  # white Gaussian, no background
    covered = expected > 0
    assert torch.allclose(r[0, ..., 3][covered], torch.full_like(r[0, ..., 3][covered], z), rtol=1e-5)
    assert int(meta["radii"][0, 0]) == math.ceil(3 * math.sqrt(var))
    assert torch.allclose(meta["means2d"][0, 0], torch.tensor([16.5, 12.5]))


@pytest.mark.parametrize("backend", ["torch", pytest.param("cpu", marks=needs_kernel)])
def test_behind_camera_and_off_screen_contribute_nothing(backend: str) -> None:
    means, quats, scales, opac, colors, viewmats, ks, w, h = _scene(30, n_cams=1, k=1)
    extra = torch.tensor([[0.0, 0.0, -2.0], [0.0, 0.0, 0.005], [50.0, 0.0, 4.0], [0.0, -40.0, 4.0]])
    n_extra = extra.shape[0]
    big = torch.cat([means, extra]), torch.cat([quats, quats[:n_extra]]), torch.cat([scales, torch.full((n_extra, 3), 0.5)])
    kw = dict(sh_degree=0, backend=backend)
    r0, a0, _ = rasterize_gaussians(means, quats, scales, opac, colors, viewmats, ks, w, h, **kw)
    r1, a1, meta = rasterize_gaussians(*big, torch.cat([opac, torch.ones(n_extra)]), torch.cat([colors, torch.ones(n_extra, 1, 3)]),
                                       viewmats, ks, w, h, **kw)
    assert torch.equal(meta["radii"][0, -n_extra:], torch.zeros(n_extra, dtype=torch.int32))
    assert bool((meta["radii"][0, :-n_extra] > 0).any())
    assert torch.allclose(r0, r1) and torch.allclose(a0, a1)


@pytest.mark.parametrize("backend", ["torch", pytest.param("cpu", marks=needs_kernel)])
def test_empty_scene_renders_background(backend: str) -> None:
    bg = torch.tensor([[0.2, 0.4, 0.6]])
    e = torch.zeros(0, 3)
    r, a, meta = rasterize_gaussians(e, torch.zeros(0, 4), e, torch.zeros(0), e, torch.eye(4)[None],
                                     torch.tensor([[[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]]]), 16, 12,
                                     backgrounds=bg, render_mode="RGB+ED", backend=backend)
    assert r.shape == (1, 12, 16, 4) and meta["radii"].shape == (1, 0)
    assert torch.allclose(r[..., :3], bg.expand(12, 16, 3)[None]) and float(a.abs().max()) == 0.0
    assert float(r[..., 3].abs().max()) == 0.0


def test_torch_reference_is_chunk_invariant() -> None:
    """Tiny budgets force list chunks with the transmittance carried over: same image."""
    means, quats, scales, opac, colors, viewmats, ks, w, h = _scene(200, n_cams=1, k=1)
    opac = opac * 0.3 + 0.7  # dense enough for early termination
    proj = project_gaussians(means, quats, scales, viewmats, ks, w, h)
    o = opac[None].expand(1, -1)
    offsets, ids = bin_gaussians(proj.means2d, proj.cov2d, o, proj.depths, proj.radii, w, h, 16)
    args = (proj.means2d.reshape(-1, 2), proj.conics.reshape(-1, 3), colors[:, 0], o.reshape(-1), offsets, ids, 1, w, h, 16)
    r_big, a_big, m_big = composite_torch(*args)
    r_small, a_small, m_small = composite_torch(*args, budget=256 * 7)
    assert int((offsets[1:] - offsets[:-1]).max()) > 7
    assert torch.allclose(r_big, r_small, atol=1e-6) and torch.allclose(a_big, a_small, atol=1e-6)
    assert torch.equal(m_big, m_small)
    if load_kernel() is not None:
        r_cpu, a_cpu = load_kernel().forward(*[t.contiguous() for t in args[:6]], 1, h, w, 16, False, True)[:2]
        assert torch.allclose(r_cpu, r_big, atol=1e-5) and torch.allclose(a_cpu, a_big, atol=1e-5)


def test_missing_extension_falls_back_to_torch_with_warning(monkeypatch: pytest.MonkeyPatch) -> None:
    cpu = backend_mod.RASTER_BACKENDS["cpu"]
    monkeypatch.setitem(backend_mod.RASTER_BACKENDS, "cpu", dataclasses.replace(cpu, available=lambda kind: False))
    monkeypatch.setattr(backend_mod, "_WARNED", set())
    scene = _scene(20, n_cams=1, k=1)
    with pytest.warns(RuntimeWarning, match="torch reference"):
        r, _, meta = rasterize_gaussians(*scene, sh_degree=0, backend="auto")
    assert meta["backend"] == "torch"
    r_ref, _, _ = rasterize_gaussians(*scene, sh_degree=0, backend="torch")
    assert torch.equal(r, r_ref)


def test_eval_sh_uses_only_the_active_degree() -> None:
    coeffs = torch.randn(7, 16, 3)
    dirs = torch.randn(2, 7, 3)
    dc = eval_sh(0, coeffs, dirs)
    assert dc.shape == (2, 7, 3)
    assert torch.allclose(dc, torch.clamp_min(coeffs[:, 0] * 0.28209479177387814 + 0.5, 0).expand(2, 7, 3))
    assert not torch.allclose(eval_sh(3, coeffs, dirs), dc)


@needs_kernel
def test_cpu_binning_matches_torch_binning() -> None:
    means, quats, scales, opac, _, viewmats, ks, w, h = _scene(300, n_cams=2, k=1)
    proj = project_gaussians(means, quats, scales, viewmats, ks, w, h)
    o = (opac[None] * proj.compensations).contiguous()
    args = (proj.means2d.contiguous(), proj.cov2d.contiguous(), o, proj.depths.contiguous(), proj.radii.contiguous(), w, h, 8)
    off_t, ids_t = bin_gaussians(*args)
    off_c, ids_c = load_kernel().bin_gaussians(*args)
    assert ids_t.numel() > 300
    assert torch.equal(off_t, off_c) and torch.equal(ids_t, ids_c)


@needs_kernel
@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_fused_no_grad_path_matches_torch(mode: str) -> None:
    """Without gradients the cpu backend projects and evaluates SH in C++: the same projection to
    float rounding, hence the same images except where rounding flips a pair across the 1/255
    alpha cut-off (rare pixels)."""

    def nearly(a: torch.Tensor, b: torch.Tensor) -> bool:
        close = (a - b).abs() <= 1e-4 * b.abs().max()
        return float(close.float().mean()) > 0.995 and float((a - b).abs().mean()) < 1e-4 * float(b.abs().max())

    scene = _scene(150, seed=7)
    with torch.no_grad():
        for kw in (dict(sh_degree=3, render_mode="RGB+ED"), dict(sh_degree=1, render_mode="D")):
            rc, ac, mc = rasterize_gaussians(*scene, backend="cpu", rasterize_mode=mode, return_median=True, **kw)
            rt, at, mt = rasterize_gaussians(*scene, backend="torch", rasterize_mode=mode, return_median=True, **kw)
            assert nearly(rc, rt) and nearly(ac, at) and nearly(mc["median_depth"], mt["median_depth"])
            assert torch.equal(mc["radii"], mt["radii"]) and torch.equal(mc["flat_ids"], mt["flat_ids"])
            assert _rel(mc["means2d"], mt["means2d"]) < 1e-5 and _rel(mc["conics"], mt["conics"]) < 1e-4
        feats = torch.rand(150, 4)
        rc, _, _ = rasterize_gaussians(*scene[:4], feats, *scene[5:], backend="cpu", rasterize_mode=mode)
        rt, _, _ = rasterize_gaussians(*scene[:4], feats, *scene[5:], backend="torch", rasterize_mode=mode)
        assert rc.shape[-1] == 4 and nearly(rc, rt)


@needs_kernel
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_cpu_sh_matches_eval_sh_and_gradcheck(degree: int) -> None:
    from nerf2gs_plugin.rendering.rasterization import _SHCPU

    g = torch.Generator().manual_seed(degree)
    dirs = torch.randn(2, 6, 3, generator=g, dtype=torch.float64).requires_grad_(True)
    coeffs = (torch.randn(6, 16, 3, generator=g, dtype=torch.float64) * 0.3).requires_grad_(True)
    out = _SHCPU.apply(degree, dirs, coeffs)
    ref = eval_sh(degree, coeffs, dirs)
    assert torch.allclose(out, ref, atol=1e-12)
    w = torch.randn(2, 6, 3, generator=g, dtype=torch.float64)
    ga = torch.autograd.grad((out * w).sum(), (dirs, coeffs))
    gb = torch.autograd.grad((ref * w).sum(), (dirs, coeffs), allow_unused=True)  # degree 0 ignores dirs
    gb = [torch.zeros_like(t) if v is None else v for t, v in zip((dirs, coeffs), gb)]
    assert all(torch.allclose(a, b, atol=1e-10) for a, b in zip(ga, gb))
    assert torch.autograd.gradcheck(lambda d, c: _SHCPU.apply(degree, d, c), (dirs, coeffs), eps=1e-6, atol=1e-6)
