"""Image enhancement of the additional (bird's-eye) views, the paper's optional Difix3D+ step.

``--augment.enhancer`` takes:

* ``none``: no enhancement;
* ``onnx:PATH``: any image-to-image ONNX model (e.g. an ONNX export of Difix), run with
  onnxruntime; its I/O convention is documented in :mod:`nerf2gs_plugin.enhancer.onnx_runtime`;
* ``builtin:PATH``: our own small residual U-Net trained by ``ns2gs-enhance train`` (an ONNX file
  too; it is NOT Difix, just a learned artifact remover trained on this dataset's images);
* ``builtin``: the built-in model at the default path (``$NS2GS_ENHANCER`` or
  ``outputs/enhancer/enhancer.onnx``, where ``ns2gs-enhance train`` writes by default).

Running one: this module, ``onnx_runtime`` and ``warp`` (the reference input of a conditioned model).
Training ours (``ns2gs-enhance train``): ``pairs`` from a reference run, ``degrade``, the residual
U-Net (``unet``) and its ONNX export, ``train``, ``pretrain`` and the bench's ``bench``.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Callable, Optional

from torch import Tensor

from nerf2gs_plugin.errors import ConfigError

DEFAULT_BUILTIN = Path("outputs/enhancer/enhancer.onnx")


class Enhancer(ABC):
    """Image in (plus an optional reference view, e.g. the source training image), image out."""

    reference_kind: str = "image"
    """What ``enhance``'s ``reference`` should be: ``image``, a real training view as it is; ``warped``,
    the nearest one warped into the image's camera with its validity (:mod:`~nerf2gs_plugin.enhancer.warp`)."""

    @abstractmethod
    def enhance(self, rgb: Tensor, reference: Optional[Tensor] = None) -> Tensor:
        """``rgb`` ``[H, W, 3]`` float in 0..1 -> enhanced ``[H, W, 3]`` float in 0..1."""

    @abstractmethod
    def cache_key(self) -> str:
        """Identifies the enhancement (model content and settings): rendered caches key on it."""


class IdentityEnhancer(Enhancer):
    """``none``: returns the image unchanged."""

    def enhance(self, rgb: Tensor, reference: Optional[Tensor] = None) -> Tensor:
        return rgb

    def cache_key(self) -> str:
        return "none"


class OnnxModelEnhancer(Enhancer):
    """An ONNX model run through :class:`~nerf2gs_plugin.enhancer.onnx_runtime.OnnxEnhancer`."""

    def __init__(self, path: Path, tile_size: Optional[int] = None, overlap: Optional[int] = None) -> None:
        from nerf2gs_plugin.enhancer.onnx_runtime import OnnxEnhancer

        self.runtime = OnnxEnhancer(path, tile_size=tile_size, overlap=overlap)
        self.path = Path(path)
        self.reference_kind = self.runtime.reference_kind

    def enhance(self, rgb: Tensor, reference: Optional[Tensor] = None) -> Tensor:
        return self.runtime.enhance(rgb, reference)

    def cache_key(self) -> str:
        return self.runtime.cache_key()


def default_builtin_path() -> Path:
    """Where ``builtin`` looks: ``$NS2GS_ENHANCER`` or ``outputs/enhancer/enhancer.onnx``."""
    env = os.environ.get("NS2GS_ENHANCER")
    return Path(env) if env else DEFAULT_BUILTIN


def _none(arg: str) -> Enhancer:
    if arg:
        raise ConfigError(f"unknown enhancer 'none:{arg}' (expected none, builtin, builtin:PATH or onnx:PATH)")
    return IdentityEnhancer()


def _builtin(arg: str) -> Enhancer:
    path = Path(arg) if arg else default_builtin_path()
    if not path.is_file():
        raise ConfigError(
            "no built-in enhancer model here: train one with `ns2gs-enhance train --data DATA --out "
            f"{path}` or pass --augment.enhancer builtin:PATH / onnx:PATH", path)
    return OnnxModelEnhancer(path)


def _onnx(arg: str) -> Enhancer:
    if not arg:
        raise ConfigError("--augment.enhancer onnx:PATH needs a model path")
    return OnnxModelEnhancer(Path(arg))


# ``--augment.enhancer KIND[:ARG]``: a new enhancer is one class and one row here
ENHANCERS: dict[str, Callable[[str], Enhancer]] = {"none": _none, "builtin": _builtin, "onnx": _onnx}


def make_enhancer(spec: str) -> Enhancer:
    """``none | builtin | builtin:PATH | onnx:PATH`` -> an :class:`Enhancer`."""
    spec = (spec or "none").strip()
    kind, _, arg = spec.partition(":")
    make = ENHANCERS.get(kind.lower())
    if make is None:
        raise ConfigError(f"unknown enhancer '{spec}' (expected none, builtin, builtin:PATH or onnx:PATH)")
    return make(arg)


__all__ = ["DEFAULT_BUILTIN", "Enhancer", "IdentityEnhancer", "OnnxModelEnhancer", "ENHANCERS", "default_builtin_path", "make_enhancer"]
