"""The augmentation's bird's-eye views rendered side by side in forked workers (``Reference.render_workers``):
the same views, in the same order, as one after another; the view store filled the same way."""

import dataclasses

from augment.test_augment_speed import CFG, Renderer, _extra_bytes
from nerf2gs_plugin.augment.cache import VIEWS_DIR_NAME
from nerf2gs_plugin.augment.datamanager import AugmentedDataManager, Reference
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig


def _views(data, root, workers: int):
    dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
    ref = Reference(Renderer(), "ref:abc", root, render_workers=workers)
    return dm, AugmentedDataManager(dm, ref, dataclasses.replace(CFG, composites=False)).views


def test_views_rendered_in_workers_equal_those_rendered_one_by_one(tiny_scene, tmp_path):
    dm, one = _views(tiny_scene, tmp_path / "one", 1)
    _, two = _views(tiny_scene, tmp_path / "two", 2)
    assert len(dm.extra_images) > 2 and _extra_bytes(two) == _extra_bytes(one)
    stored = sorted(p.name for p in (tmp_path / "two").rglob(f"{VIEWS_DIR_NAME}/*.png"))
    assert stored == sorted(p.name for p in (tmp_path / "one").rglob(f"{VIEWS_DIR_NAME}/*.png")) and stored
