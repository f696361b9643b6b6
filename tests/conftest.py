"""Shared test setup: caches in known places, small thread count, deterministic seeds."""

import os
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("XDG_CACHE_HOME", str(_ROOT / ".cache"))
os.environ.setdefault("TORCH_EXTENSIONS_DIR", str(_ROOT / ".cache" / "torch_extensions"))
os.environ.setdefault("MPLCONFIGDIR", str(_ROOT / ".cache" / "matplotlib"))

import pytest


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory):
    """A tiny analytic nerfstudio dataset (ground plane, sky, transient patches)."""
    from tiny_scene import write_tiny_scene

    return write_tiny_scene(tmp_path_factory.mktemp("tiny_scene"))
