"""The small synthetic street (~48x32 px, generated once per session) that the data and masks tests
share; their conftests import these fixtures."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

SMALL = dict(width=48, height=32, num_train=6, num_street=2, num_bev=3, num_val_street=2, num_val_bev=2, num_lane=2,
             num_val_lane=2, num_cars=4,
             spp=2, num_points=300, progress=False)


def small_config(out: Path, seed: int = 0, **kw) -> SynthStreetConfig:
    return SynthStreetConfig(out=out, seed=seed, **{**SMALL, **kw})


@pytest.fixture(scope="session")
def make_config():
    """``make_config(out, seed=0, **overrides)`` -> a small :class:`SynthStreetConfig`."""
    return small_config


@pytest.fixture(scope="session")
def small_street(tmp_path_factory) -> Path:
    """The small street dataset (read-only: copy it with ``street_copy`` before changing it)."""
    out = tmp_path_factory.mktemp("street") / "street"
    generate_street(small_config(out))
    return out


@pytest.fixture
def street_copy(small_street, tmp_path) -> Path:
    """A private copy of the small street that a test may modify."""
    dst = tmp_path / "street"
    shutil.copytree(small_street, dst, ignore=shutil.ignore_patterns(".ns2gs_cache"))
    return dst
