"""2DGS surfel rasterizer: analytic cases, gradients, the torch reference vs the C++ kernel."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.rendering import rasterize_surfels
from nerf2gs_plugin.utils.quaternions import quat_to_rotmat

W, H = 48, 40
F = 60.0


def _cam(dtype=torch.float32):
    K = torch.tensor([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1]], dtype=dtype)[None]
    return torch.eye(4, dtype=dtype)[None], K


def _quat_axis(axis, angle):
    a = torch.tensor(axis, dtype=torch.float32)
    a = a / a.norm()
    return torch.cat([torch.tensor([math.cos(angle / 2)]), a * math.sin(angle / 2)])


def _render(means, quats, scales, opac, colors, backend="torch", **kw):
    V, K = _cam(means.dtype)
    return rasterize_surfels(means, quats, scales, opac, colors, V, K, W, H, backend=backend, **kw)


def _random_scene(n, seed, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * torch.tensor([0.5, 0.4, 0.3], dtype=dtype)
    means[:, 2] += 3.0
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    quats = quats / quats.norm(dim=-1, keepdim=True)
    scales = torch.cat([torch.rand(n, 2, generator=g, dtype=dtype) * 0.3 + 0.1, torch.zeros(n, 1, dtype=dtype)], 1)
    opac = torch.rand(n, generator=g, dtype=dtype) * 0.8 + 0.1
    sh = torch.randn(n, 16, 3, generator=g, dtype=dtype) * 0.3
    return means, quats, scales, opac, sh


def test_single_facing_surfel_profile_normal_and_depth():
    z, s, o = 2.0, 0.25, 0.8
    means = torch.tensor([[0.0, 0.0, z]])
    out = _render(means, torch.tensor([[1.0, 0, 0, 0]]), torch.tensor([[s, s, 0.0]]), torch.tensor([o]),
                  torch.tensor([[1.0, 0.5, 0.25]]))
    render, alpha, normals, surf, distort, median, meta = out
    assert render.shape == (1, H, W, 4) and alpha.shape == (1, H, W, 1) and normals.shape == (1, H, W, 3)
    sigma_px = s * F / z
    ys, xs = torch.meshgrid(torch.arange(H) + 0.5, torch.arange(W) + 0.5, indexing="ij")
    r2 = ((xs - W / 2) ** 2 + (ys - H / 2) ** 2) / sigma_px**2
    expect = o * torch.exp(-0.5 * r2)
    inside = r2 < 4.0  # where the object-space Gaussian, not the low-pass, decides
    assert torch.allclose(alpha[0, ..., 0][inside], expect[inside], atol=1e-5)
    cut = r2 > 2 * math.log(255 * o) + 0.1  # alpha < 1/255 there: skipped
    assert int(cut.sum()) > 100 and float(alpha[0, ..., 0][cut].abs().max()) == 0.0
    # colour = alpha * c, expected depth = z, median = z, rendered normal = alpha * (0, 0, -1)
    c = (H // 2, W // 2)
    assert torch.allclose(render[0, c[0], c[1], :3], alpha[0, c[0], c[1]] * torch.tensor([1.0, 0.5, 0.25]), atol=1e-6)
    assert torch.allclose(render[0, ..., 3][inside], torch.full_like(render[0, ..., 3][inside], z), atol=1e-5)
    assert torch.allclose(median[0, ..., 0][inside], torch.full_like(median[0, ..., 0][inside], z), atol=1e-5)
    n_unit = normals[0][inside] / alpha[0][inside]
    assert torch.allclose(n_unit, torch.tensor([0.0, 0.0, -1.0]).expand_as(n_unit), atol=1e-5)
    assert torch.allclose(surf[0, c[0], c[1]], torch.tensor([0.0, 0.0, -1.0]), atol=1e-4)
    assert float(distort.abs().max()) < 1e-6
    assert torch.allclose(meta["means2d"][0, 0], torch.tensor([W / 2, H / 2]))
    assert int(meta["radii"][0, 0]) >= math.ceil(3 * sigma_px)


@pytest.mark.parametrize("angle", [0.3, math.pi - 0.3])
def test_rendered_normal_is_the_surfel_axis_facing_the_camera(angle):
    quat = _quat_axis([0.0, 1.0, 0.0], angle)[None]
    out = _render(torch.tensor([[0.0, 0.0, 2.0]]), quat, torch.tensor([[0.3, 0.3, 0.0]]), torch.tensor([0.9]),
                  torch.tensor([[1.0, 1.0, 1.0]]))
    alpha, normals = out[1][0], out[2][0]
    c = (H // 2, W // 2)
    n = normals[c] / alpha[c]
    axis = quat_to_rotmat(quat)[0, :, 2]
    expect = -axis if float(axis[2]) > 0 else axis  # back-facing (away from the camera) is flipped
    assert torch.allclose(n, expect, atol=1e-5)
    assert float(n[2]) < 0


def test_tilted_plane_depth_normals_match_rendered_normals():
    # a dense grid of surfels on the plane z = 3 + 0.5 y, all with the plane's normal
    nrm = torch.nn.functional.normalize(torch.tensor([0.0, -0.5, 1.0]), dim=0)
    angle = math.acos(float(nrm[2]))
    quat = _quat_axis([1.0, 0.0, 0.0], angle)
    assert torch.allclose(quat_to_rotmat(quat[None])[0, :, 2], nrm, atol=1e-6)
    u = torch.linspace(-1.6, 1.6, 17)
    gx, gy = torch.meshgrid(u, u, indexing="xy")
    x, y = gx.reshape(-1), gy.reshape(-1)
    means = torch.stack([x, y, 3.0 + 0.5 * y], -1)
    n = means.shape[0]
    _, alpha, normals, surf, _, _, _ = _render(means, quat.expand(n, 4), torch.tensor([0.15, 0.15, 0.0]).expand(n, 3),
                                               torch.full((n,), 0.95), torch.ones(n, 3))
    core = (slice(8, H - 8), slice(8, W - 8))
    assert float(alpha[0][core].min()) > 0.97
    rn = torch.nn.functional.normalize(normals[0][core], dim=-1)
    sn = surf[0][core]
    assert float((rn * sn).sum(-1).min()) > 0.999
    assert torch.allclose(rn, -nrm.expand_as(rn), atol=1e-4)  # facing the camera


def test_fronto_parallel_depth_median_and_distortion_of_two_layers():
    means = torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, 5.0]])
    quats = torch.tensor([[1.0, 0, 0, 0], [1.0, 0, 0, 0]])
    scales = torch.tensor([[0.3, 0.3, 0.0], [0.75, 0.75, 0.0]])
    render, alpha, _, _, distort, median, _ = _render(means, quats, scales, torch.tensor([0.6, 0.9]),
                                                        torch.ones(2, 3))
    c = (0, H // 2, W // 2)
    a1, a2 = 0.6, 0.9
    w1, w2 = a1, (1 - a1) * a2  # pixel centres sit 0.5 px off the axis: a factor ~ 1 - 1e-3
    assert float(alpha[c]) == pytest.approx(w1 + w2, rel=2e-3)
    ed = (w1 * 2.0 + w2 * 5.0) / (w1 + w2)
    assert float(render[c][3]) == pytest.approx(ed, rel=2e-3)
    assert float(median[c]) == pytest.approx(2.0, abs=1e-5)  # T = 1 > 0.5 before the first, 0.4 before the second
    assert float(distort[c]) == pytest.approx(w1 * w2 * 9.0, rel=5e-3)
    # the far surfel alone: no distortion, median on it
    _, _, _, _, d1, m1, _ = _render(means[1:], quats[1:], scales[1:], torch.tensor([0.9]), torch.ones(1, 3))
    assert float(d1.abs().max()) < 1e-6 and float(m1[c]) == pytest.approx(5.0, abs=1e-5)


def test_behind_camera_offscreen_and_empty_scene_render_background():
    bg = torch.tensor([0.2, 0.4, 0.6])
    means = torch.tensor([[0.0, 0.0, -2.0], [50.0, 0.0, 2.0], [0.0, 0.0, 0.005]])
    quats = torch.tensor([[1.0, 0, 0, 0]]).expand(3, 4)
    render, alpha, normals, _, distort, median, meta = _render(
        means, quats, torch.tensor([[0.3, 0.3, 0.0]]).expand(3, 3), torch.ones(3) * 0.9, torch.ones(3, 3),
        backgrounds=bg[None])
    assert float(alpha.abs().max()) == 0.0 and float(normals.abs().max()) == 0.0 and float(median.abs().max()) == 0
    assert torch.allclose(render[0, ..., :3], bg.expand(H, W, 3))
    assert meta["radii"].tolist() == [[0, 0, 0]]
    empty = _render(torch.zeros(0, 3), torch.zeros(0, 4), torch.zeros(0, 3), torch.zeros(0), torch.zeros(0, 3),
                    backgrounds=bg[None])
    assert torch.allclose(empty[0][0, ..., :3], bg.expand(H, W, 3)) and float(empty[1].abs().max()) == 0.0


def test_tile_size_does_not_change_the_image():
    scene = _random_scene(40, seed=3)
    a = _render(*scene, sh_degree=3, tile_size=16)
    b = _render(*scene, sh_degree=3, tile_size=8)
    for x, y in zip(a[:6], b[:6]):
        assert torch.allclose(x, y, atol=1e-4)


def test_gradcheck_double():
    means, quats, scales, opac, sh = _random_scene(4, seed=1, dtype=torch.float64)
    V, K = _cam(torch.float64)
    w, h = 14, 12
    K = K.clone()
    K[0, :2] *= 0.3
    K[0, 0, 2], K[0, 1, 2] = w / 2, h / 2
    colors = torch.rand(4, 3, dtype=torch.float64)

    def f(m, q, s, o, c):
        r, a, n, sn, d, med, _ = rasterize_surfels(m, q, s, o, c, V, K, w, h, backend="torch", tile_size=8)
        return r, a, n, d, med

    inputs = tuple(t.clone().requires_grad_() for t in (means, quats, scales, opac, colors))
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-3, fast_mode=True)


def test_meta_gradients_for_densification():
    means, quats, scales, opac, sh = _random_scene(30, seed=2)
    means.requires_grad_()
    render, alpha, normals, surf, distort, median, meta = _render(means, quats, scales, opac, sh, sh_degree=1)
    assert meta["means2d"].shape == (1, 30, 2) and meta["gradient_2dgs"].shape == (1, 30, 2)
    meta["means2d"].retain_grad()
    (render.sum() + distort.sum()).backward()
    g = meta["gradient_2dgs"].grad
    visible = meta["radii"][0] > 0
    assert g is not None and float(g[0][visible].norm(dim=-1).min()) > 0
    assert meta["means2d"].grad is not None and means.grad is not None
    assert torch.all(g[0][~visible] == 0)
    with torch.no_grad():
        assert _render(means, quats, scales, opac, sh, sh_degree=1)[6]["gradient_2dgs"] is None


def test_bad_arguments():
    scene = _random_scene(3, seed=0)
    with pytest.raises(ConfigError):
        _render(*scene, sh_degree=3, backend="vulkan")
    with pytest.raises(ValueError):
        _render(*scene[:4], scene[4][:, :4], sh_degree=3)


# ------------------------------------------------------------------ the C++ kernel vs the reference
def _cpu_or_skip():
    from nerf2gs_plugin.rendering import surfels_cpu

    if not surfels_cpu.available():
        pytest.skip(f"surfel C++ kernel not buildable here: {surfels_cpu.error()}")


def _outputs_and_grads(scene, backend, sh_degree, dtype, densify_signal="lowpass"):
    ins = [t.clone().requires_grad_() for t in scene]
    V, K = _cam(dtype)
    out = rasterize_surfels(*ins, V, K, W, H, sh_degree=sh_degree, backend=backend,
                            backgrounds=torch.tensor([[0.1, 0.2, 0.3]], dtype=dtype), densify_signal=densify_signal)
    assert out[6]["backend"] == backend
    g = torch.Generator().manual_seed(7)
    loss = sum((o * torch.rand(o.shape, generator=g, dtype=dtype)).sum() for o in out[:6])
    loss.backward()
    grads = [t.grad for t in ins] + [out[6]["gradient_2dgs"].grad]
    return [o.detach() for o in out[:6]], grads


@pytest.mark.parametrize("dtype,sh_degree", [(torch.float64, 3), (torch.float32, 0), (torch.float32, 2)])
def test_cpu_kernel_matches_torch_reference(dtype, sh_degree):
    _cpu_or_skip()
    scene = _random_scene(60, seed=11 + sh_degree, dtype=dtype)
    if sh_degree == 0:
        scene = scene[:4] + (scene[4][:, :1].contiguous(),)
    ref_out, ref_g = _outputs_and_grads(scene, "torch", sh_degree, dtype)
    out, g = _outputs_and_grads(scene, "cpu", sh_degree, dtype)
    rel = 1e-10 if dtype == torch.float64 else 1e-4
    names = ["render", "alpha", "normals", "surf_normals", "distort", "median"]
    for name, a, b in zip(names, ref_out, out):
        # surf normals are finite differences of depth: float32 noise is amplified there
        tol = rel * (30 if name == "surf_normals" and dtype == torch.float32 else 1)
        assert float((a - b).abs().max()) <= tol * max(float(a.abs().max()), 1.0), name
    for name, a, b in zip(["means", "quats", "scales", "opacities", "colors", "gradient_2dgs"], ref_g, g):
        assert float(a.abs().max()) > 0, name
        assert float((a - b).abs().max()) <= rel * float(a.abs().max()), name


def test_cpu_kernel_matches_torch_reference_for_the_screen_signal():
    _cpu_or_skip()
    scene = _random_scene(60, seed=5, dtype=torch.float64)
    _, ref_g = _outputs_and_grads(scene, "torch", 1, torch.float64, "screen")
    _, g = _outputs_and_grads(scene, "cpu", 1, torch.float64, "screen")
    _, low = _outputs_and_grads(scene, "cpu", 1, torch.float64, "lowpass")
    assert float(ref_g[-1].abs().max()) > 0
    assert float((ref_g[-1] - g[-1]).abs().max()) <= 1e-10 * float(ref_g[-1].abs().max())
    # only the densification signal changes, and these 0.1-0.4 m surfels at 3 m (2-8 px) get a weaker one
    for a, b in zip(g[:-1], low[:-1]):  # equal up to the threads' summation order
        assert torch.allclose(a, b, rtol=1e-12, atol=1e-12 * float(b.abs().max()))
    assert float(g[-1].norm(dim=-1).mean()) < 0.5 * float(low[-1].norm(dim=-1).mean())


def test_screen_signal_is_the_gradient_of_a_rigid_screen_translation():
    """Moving each surfel's footprint by d pixels (homography S(d) T, low-pass centre c + d) and
    differentiating colours and alpha w.r.t. d gives the "screen" signal exactly."""
    import dataclasses

    from nerf2gs_plugin.rendering.surfels_torch import build_tile_lists, composite_surfels_torch, project_surfels

    means, quats, scales, opac, sh = _random_scene(40, seed=9, dtype=torch.float64)
    V, K = _cam(torch.float64)
    proj = project_surfels(means, quats, scales, opac, V, K, W, H, 0.01, 1e10)
    lists = build_tile_lists(proj, W, H, 16)
    colors = sh[None, :, 0, :]
    C, N = proj.radii.shape
    d = torch.zeros(C, N, 2, dtype=torch.float64, requires_grad=True)
    S = torch.eye(3, dtype=torch.float64).repeat(C, N, 1, 1)
    S = torch.cat([S[..., :2], torch.cat([d, torch.ones(C, N, 1, dtype=torch.float64)], -1)[..., None]], -1)
    moved = dataclasses.replace(proj, T=S @ proj.T, means2d=proj.means2d + d)
    dens = torch.zeros(C, N, 2, dtype=torch.float64, requires_grad=True)
    g = torch.Generator().manual_seed(3)
    wc, wa = torch.rand(C, H, W, 3, generator=g, dtype=torch.float64), torch.rand(C, H, W, 1, generator=g, dtype=torch.float64)
    ref = composite_surfels_torch(moved, lists, opac, colors, W, H, 0.01)
    ((ref["colors"] * wc).sum() + (ref["alpha"] * wa).sum()).backward()
    ours = composite_surfels_torch(proj, lists, opac, colors, W, H, 0.01, dens, "screen")
    ((ours["colors"] * wc).sum() + (ours["alpha"] * wa).sum()).backward()
    assert float(d.grad.abs().max()) > 0
    assert torch.allclose(dens.grad, d.grad, rtol=1e-8, atol=1e-10 * float(d.grad.abs().max()))


def test_missing_kernel_falls_back_to_torch_with_a_warning(monkeypatch):
    from nerf2gs_plugin.rendering import backend as be
    from nerf2gs_plugin.rendering import surfels_cpu

    cpu = be.RASTER_BACKENDS["cpu"]
    monkeypatch.setitem(be.RASTER_BACKENDS, "cpu", dataclasses.replace(cpu, available=lambda kind: False))
    monkeypatch.setattr(be, "_WARNED", set())
    with pytest.warns(RuntimeWarning, match="torch reference"):
        out = _render(*_random_scene(5, seed=0), sh_degree=3, backend="cpu")
    assert out[6]["backend"] == "torch"
    assert "surfels-cpu" in be._WARNED


def test_camera_batch_equals_single_cameras_and_plane_through_the_camera_is_clipped():
    means, quats, scales, opac, sh = _random_scene(25, seed=4)
    # plus a large ground-like surfel that reaches behind the camera plane (y = 0.6, horizontal)
    means = torch.cat([means, torch.tensor([[0.0, 0.6, 0.5]])])
    quats = torch.cat([quats, _quat_axis([1.0, 0.0, 0.0], math.pi / 2)[None]])
    scales = torch.cat([scales, torch.tensor([[3.0, 3.0, 0.0]])])
    opac = torch.cat([opac, torch.tensor([0.9])])
    sh = torch.cat([sh, torch.zeros(1, 16, 3)])
    V, K = _cam()
    V2 = V.clone()
    V2[0, :3, 3] = torch.tensor([0.3, -0.1, 0.2])
    Vs, Ks = torch.cat([V, V2]), K.expand(2, 3, 3)
    both = rasterize_surfels(means, quats, scales, opac, sh, Vs, Ks, W, H, sh_degree=2, backend="torch")
    for c in range(2):
        one = rasterize_surfels(means, quats, scales, opac, sh, Vs[c:c + 1], Ks[c:c + 1], W, H, sh_degree=2,
                                backend="torch")
        for a, b in zip(both[:6], one[:6]):
            assert torch.allclose(a[c], b[0], atol=1e-5)
    alpha, depth = both[1][0, ..., 0], both[0][0, ..., 3]
    assert all(torch.isfinite(t).all() for t in both[:6])
    # the ground surfel covers the lower image rows, at the ray-plane depth 0.6 * F / (y_px - H/2)
    row = H - 1
    expect = 0.6 * F / (row + 0.5 - H / 2)
    assert float(alpha[row].min()) > 0.5
    assert float(depth[row, 2]) == pytest.approx(expect, rel=0.05)


def test_recomputed_batches_give_the_same_gradients(monkeypatch):
    from nerf2gs_plugin.rendering import surfels_torch

    scene = _random_scene(20, seed=6)

    def grads():
        ins = [t.clone().requires_grad_() for t in scene]
        out = _render(*ins, sh_degree=1)
        sum(o.sum() for o in out[:6]).backward()
        return [t.grad for t in ins]

    plain = grads()
    monkeypatch.setattr(surfels_torch, "RECOMPUTE_ABOVE", 0)
    monkeypatch.setattr(surfels_torch, "PAIR_PIXEL_BUDGET", 1 << 14)  # several batches
    for a, b in zip(plain, grads()):  # only float summation order differs
        assert float((a - b).abs().max()) <= 1e-5 * float(a.abs().max())
