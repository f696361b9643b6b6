"""Which rasterization backend runs: ``gsplat`` (CUDA), ``cpu`` (C++/OpenMP extension) or ``torch``.

``"auto"`` picks gsplat for CUDA tensors when the package imports, the compiled extension for CPU
tensors when it builds, else the pure-torch reference (with a one-line warning once). The
extension is compiled on first use with ``torch.utils.cpp_extension.load`` into
``TORCH_EXTENSIONS_DIR`` (see :func:`extension_cache_dir`) and reloaded from there afterwards.
"""

from __future__ import annotations

import hashlib
import os
import threading
import warnings
from pathlib import Path
from typing import Any, Optional, Sequence

from nerf2gs_plugin.errors import ConfigError

BACKENDS = ("auto", "cpu", "torch", "gsplat")
CSRC = Path(__file__).with_name("csrc")

_EXTS: dict[str, Any] = {}
_FAILED: dict[str, str] = {}
_LOCK = threading.Lock()
_WARNED: set[str] = set()


def extension_cache_dir() -> Path:
    """Where compiled extensions are cached: ``$TORCH_EXTENSIONS_DIR`` or torch's default."""
    env = os.environ.get("TORCH_EXTENSIONS_DIR")
    if env:
        return Path(env)
    from torch.utils.cpp_extension import _get_build_directory  # noqa: PLC0415

    return Path(_get_build_directory("", verbose=False)).parent


def load_extension(name: str, sources: list[str], headers: Sequence[str] = ()) -> Optional[Any]:
    """Compile (first use) or load (cached) the C++ extension ``name`` built from ``csrc/<sources>``.

    The build name carries a hash of the sources and ``headers`` (also under ``csrc/``), so an
    edited kernel is rebuilt and never mistaken for a stale cached one. Returns None when it
    cannot be built (no compiler, ...); the reason is kept for :func:`extension_error`.
    Thread-safe; tries once per process.
    """
    if name in _EXTS or name in _FAILED:
        return _EXTS.get(name)
    with _LOCK:
        if name in _EXTS or name in _FAILED:
            return _EXTS.get(name)
        try:
            from torch.utils.cpp_extension import load  # noqa: PLC0415

            build = os.environ.get("TORCH_EXTENSIONS_DIR")
            if build:
                Path(build).mkdir(parents=True, exist_ok=True)
            digest = hashlib.sha1()
            for f in [*sources, *headers]:
                digest.update((CSRC / f).read_bytes())
            _EXTS[name] = load(
                name=f"{name}_{digest.hexdigest()[:10]}",
                sources=[str(CSRC / s) for s in sources],
                extra_cflags=["-O3", "-fopenmp", "-march=native", "-fno-math-errno"],
                extra_include_paths=[str(CSRC)],
                extra_ldflags=["-fopenmp"],
                verbose=False,
            )
        except Exception as e:  # noqa: BLE001 - the caller falls back to the torch reference
            msg = str(e).strip().splitlines()[0][:200] if str(e).strip() else ""
            _FAILED[name] = f"{type(e).__name__}: {msg}"
    return _EXTS.get(name)


def extension_error(name: str) -> Optional[str]:
    """Why extension ``name`` failed to build (None if it built or was never tried)."""
    return _FAILED.get(name)


def gsplat_available() -> bool:
    """True when CUDA is usable and ``gsplat`` imports (never imported on a CPU-only machine)."""
    import torch  # noqa: PLC0415

    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401, PLC0415
    except Exception:  # noqa: BLE001
        return False
    return True


def warn_once(key: str, message: str) -> None:
    """One-line warning, once per process and key."""
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(message, RuntimeWarning, stacklevel=3)


def resolve_backend(backend: str, device_type: str, ext_name: str, sources: list[str], headers: Sequence[str] = ()) -> str:
    """Turn a requested backend into the one that runs: ``"gsplat"``, ``"cpu"`` or ``"torch"``.

    ``"auto"``: gsplat on CUDA when importable; the extension on CPU when it builds; else torch
    (warning once). An explicit ``"cpu"`` that cannot build, or ``"gsplat"`` that is not usable,
    also falls back to torch with a warning rather than failing a training run.
    """
    if backend not in BACKENDS:
        raise ConfigError(f"unknown rasterization backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if backend == "torch":
        return "torch"
    if device_type == "cuda":
        if backend in ("auto", "gsplat") and gsplat_available():
            return "gsplat"
        if backend == "gsplat":
            warn_once("gsplat", "gsplat is not importable; rasterizing with the torch reference on the GPU")
        return "torch"
    if backend == "gsplat":
        warn_once("gsplat-cpu", "the gsplat backend needs CUDA tensors; using the CPU path")
    if load_extension(ext_name, sources, headers) is not None:
        return "cpu"
    warn_once(ext_name, f"rasterizer C++ extension unavailable, using the slow torch reference ({extension_error(ext_name)})")
    return "torch"
