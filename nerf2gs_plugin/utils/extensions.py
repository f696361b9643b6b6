"""The one loader of the C++/OpenMP kernels (rasterizers, hash grid): compiled on first use with
``torch.utils.cpp_extension.load``, cached under ``TORCH_EXTENSIONS_DIR`` and reloaded afterwards.

A kernel that fails to build on a machine that has a C++ compiler is an error
(:class:`KernelBuildError`), not a silent ten-times-slower torch fallback: a broken kernel must
fail the test suite. Machines without a compiler set ``NERF2GS_ALLOW_NO_KERNELS=1``; the kernels
then fall back to the torch reference (the reason printed once, and reported in pytest's summary).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence

from nerf2gs_plugin.errors import UserError

OPT_OUT_ENV = "NERF2GS_ALLOW_NO_KERNELS"
CFLAGS = ("-O3", "-fopenmp", "-march=native")

_EXTS: dict[str, Any] = {}
_FAILED: dict[str, str] = {}
_LOCK = threading.Lock()
_BUILD_SECONDS = [0.0]


class KernelBuildError(UserError):
    """A C++ kernel did not build although a compiler is present."""


def kernels_opted_out() -> bool:
    """True when ``NERF2GS_ALLOW_NO_KERNELS`` asks for the torch fallback instead of an error."""
    return os.environ.get(OPT_OUT_ENV, "").strip().lower() not in ("", "0", "false", "no")


def compiler_available() -> bool:
    """True when the C++ compiler torch would call (``$CXX`` or ``c++``) is on the PATH."""
    return shutil.which(os.environ.get("CXX", "c++")) is not None


def extension_cache_dir() -> Path:
    """The folder torch builds each extension's folder in: ``$TORCH_EXTENSIONS_DIR``, or torch's default
    with its ``py<ver>_<accelerator>`` level (where the built ``.so`` and torch's lock live)."""
    env = os.environ.get("TORCH_EXTENSIONS_DIR")
    if env:
        return Path(env)
    from torch.utils.cpp_extension import _get_build_directory  # noqa: PLC0415 - torch is heavy; only on first build

    return Path(_get_build_directory("", verbose=False))  # ".../py311_cpu/": Path drops the slash, not the level


def _build_name(name: str, sources: Sequence[Path], headers: Sequence[Path], cflags: Sequence[str] = CFLAGS) -> str:
    """``name`` plus a hash of every source and header, the flags, torch's version and, for
    ``-march=native``, the CPU: an edited kernel is rebuilt, never stale, and a kernel built for
    another CPU (a home folder shared by several machines) is never loaded."""
    import torch

    digest = hashlib.sha1()
    for f in [*sources, *headers]:
        digest.update(Path(f).read_bytes())
    digest.update(" ".join([*cflags, torch.__version__]).encode())
    if "-march=native" in cflags:
        digest.update(_cpu_key().encode())
    return f"{name}_{digest.hexdigest()[:10]}"


def _cpu_key() -> str:
    """The CPU's model and instruction-set flags (what ``-march=native`` compiles for)."""
    import platform

    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.machine() + platform.processor()
    keep = [ln.split(":", 1)[1].strip() for ln in info.splitlines()
            if ln.split(":", 1)[0].strip() in ("model name", "flags", "Features", "CPU part")]
    return "|".join([platform.machine(), *dict.fromkeys(keep)])


def _load_built(build_name: str, folder: Path) -> Optional[Any]:
    """The module of a kernel already built in ``folder`` (None if none is, or it does not load).

    Loaded as it is: torch's ``load`` would hand it to ninja, which rebuilds whenever the sources'
    paths or times differ from the build's (another checkout, a fresh clone), although the build
    name already pins their content."""
    import importlib.util

    so = folder / f"{build_name}.so"
    if not so.is_file():
        return None
    try:
        spec = importlib.util.spec_from_file_location(build_name, so)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    except (ImportError, OSError):  # a build cut short: made again by torch's load
        so.unlink(missing_ok=True)
        return None


def load_extension(name: str, sources: Sequence[Path], headers: Sequence[Path] = (),
                   extra_cflags: Sequence[str] = CFLAGS) -> Optional[Any]:
    """Compile (first use) or load (cached) the C++ extension ``name`` from ``sources``.

    Returns the module; None when it cannot be built and the opt-out is set (the reason is kept
    for :func:`extension_error` and printed once). Raises :class:`KernelBuildError` when it cannot
    be built without the opt-out. Thread-safe; tries once per process.
    """
    if name in _EXTS:
        return _EXTS[name]
    with _LOCK:
        if name not in _EXTS and name not in _FAILED:
            t0 = time.perf_counter()
            _build(name, [Path(s) for s in sources], [Path(h) for h in headers], list(extra_cflags))
            _BUILD_SECONDS[0] += time.perf_counter() - t0
    if name in _FAILED:
        _raise_unless_opted_out(name)
    return _EXTS.get(name)


def build_seconds() -> float:
    """Wall seconds this process has spent compiling or loading kernels: a one-time cost that a
    training step which first needs a kernel pays, and that timings of training leave out."""
    return _BUILD_SECONDS[0]


def _build(name: str, sources: list[Path], headers: list[Path], cflags: list[str]) -> None:
    try:
        from torch.utils.cpp_extension import load  # noqa: PLC0415 - torch is heavy; only on first build

        build_name = _build_name(name, sources, headers, cflags)
        cache = extension_cache_dir()
        cache.mkdir(parents=True, exist_ok=True)
        with build_lock(cache / f"{build_name}.build-lock") as exclusive:
            # holding the build lock, no other process of ours is building this kernel: a torch lock
            # there was left by a killed build, and torch would wait on it forever
            _remove_stale_lock(cache / build_name / "lock", 0.0 if exclusive else STALE_LOCK_SECONDS)
            built = _load_built(build_name, cache / build_name)
            if built is not None:
                _EXTS[name] = built
                return
            print(f"compiling the {name} kernel (first use, about 1 min)...", file=sys.stderr, flush=True)
            include = sorted({str(h.parent) for h in headers})
            _EXTS[name] = load(name=build_name, sources=[str(s) for s in sources], extra_cflags=cflags,
                               extra_include_paths=include, extra_ldflags=["-fopenmp"], verbose=False)
    except Exception as e:  # noqa: BLE001 - reported below: an error, or the torch fallback when opted out
        msg = str(e).strip().splitlines()[0][:200] if str(e).strip() else ""
        _FAILED[name] = f"{type(e).__name__}: {msg}"
        print(f"the {name} kernel did not build: {_FAILED[name]}", file=sys.stderr, flush=True)


# A build takes 1-2 min on 2 cores; a lock this old was left by a build that was killed, and torch's
# FileBaton would wait on it forever. Only the fallback where no OS file lock can be taken (below).
STALE_LOCK_SECONDS = 20 * 60


@contextmanager
def build_lock(path: Path) -> Iterator[bool]:
    """Hold an OS lock on ``path`` (``flock``: released by the OS when the holder dies, killed or not)
    while building; waits while another process holds it. Yields True when it is held, False where
    the platform has no ``flock`` (then only the age of torch's own lock tells a killed build)."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield False
        return
    with open(path, "a+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield True
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


def _remove_stale_lock(lock: Path, max_age_s: float = STALE_LOCK_SECONDS) -> bool:
    """Delete torch's build ``lock`` when it is older than ``max_age_s`` (0: whatever its age; returns whether it did)."""
    import time

    try:
        age = time.time() - lock.stat().st_mtime
    except FileNotFoundError:
        return False
    if age < max_age_s:
        return False
    lock.unlink(missing_ok=True)
    print(f"removed a stale kernel-build lock ({lock}, left by a build that was killed)", file=sys.stderr, flush=True)
    return True


def _raise_unless_opted_out(name: str) -> None:
    if kernels_opted_out():
        return
    where = "a C++ compiler is on the PATH" if compiler_available() else "no C++ compiler was found"
    raise KernelBuildError(f"the {name} C++ kernel did not build ({_FAILED[name]}); {where}: fix the build, "
                           f"or set {OPT_OUT_ENV}=1 to run the slow torch reference instead")


def extension_error(name: str) -> Optional[str]:
    """Why extension ``name`` failed to build (None if it built or was never tried)."""
    return _FAILED.get(name)


def failed_extensions() -> dict[str, str]:
    """Every kernel that failed to build in this process, with the reason (for pytest's summary)."""
    return dict(_FAILED)
