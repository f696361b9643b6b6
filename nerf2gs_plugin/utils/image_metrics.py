"""PSNR and SSIM: the one copy that training logs, the splatting losses, the enhancer and the
evaluation all use (LPIPS, which needs weights, is in ``utils.lpips``).

Images are ``[H,W,3]`` in [0, 1] (``[B,3,H,W]`` is accepted too). SSIM is the standard Wang et
al. form used by nerfstudio's ``ns-eval`` (torchmetrics), skimage (``gaussian_weights=True``) and
pytorch_msssim: a separable Gaussian window over the *valid* region (no padding), mean over pixels
and channels. It is differentiable, and the splatting methods train with it.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

_WINDOWS: dict[tuple, Tensor] = {}


def psnr_from_mse(mse: Tensor, data_range: float = 1.0) -> Tensor:
    """PSNR in dB of a mean squared error (capped at 100 dB for ``data_range`` 1, so identical
    images give a finite number that JSON can hold)."""
    return 10.0 * torch.log10(data_range**2 / mse.clamp_min(1e-10 * data_range**2))


def psnr(pred: Tensor, gt: Tensor, data_range: float = 1.0) -> Tensor:
    """Peak signal-to-noise ratio in dB over all pixels and channels."""
    return psnr_from_mse(((pred.float() - gt.float().to(pred.device)) ** 2).mean(), data_range)


def _nchw(img: Tensor) -> Tensor:
    if img.ndim == 3:
        return img.permute(2, 0, 1)[None]
    if img.ndim == 4:
        return img
    raise ValueError(f"expected an image [H,W,C] or a batch [B,C,H,W], got shape {tuple(img.shape)}")


def gaussian_window(size: int = 11, sigma: float = 1.5, device=None, dtype=torch.float32) -> Tensor:
    """Normalised 1-D Gaussian ``[size]`` (cached per device/dtype)."""
    key = (size, sigma, str(device), dtype)
    if key not in _WINDOWS:
        x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
        g = torch.exp(-(x**2) / (2 * sigma**2))
        _WINDOWS[key] = (g / g.sum()).to(device=device, dtype=dtype)
    return _WINDOWS[key]
def ssim_map(pred: Tensor, gt: Tensor, window_size: int = 11, sigma: float = 1.5, data_range: float = 1.0) -> Tensor:
    """Per-pixel SSIM ``[B,C,H-w+1,W-w+1]`` (valid region). Images smaller than the window use
    the largest odd window that fits."""
    x, y = _nchw(pred).float(), _nchw(gt).float().to(pred.device)
    if x.shape != y.shape:
        raise ValueError(f"SSIM of images of different shapes {tuple(x.shape)} and {tuple(y.shape)}")
    b, c, h, w = x.shape
    win = min(window_size, h, w)
    win -= 1 - win % 2
    g = gaussian_window(win, sigma, x.device, x.dtype)
    # five moments at once, separable blur (row pass then column pass), depthwise
    stack = torch.cat([x, y, x * x, y * y, x * y], 1)
    n = stack.shape[1]
    blurred = F.conv2d(stack, g.reshape(1, 1, 1, win).expand(n, 1, 1, win), groups=n)
    blurred = F.conv2d(blurred, g.reshape(1, 1, win, 1).expand(n, 1, win, 1), groups=n)
    mu_x, mu_y, e_xx, e_yy, e_xy = blurred.split(c, 1)
    var_x, var_y, cov = e_xx - mu_x**2, e_yy - mu_y**2, e_xy - mu_x * mu_y
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    return ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))


def ssim(pred: Tensor, gt: Tensor, window_size: int = 11, sigma: float = 1.5, data_range: float = 1.0) -> Tensor:
    """Mean SSIM (scalar tensor, differentiable) of ``[H,W,3]`` images (or ``[B,3,H,W]`` batches).
    float32 ``[H,W,C]`` images on the CPU go through the fused C++ kernel (the splatting losses' largest
    cost after the rasterizer otherwise); the same values and gradient to float rounding."""
    if _fused_applies(pred, gt, window_size):
        y = gt.to(device=pred.device, dtype=torch.float32).contiguous()
        c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
        return _FusedSSIM.apply(pred.contiguous(), y, gaussian_window(window_size, sigma), c1, c2)
    return ssim_map(pred, gt, window_size, sigma, data_range).mean()


SSIM_EXT = "nerf2gs_ssim"


def _ssim_kernel():
    from pathlib import Path

    from nerf2gs_plugin.utils.extensions import load_extension

    return load_extension(SSIM_EXT, [Path(__file__).with_name("csrc") / "ssim.cpp"], (),
                          ("-O3", "-fopenmp", "-march=native", "-fno-math-errno"))


def _fused_applies(pred: Tensor, gt: Tensor, window_size: int) -> bool:
    """One float32 ``[H,W,C]`` CPU image at least a window large, no gradient into ``gt``, the kernel built."""
    return (pred.ndim == 3 and pred.shape == gt.shape and pred.device.type == "cpu" and gt.device.type == "cpu"
            and pred.dtype == torch.float32 and not gt.requires_grad and window_size % 2 == 1
            and min(pred.shape[0], pred.shape[1]) >= window_size and _ssim_kernel() is not None)


class _FusedSSIM(torch.autograd.Function):
    """Mean SSIM by ``csrc/ssim.cpp``: the gradient reaches ``x`` only."""

    @staticmethod
    def forward(ctx, x, y, window, c1, c2):  # type: ignore[override]
        mean, moments = _ssim_kernel().forward(x, y, window, c1, c2)
        ctx.save_for_backward(x, y, window, moments)
        ctx.constants = (c1, c2)
        return mean

    @staticmethod
    def backward(ctx, grad):  # type: ignore[override]
        x, y, window, moments = ctx.saved_tensors
        dx = _ssim_kernel().backward(x, y, window, moments, *ctx.constants, float(grad))
        return dx, None, None, None, None


