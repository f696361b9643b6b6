"""The cpu backend's fused projection + SH op (C++ forward and backward) against the torch reference."""

from __future__ import annotations

import pytest
import torch

from nerf2gs_plugin.rendering.projection import camera_centers, project_gaussians
from nerf2gs_plugin.rendering.rasterization import load_kernel, project_cpu
from nerf2gs_plugin.rendering.sh import eval_sh
from nerf2gs_plugin.rendering.tiles import bin_gaussians
from projection_cases import assert_same_gradients, random_geometry, three_cameras

pytestmark = pytest.mark.skipif(load_kernel() is None, reason="C++ rasterizer could not be built here")


def _gaussians(n: int, dtype=torch.float64, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means, quats, scales = random_geometry(n, dtype, g)  # quats not normalised: the op uses them as given
    means[1, 0] = 40.0  # far off to the side: the clamped Jacobian
    sh = torch.randn(n, 16, 3, generator=g, dtype=dtype) * 0.4
    return means, quats, scales, sh


def _outputs(proj, cols):
    return proj.means2d, proj.conics, proj.depths, proj.compensations, cols


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_projection_op_matches_torch_values_and_gradients(degree: int) -> None:
    vm, ks = three_cameras()
    base = _gaussians(40, seed=degree)
    a = [t.clone().requires_grad_(True) for t in base]
    b = [t.clone().requires_grad_(True) for t in base]
    pc, cc = project_cpu(a[0], a[1], a[2], vm, ks, 40, 30, sh=a[3], sh_degree=degree)
    pt = project_gaussians(b[0], b[1], b[2], vm, ks, 40, 30)
    ct = eval_sh(degree, b[3], b[0][None] - camera_centers(vm)[:, None])
    assert torch.equal(pc.radii, pt.radii) and int((pt.radii == 0).sum()) >= 3  # culled pairs are exercised
    assert torch.allclose(pc.cov2d, pt.cov2d, rtol=1e-12, atol=1e-12)
    for x, y in zip(_outputs(pc, cc), _outputs(pt, ct)):
        assert torch.allclose(x, y, rtol=1e-12, atol=1e-12)
    assert_same_gradients(_outputs(pc, cc), _outputs(pt, ct), a, b, seed=99)


@pytest.mark.parametrize("degree", [0, 3])
def test_projection_op_gradcheck_double(degree: int) -> None:
    vm, ks = three_cameras()
    inputs = [t[2:10].clone().requires_grad_(True) for t in _gaussians(12, seed=5)]

    def f(m, q, s, c):
        proj, cols = project_cpu(m, q, s, vm, ks, 40, 30, sh=c, sh_degree=degree)
        return _outputs(proj, cols)

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-5)


def test_projection_op_without_sh_and_float32_matches_torch() -> None:
    vm, ks = three_cameras(torch.float32)
    means, quats, scales, _ = _gaussians(200, dtype=torch.float32, seed=3)
    quats = torch.nn.functional.normalize(quats, dim=-1)
    pc, cols = project_cpu(means, quats, scales, vm, ks, 40, 30)
    pt = project_gaussians(means, quats, scales, vm, ks, 40, 30)
    assert cols is None
    for x, y in zip(_outputs(pc, None)[:4], _outputs(pt, None)[:4]):
        assert torch.allclose(x, y, rtol=1e-5, atol=1e-5)
    assert float((pc.radii != pt.radii).float().mean()) < 0.01  # a ceil can flip on float rounding


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_radix_sorted_binning_matches_torch_with_depth_ties(dtype) -> None:
    """Binning's depth order (C++ radix sort) equals torch's stable argsort, ties included."""
    vm, ks = three_cameras(dtype)
    means, quats, scales, _ = _gaussians(400, dtype=dtype, seed=4)
    means[::4, 2] = 3.0  # many exact depth ties in the first camera
    proj = project_gaussians(means, torch.nn.functional.normalize(quats, dim=-1), scales, vm, ks, 40, 30)
    opac = torch.full(proj.depths.shape, 0.8, dtype=dtype)
    args = (proj.means2d.contiguous(), proj.cov2d.contiguous(), opac, proj.depths.contiguous(), proj.radii.contiguous(), 40, 30, 8)
    off_t, ids_t = bin_gaussians(*args)
    off_c, ids_c = load_kernel().bin_gaussians(*args)
    assert ids_t.numel() > 400
    assert torch.equal(off_t, off_c) and torch.equal(ids_t, ids_c)
