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
    """Mean SSIM (scalar tensor, differentiable) of ``[H,W,3]`` images (or ``[B,3,H,W]`` batches)."""
    return ssim_map(pred, gt, window_size, sigma, data_range).mean()


