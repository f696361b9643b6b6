"""The per-image metrics table of the evaluation. The metrics themselves sit on the ground floor,
where the enhancer's training uses them too: PSNR and SSIM in :mod:`nerf2gs_plugin.utils.image_metrics`,
LPIPS in :mod:`nerf2gs_plugin.utils.lpips`."""

from __future__ import annotations

from typing import Callable

from torch import Tensor

from nerf2gs_plugin.utils.image_metrics import psnr, ssim

# The per-image metrics every evaluation reports (``<name>`` and ``<name>_std`` per split), in
# order: a new metric is one function and one row here. LPIPS needs weights and the ground-mask
# PSNR a mask, so evaluate_run adds those two itself.
IMAGE_METRICS: dict[str, Callable[[Tensor, Tensor], Tensor]] = {"psnr": psnr, "ssim": ssim}
