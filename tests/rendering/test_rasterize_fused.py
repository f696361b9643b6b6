"""The CPU compositor's backward in one pass over a Gaussian's rows (3 or 4 channels, 16 px tiles) gives the
gradients of its three-pass form (any other channel count) to float rounding."""

from __future__ import annotations

import pytest
import torch

from nerf2gs_plugin.rendering import rasterize_gaussians
from nerf2gs_plugin.rendering.rasterization import load_kernel

from test_rasterize import _scene

needs_kernel = pytest.mark.skipif(load_kernel() is None, reason="C++ rasterizer could not be built here")


def _grads(scene, feats: torch.Tensor, mode: str, channels: list[int]):
    """The render's ``channels`` and the gradients of their weighted sum (plus the alpha's) w.r.t. the Gaussians."""
    leaves = [t.clone().requires_grad_(True) for t in (*scene[:4], feats)]
    render, alpha, _ = rasterize_gaussians(*leaves, *scene[5:], render_mode=mode, backend="cpu", tile_size=16)
    part = render[..., channels]
    weights = torch.linspace(-1.0, 1.0, part.numel()).reshape(part.shape)
    ((part * weights).sum() + 0.3 * (alpha**2).sum()).backward()
    grads = [t.grad for t in leaves]
    grads[-1] = grads[-1][:, :3]  # the features' gradient: the three real channels
    return part.detach(), grads


@needs_kernel
@pytest.mark.parametrize("mode,fused_channels,plain_channels", [("RGB", [0, 1, 2], [0, 1, 2]),
                                                                ("RGB+ED", [0, 1, 2, 3], [0, 1, 2, 5])])
def test_the_one_pass_backward_gives_the_three_pass_gradients(mode, fused_channels, plain_channels) -> None:
    scene = _scene(150, w=48, h=40, seed=len(fused_channels))
    feats = torch.rand(150, 3)
    fused_render, fused = _grads(scene, feats, mode, fused_channels)
    # two zero feature channels more: 5 (RGB) or 6 (RGB+ED) channels take the three-pass backward
    plain_render, plain = _grads(scene, torch.cat([feats, torch.zeros(150, 2)], 1), mode, plain_channels)
    assert torch.allclose(fused_render, plain_render, rtol=1e-6, atol=1e-6)
    for a, b in zip(fused, plain):
        assert float(b.abs().max()) > 0
        assert float((a - b).abs().max()) <= 1e-5 * float(b.abs().max())
