"""The 2DGS cpu backend's fused projection + SH op and tile lists against the torch reference."""

from __future__ import annotations

import pytest
import torch

from nerf2gs_plugin.rendering.projection import camera_centers
from nerf2gs_plugin.rendering.sh import eval_sh
from nerf2gs_plugin.rendering.surfels_cpu import available, project_surfels_cpu, tile_lists_cpu
from nerf2gs_plugin.rendering.surfels_torch import _adjugate, _det, build_tile_lists, project_surfels
from projection_cases import assert_same_gradients, random_geometry, three_cameras

pytestmark = pytest.mark.skipif(not available(), reason="C++ surfel kernel could not be built here")


def _scene(n: int, dtype=torch.float64, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means, quats, scales = random_geometry(n, dtype, g)  # quats normalised inside, as the reference
    opac = torch.rand(n, generator=g, dtype=dtype)
    sh = torch.randn(n, 16, 3, generator=g, dtype=dtype) * 0.4
    return means, quats, scales, opac, sh, *three_cameras(dtype)


def _reference(means, quats, scales, opac, sh, vm, ks, degree):
    proj = project_surfels(means, quats, scales, opac, vm, ks, 40, 30, 0.01, 1e10)
    T = proj.T.reshape(-1, 3, 3)
    adj = _adjugate(T)
    cols = eval_sh(degree, sh[None], means[None] - camera_centers(vm)[:, None])
    return proj, (adj.reshape(-1, 9), _det(T, adj), proj.means2d, proj.depths, proj.normals, cols)


@pytest.mark.parametrize("degree", [0, 2, 3])
def test_surfel_projection_op_matches_torch(degree: int) -> None:
    means, quats, scales, opac, sh, vm, ks = _scene(60, seed=degree)
    a = [t.clone().requires_grad_(True) for t in (means, quats, scales, sh)]
    b = [t.clone().requires_grad_(True) for t in (means, quats, scales, sh)]
    pc, cc = project_surfels_cpu(a[0], a[1], a[2], opac, vm, ks, 40, 30, 0.01, 1e10, sh=a[3], sh_degree=degree)
    pt, ref = _reference(b[0], b[1], b[2], opac, b[3], vm, ks, degree)
    ours = (pc.adj, pc.det, pc.means2d, pc.depths, pc.normals, cc)
    assert torch.equal(pc.radii, pt.radii) and int((pt.radii == 0).sum()) >= 3
    assert torch.allclose(pc.bbox, pt.bbox, rtol=1e-12, atol=1e-10)
    for x, y in zip(ours, ref):
        assert torch.allclose(x, y, rtol=1e-12, atol=1e-10)
    assert_same_gradients(ours, ref, a, b, seed=7)
    lc, lt = tile_lists_cpu(pc, 40, 30, 8), build_tile_lists(pt, 40, 30, 8)
    assert lt.flat_ids.numel() > 60
    assert torch.equal(lc.flat_ids, lt.flat_ids) and torch.equal(lc.starts, lt.starts) and torch.equal(lc.counts, lt.counts)


def test_surfel_projection_op_gradcheck_double() -> None:
    means, quats, scales, opac, sh, vm, ks = _scene(10, seed=4)
    inputs = [t[1:7].clone().requires_grad_(True) for t in (means, quats, scales, sh)]

    def f(m, q, s, c):
        p, cols = project_surfels_cpu(m, q, s, opac[1:7], vm, ks, 40, 30, 0.01, 1e10, sh=c, sh_degree=3)
        return p.adj, p.det, p.means2d, p.depths, p.normals, cols

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-5)
