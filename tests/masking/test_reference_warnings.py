"""The masks stage's first reference trains without masks on purpose: StreetNeRF's warnings about
missing sky, ground and transient masks are not printed for it, but are for any other run without them."""

from __future__ import annotations

import dataclasses
import warnings

from nerf2gs_plugin.engine.config import read_config_doc
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.masking.mask_reference import ensure_reference
from nerf2gs_plugin.masks.maskless import maskless_view
from nerf2gs_plugin.registry import get_method

KINDS = ("sky", "ground", "transient")


def _mask_warnings(caught: list[warnings.WarningMessage]) -> list[str]:
    return [str(w.message) for w in caught if "the dataset has no" in str(w.message) and "masks" in str(w.message)]


def test_the_masks_reference_says_nothing_of_its_missing_masks(street_copy, tmp_path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ref = ensure_reference(street_copy, tmp_path / "reference", steps=1, progress=False, log=lambda s: None)
    assert _mask_warnings(caught) == []
    assert read_config_doc(ref / "config.yml")["config"]["pipeline"]["model"]["expect_masks"] is False


def test_a_streetnerf_run_without_masks_still_warns(street_copy, tmp_path):
    cfg = get_method("streetnerf").with_steps(1)
    cfg = dataclasses.replace(cfg, data=maskless_view(street_copy), run_dir=tmp_path / "sn", steps_per_eval_image=0, progress=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        Trainer(cfg).setup()
    said = _mask_warnings(caught)
    assert [k for k in KINDS if any(f"no {k} masks" in s for s in said)] == list(KINDS), said
