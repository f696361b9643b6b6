"""The C++ hash-grid kernel against the pure-torch reference: values and table gradients."""

import pytest
import torch

from nerf2gs_plugin.fields.hash_encoding import HashEncoding, HashGridSpec, grid_resolutions, hash_encode, hash_encode_torch, level_weights, load_kernel

pytestmark = pytest.mark.skipif(load_kernel() is None, reason="C++ toolchain unavailable")


@pytest.mark.parametrize("features", [1, 2, 4])
def test_cpu_kernel_matches_reference(features):
    g = torch.Generator().manual_seed(features)
    # levels 16 and 24 fit densely in 2^14 entries, 64 and 128 are hashed: both paths are covered
    res = [16, 24, 64, 128]
    table = (torch.rand(len(res), 2**14, features, generator=g) * 2 - 1)
    x = torch.rand(3000, 3, generator=g) * 1.1 - 0.05  # a few points outside [0,1] exercise the clamp
    x[:5] = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5], [1.0, 0.0, 1.0], [0.999999, 1e-7, 0.25]])
    grad = torch.randn(3000, len(res), features, generator=g)

    t_cpu = table.clone().requires_grad_(True)
    out_cpu = hash_encode(x, t_cpu, res, backend="cpu")
    (out_cpu * grad).sum().backward()
    t_ref = table.clone().requires_grad_(True)
    out_ref = hash_encode_torch(x, t_ref, res)
    (out_ref * grad).sum().backward()

    assert out_cpu.shape == (3000, len(res), features)
    torch.testing.assert_close(out_cpu, out_ref, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(t_cpu.grad, t_ref.grad, atol=1e-4, rtol=1e-4)
    assert t_cpu.grad.abs().sum() > 0


def test_interpolation_is_exact_at_grid_vertices():
    """At a vertex of a dense level the encoding returns that vertex's table entry."""
    res = [4]
    table = torch.arange(5**3, dtype=torch.float32).reshape(1, 125, 1)
    table = torch.cat([table, torch.zeros(1, 128 - 125, 1)], 1)
    x = torch.tensor([[0.25, 0.5, 0.75]])  # vertex (1, 2, 3)
    out = hash_encode(x, table, res, backend="cpu")
    assert float(out) == pytest.approx(1 + 5 * (2 + 5 * 3))


def test_module_and_antialiasing_weights():
    enc = HashEncoding(HashGridSpec(num_levels=6, log2_table_size=12, base_res=8, max_res=256))
    assert enc.resolutions == grid_resolutions(6, 8, 256) and enc.resolutions[0] == 8 and enc.resolutions[-1] == 256
    x = torch.rand(100, 3)
    assert enc(x).shape == (100, enc.out_dim)
    # a large footprint fades the fine levels out, a tiny one keeps every level
    w_big = level_weights(torch.full((1,), 0.05), torch.tensor(enc.resolutions, dtype=torch.float32))
    w_small = level_weights(torch.full((1,), 1e-5), torch.tensor(enc.resolutions, dtype=torch.float32))
    assert torch.all(w_big[0, 1:] <= w_big[0, :-1]) and float(w_big[0, -1]) < 0.05
    assert torch.allclose(w_small, torch.ones_like(w_small), atol=1e-4)
    feats_aa = enc(x, torch.full((100,), 0.05))
    assert feats_aa.abs().sum() < enc(x).abs().sum()


@pytest.mark.parametrize("features", [2, 4])
def test_cpu_kernel_position_gradient_matches_reference(features):
    """A camera optimizer moves the sample positions: the kernel's gradient w.r.t. them is the
    reference's autograd one (dense and hashed levels, points outside [0, 1] get none on that axis)."""
    g = torch.Generator().manual_seed(10 + features)
    res = [16, 24, 64, 128]
    table = torch.rand(len(res), 2**14, features, generator=g) * 2 - 1
    x = torch.rand(2000, 3, generator=g) * 1.1 - 0.05
    grad = torch.randn(2000, len(res), features, generator=g)
    x_cpu, x_ref = x.clone().requires_grad_(True), x.clone().requires_grad_(True)
    (hash_encode(x_cpu, table.clone().requires_grad_(True), res, backend="cpu") * grad).sum().backward()
    (hash_encode_torch(x_ref, table, res) * grad).sum().backward()
    assert float(x_ref.grad.abs().max()) > 1.0  # a real signal, not zeros on both sides
    torch.testing.assert_close(x_cpu.grad, x_ref.grad, atol=2e-3, rtol=1e-4)
    outside = (x < 0) | (x > 1)
    assert bool((x_cpu.grad[outside] == 0).all())


def test_positions_without_grad_keep_the_table_only_backward():
    """The default path (positions that need no grad) returns no position gradient and the same table gradient."""
    res = [16, 64]
    table = torch.rand(2, 2**12, 2, requires_grad=True)
    x = torch.rand(100, 3)
    hash_encode(x, table, res, backend="cpu").sum().backward()
    assert x.grad is None and table.grad is not None


def test_render_pass_matches_the_encoding_times_level_weights():
    """Without a gradient the kernel applies the anti-aliasing weights itself (one pass); same numbers."""
    torch.manual_seed(0)
    enc = HashEncoding(HashGridSpec(6, 2, 12, 4, 256), backend="cpu")
    with torch.no_grad():
        enc.table.normal_()
    x = torch.rand(3000, 3) * 1.2 - 0.1  # some outside [0, 1]: clamped alike
    r = torch.rand(3000) * 0.02
    r[:5] = 0.0
    with_grad = enc(x, r)
    assert with_grad.requires_grad
    with torch.no_grad():
        fused = enc(x, r)
    torch.testing.assert_close(fused, with_grad.detach(), atol=1e-6, rtol=1e-5)


@pytest.mark.parametrize("levels,log2_table", [(5, 11), (12, 14)])
def test_training_pass_with_level_weights_is_the_separate_multiply_bit_for_bit(levels, log2_table):
    """With a gradient to the table only, the kernel multiplies the level weights in its pass: the output and the
    table's gradient are bit-for-bit those of the encoding times the weights (zero gradients skipped alike)."""
    torch.manual_seed(0)
    enc = HashEncoding(HashGridSpec(levels, 2, log2_table, 16, 512), backend="cpu")
    with torch.no_grad():
        enc.table.normal_()
    x = torch.rand(4000, 3) * 1.2 - 0.1
    r = torch.rand(4000) * 0.02
    r[:5] = 0.0
    g = torch.randn(4000, levels * 2)
    g[::7] = 0.0  # rows without gradient, as where no loss reaches
    fused = enc(x, r)
    (fused * g).sum().backward()
    grad_fused, enc.table.grad = enc.table.grad.clone(), None
    feats = hash_encode(x, enc.table, enc.resolutions, "cpu")
    separate = (feats * level_weights(r, enc._res.float())[..., None]).reshape(4000, -1)
    (separate * g).sum().backward()
    assert "Weighted" in type(fused.grad_fn.next_functions[0][0]).__name__  # the fused pass ran (under the reshape)
    assert torch.equal(fused, separate) and torch.equal(grad_fused, enc.table.grad)
