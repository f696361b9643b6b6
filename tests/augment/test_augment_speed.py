"""The augmentation renders no more than it needs: composites only under their masks, every bird's-eye
view on its own key (reused across entries, after a cut-short render, and from entries written before)."""

import dataclasses
import shutil

import pytest
import torch

from nerf2gs_plugin.augment.cache import VIEWS_DIR_NAME
from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference, composite_weight
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig


class Renderer:
    """A stand-in reference: an image that depends on the camera and the pixel, counting cameras and pixels."""

    def __init__(self, fail_at: int = -1):
        self.calls = self.pixels = 0
        self.fail_at = fail_at

    def __call__(self, camera, pixels=None):
        if self.calls == self.fail_at:
            raise KeyboardInterrupt
        self.calls += 1
        h, w = int(camera.height[0]), int(camera.width[0])
        yy, xx = torch.meshgrid(torch.linspace(0, 1, h), torch.linspace(0, 1, w), indexing="ij")
        shift = float(camera.camera_to_worlds[0, :, 3].sum()) % 1.0
        out = {"rgb": torch.stack([yy, xx, (yy + xx + shift) % 1.0], -1), "depth": torch.full((h, w, 1), 2.0),
               "accumulation": torch.ones(h, w, 1)}
        if pixels is not None:
            self.pixels += int(pixels.sum())
            out = {k: torch.where(pixels[..., None], v, torch.zeros_like(v)) for k, v in out.items()}
        else:
            self.pixels += h * w
        return out


def _views(data, root, render, cfg, pixels=False):
    dm = FullImageDataManagerConfig().setup(data=data, device="cpu")
    ref = Reference(render, "ref:abc", root, render_pixels=(lambda c, p: render(c, p)) if pixels else None)
    return dm, AugmentedDataManager(dm, ref, cfg).views


CFG = AugmentConfig(delta_h=2.0, min_coverage=0.0)


def _extra_bytes(views):
    return [p.read_bytes() for p in sorted((views.cache_dir / "extra").glob("*.png"))]


def test_bird_eye_views_are_reused_when_only_the_composites_change(tiny_scene, tmp_path):
    r1 = Renderer()
    dm, first = _views(tiny_scene, tmp_path, r1, CFG)
    n_bev = len(dm.extra_images)
    assert n_bev > 0 and r1.calls > n_bev  # composites and bird's-eye views
    r2 = Renderer()
    _, second = _views(tiny_scene, tmp_path, r2, dataclasses.replace(CFG, composites=False))
    assert second.cache_dir != first.cache_dir and not second.reused  # another entry ...
    assert r2.calls == 0  # ... with nothing rendered again
    assert _extra_bytes(second) == _extra_bytes(first)
    r3 = Renderer()  # --augment.use-cache False renders again
    _views(tiny_scene, tmp_path, r3, dataclasses.replace(CFG, composites=False, use_cache=False))
    assert r3.calls == n_bev


def test_a_cut_short_render_keeps_the_views_it_finished(tiny_scene, tmp_path):
    cfg = dataclasses.replace(CFG, composites=False)
    with pytest.raises(KeyboardInterrupt):
        _views(tiny_scene, tmp_path, Renderer(fail_at=3), cfg)
    r = Renderer()
    dm, views = _views(tiny_scene, tmp_path, r, cfg)
    assert r.calls == len(dm.extra_images) - 3
    clean = Renderer()
    _, again = _views(tiny_scene, tmp_path / "clean", clean, cfg)
    assert _extra_bytes(views) == _extra_bytes(again)


def test_entries_written_before_the_view_store_are_read(tiny_scene, tmp_path):
    dm, first = _views(tiny_scene, tmp_path, Renderer(), CFG)
    shutil.rmtree(tmp_path / "augment_cache" / VIEWS_DIR_NAME)  # what an older version left: the entry alone
    r = Renderer()
    _, second = _views(tiny_scene, tmp_path, r, dataclasses.replace(CFG, composites=False))
    assert r.calls == 0 and _extra_bytes(second) == _extra_bytes(first)
    stricter = Renderer()  # the old entry kept its views at min_coverage 0: it cannot answer for 0.5
    _views(tiny_scene, tmp_path, stricter, dataclasses.replace(CFG, composites=False, min_coverage=0.5))
    assert stricter.calls == len(dm.extra_images)


def test_composites_render_only_the_pixels_they_paste(tiny_scene, tmp_path):
    cfg = dataclasses.replace(CFG, extra_views=False, dilate_px=2, feather_px=1)
    full = Renderer()
    dm, whole = _views(tiny_scene, tmp_path / "whole", full, cfg)
    part = Renderer()
    _, masked = _views(tiny_scene, tmp_path / "masked", part, cfg, pixels=True)
    pngs = sorted(p.name for p in (whole.cache_dir / "composites").glob("*.png"))
    assert pngs and pngs == sorted(p.name for p in (masked.cache_dir / "composites").glob("*.png"))
    for name in pngs:
        assert (whole.cache_dir / "composites" / name).read_bytes() == (masked.cache_dir / "composites" / name).read_bytes()
    imgs = dm.train_images
    pasted = sum(int((composite_weight(imgs.mask("transient", i), 2, 1) > 0).sum()) for i in whole.manifest.composited_images)
    assert part.calls == full.calls == len(pngs) and part.pixels == pasted < full.pixels / 4
