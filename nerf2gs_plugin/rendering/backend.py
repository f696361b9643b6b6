"""The rasterizer backends, one table: name -> where it runs, whether it is usable here, and its
3DGS and 2DGS entry points. A new backend is one module plus one row of :data:`RASTER_BACKENDS`.

``"auto"`` picks the first usable backend of :data:`AUTO_ORDER` for the tensors' device, else the
pure-torch reference: gsplat for CUDA tensors when the package imports, the compiled C++/OpenMP
kernels for CPU tensors (a kernel that does not build is an error, see
:mod:`nerf2gs_plugin.utils.extensions`, unless ``NERF2GS_ALLOW_NO_KERNELS=1``: then torch, with a
one-line warning once).

Entry points are ``"module:function"`` strings, imported on first use: a CPU machine never
imports gsplat, and a backend module may import the rasterizer entries without a cycle. A
``gaussians`` function takes :func:`~.rasterization.rasterize_gaussians`' arguments after
``height`` as keywords (no ``backend``); a ``surfels`` function likewise for
:func:`~.surfels.rasterize_surfels`; ``available(kind)`` says whether the backend can run ``kind``
(``"gaussians"`` or ``"surfels"``) on this machine.
"""

from __future__ import annotations

import importlib
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Optional

from nerf2gs_plugin.errors import ConfigError

KINDS = ("gaussians", "surfels")
_WARNED: set[str] = set()


def gsplat_available(kind: str = "gaussians") -> bool:
    """True when CUDA is usable and ``gsplat`` imports (never imported on a CPU-only machine)."""
    import torch  # noqa: PLC0415 - keeps this table cheap to import

    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401, PLC0415
    except Exception:  # noqa: BLE001
        return False
    return True


_CPU_KERNELS = {"gaussians": "nerf2gs_plugin.rendering.rasterization:load_kernel",
                "surfels": "nerf2gs_plugin.rendering.surfels_cpu:extension"}


def cpu_kernel_available(kind: str) -> bool:
    """True when the C++ kernel of ``kind`` builds (raises when it fails and no opt-out is set)."""
    return resolve_entry(_CPU_KERNELS[kind])() is not None


@dataclass(frozen=True)
class RasterBackend:
    devices: tuple[str, ...]  # device types its tensors may live on
    available: Callable[[str], bool]  # kind -> usable on this machine
    gaussians: str  # "module:function", 3DGS
    surfels: str  # "module:function", 2DGS


RASTER_BACKENDS: dict[str, RasterBackend] = {
    "gsplat": RasterBackend(("cuda",), gsplat_available, "nerf2gs_plugin.rendering.gsplat_backend:rasterize_gsplat",
                            "nerf2gs_plugin.rendering.gsplat_backend:rasterize_surfels_gsplat"),
    "cpu": RasterBackend(("cpu",), cpu_kernel_available, "nerf2gs_plugin.rendering.rasterization:rasterize_gaussians_cpu",
                         "nerf2gs_plugin.rendering.surfels:rasterize_surfels_cpu"),
    "torch": RasterBackend(("cpu", "cuda"), lambda kind: True, "nerf2gs_plugin.rendering.rasterization:rasterize_gaussians_torch",
                           "nerf2gs_plugin.rendering.surfels:rasterize_surfels_torch"),
}
AUTO_ORDER = {"cuda": ("gsplat",), "cpu": ("cpu",)}
BACKENDS = ("auto", *RASTER_BACKENDS)


def resolve_entry(spec: str) -> Callable[..., Any]:
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name)


def backend_function(name: str, kind: str) -> Callable[..., Any]:
    """The ``kind`` entry point of backend ``name``."""
    return resolve_entry(getattr(RASTER_BACKENDS[name], kind))


def fastest_backend(device_type: str, kind: str) -> Optional[str]:
    """The backend ``"auto"`` would pick for ``kind`` on ``device_type`` besides torch, or None."""
    for name in AUTO_ORDER.get(device_type, ()):
        if device_type in RASTER_BACKENDS[name].devices and RASTER_BACKENDS[name].available(kind):
            return name
    return None


def warn_once(key: str, message: str) -> None:
    """One-line warning, once per process and key."""
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(message, RuntimeWarning, stacklevel=3)


def resolve_backend(backend: str, device_type: str, kind: str) -> str:
    """Turn a requested backend into the one that runs for ``kind`` on ``device_type``.

    ``"auto"``: the first usable backend of :data:`AUTO_ORDER`, else torch. An explicit backend
    that does not run here falls back to the one ``"auto"`` picks (then torch) with a warning
    rather than failing a training run.
    """
    if backend not in BACKENDS:
        raise ConfigError(f"unknown rasterization backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if backend == "torch":
        return "torch"
    if backend != "auto":
        entry = RASTER_BACKENDS[backend]
        if device_type in entry.devices and entry.available(kind):
            return backend
        if device_type not in entry.devices:
            warn_once(f"{backend}-{device_type}", f"the {backend} backend cannot run on {device_type} tensors; "
                      f"using the {device_type} default")
    chosen = fastest_backend(device_type, kind)
    if chosen is not None:
        return chosen
    if device_type == "cpu" or backend != "auto":
        warn_once(f"{kind}-{backend}", f"no fast {kind} rasterizer usable here (requested {backend!r}); "
                  "using the slow torch reference")
    return "torch"
