"""The fused SSIM kernel (``utils/csrc/ssim.cpp``) behind ``ssim`` on float32 CPU images: the same mean and
gradient as the torch formula (``ssim_map``) to float rounding; the other inputs keep the torch formula."""

from __future__ import annotations

import pytest
import torch

from nerf2gs_plugin.utils import image_metrics
from nerf2gs_plugin.utils.image_metrics import ssim, ssim_map


def _pair(h: int, w: int, c: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(seed)
    y = torch.rand(h, w, c, generator=gen)
    x = (0.7 * y + 0.3 * torch.rand(h, w, c, generator=gen)).requires_grad_(True)
    return x, y


@pytest.mark.parametrize("shape", [(90, 120, 3), (24, 40, 3), (11, 13, 1), (37, 50, 2)])
def test_the_kernel_gives_the_torch_formulas_value_and_gradient(shape):
    x, y = _pair(*shape, seed=sum(shape))
    assert image_metrics._fused_applies(x, y, 11)
    fused = ssim(x, y)
    (g_fused,) = torch.autograd.grad(3.0 * fused, x)  # an upstream gradient other than 1
    ref = ssim_map(x, y).mean()
    (g_ref,) = torch.autograd.grad(3.0 * ref, x)
    assert abs(float(fused) - float(ref)) < 1e-6
    assert float((g_fused - g_ref).abs().max()) <= 1e-5 * float(g_ref.abs().max())
    assert float(ssim(y, y)) == pytest.approx(1.0, abs=1e-6)


def test_other_inputs_keep_the_torch_formula():
    x, y = _pair(24, 40, 3, seed=1)
    assert not image_metrics._fused_applies(x.double(), y.double(), 11)
    assert not image_metrics._fused_applies(x[:8], y[:8], 11)  # smaller than the window
    assert not image_metrics._fused_applies(x, y.clone().requires_grad_(True), 11)
    nchw = x.permute(2, 0, 1)[None]
    assert not image_metrics._fused_applies(nchw, y.permute(2, 0, 1)[None], 11)
    assert torch.equal(ssim(x.double(), y.double()), ssim_map(x.double(), y.double()).mean())
