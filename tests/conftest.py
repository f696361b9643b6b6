"""Shared test setup: caches in known places, small thread count, deterministic seeds."""

import os
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("XDG_CACHE_HOME", str(_ROOT / ".cache"))
os.environ.setdefault("TORCH_EXTENSIONS_DIR", str(_ROOT / ".cache" / "torch_extensions"))
os.environ.setdefault("MPLCONFIGDIR", str(_ROOT / ".cache" / "matplotlib"))
if os.environ.get("PYTEST_XDIST_WORKER_COUNT"):  # pytest -n N: the cores shared out, not N x all of them
    os.environ.setdefault("OMP_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // int(os.environ["PYTEST_XDIST_WORKER_COUNT"]))))

import pytest


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory):
    """A tiny analytic nerfstudio dataset (ground plane, sky, transient patches)."""
    from tiny_scene import write_tiny_scene

    return write_tiny_scene(tmp_path_factory.mktemp("tiny_scene"))


def pytest_terminal_summary(terminalreporter):
    """Say once when C++ kernels ran on the torch fallback because NERF2GS_ALLOW_NO_KERNELS allowed it
    (without it, a kernel that does not build fails the tests that use it)."""
    from nerf2gs_plugin.utils.extensions import OPT_OUT_ENV, failed_extensions, kernels_opted_out

    failed = {k: v for k, v in failed_extensions().items() if not k.startswith("nerf2gs_test_")}
    if kernels_opted_out():
        if getattr(terminalreporter.config.option, "numprocesses", None):  # the workers built them, not this process
            what = "the workers' kernels; run without -n to list those that failed"
        else:
            what = "; ".join(f"{k}: {v}" for k, v in failed.items()) or "every kernel built"
        terminalreporter.write_line(f"{OPT_OUT_ENV} is set: kernels that did not build ran on the torch reference ({what})",
                                    yellow=True)
