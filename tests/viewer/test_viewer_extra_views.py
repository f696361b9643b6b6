"""The viewer finds an augmented run's bird's-eye views in the reference's augment cache manifest."""

import shutil
from types import SimpleNamespace

import numpy as np
import torch

from nerf2gs_plugin.augment.datamanager import AugmentConfig, render_augmented_views
from nerf2gs_plugin.augment.geometry import ViewGeometry
from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint
from nerf2gs_plugin.registry import get_method
from nerf2gs_plugin.viewer.scene import find_extra_views


def _constant_render(cam):
    h, w = int(cam.height[0]), int(cam.width[0])
    return {"rgb": torch.tensor([0.2, 0.8, 0.4]).expand(h, w, 3).clone(), "depth": torch.ones(h, w, 1)}


def test_extra_views_from_manifest_then_recomputed(tiny_scene, tmp_path):
    dm = get_method("voxel-grid").config.pipeline.datamanager.setup(data=tiny_scene, device="cpu")
    td = dm.train_data
    ref = tmp_path / "reference_run"
    (ref / "checkpoints").mkdir(parents=True)
    (ref / "checkpoints" / "step-000000009.ckpt").write_bytes(b"only resolved, never loaded here")
    aug = AugmentConfig(delta_h=3.0, theta_pitch=40.0, every_n=2, composites=False)
    views = render_augmented_views(dm.train_images, td, _constant_render, "ref:test",
                                   dataset_fingerprint(td.image_filenames), ref, aug)
    expected = ViewGeometry.of(aug).cameras(dm.train_images.cameras, td)
    config = SimpleNamespace(augment_from=ref, augment=aug)

    found = find_extra_views(config, td, dm.train_images.cameras, thumb_side=16)
    assert found.source == str(views.cache_dir / "manifest.json")
    assert len(found.cameras) == 4 and torch.allclose(found.cameras.camera_to_worlds, expected.camera_to_worlds, atol=1e-5)
    # independently of ViewGeometry: every 2nd training camera, raised by delta_h along up, same heading,
    # pitched 40 deg below the horizon (--augment.pitch-mode absolute, the default)
    train_c2w = dm.train_images.cameras.camera_to_worlds[::2]
    got = found.cameras.camera_to_worlds
    up = td.up / td.up.norm()
    assert torch.allclose(got[:, :, 3], train_c2w[:, :, 3] + td.metres_to_world(3.0) * up, atol=1e-5)
    fwd_t, fwd_g = -train_c2w[:, :, 2], -got[:, :, 2]
    elev = lambda f: torch.rad2deg(torch.asin((f @ up).clamp(-1, 1)))  # noqa: E731
    assert torch.allclose(elev(fwd_g), torch.full_like(elev(fwd_g), -40.0), atol=1e-3) and not torch.allclose(elev(fwd_t), -40 + 0 * elev(fwd_t))
    heading = lambda f: torch.nn.functional.normalize(f - (f @ up)[:, None] * up, dim=-1)  # noqa: E731
    assert torch.allclose(heading(fwd_g), heading(fwd_t), atol=1e-4)
    thumb = found.thumbnails[0]
    assert thumb is not None and max(thumb.shape[:2]) == 16
    np.testing.assert_allclose(thumb.reshape(-1, 3).mean(0), [51, 204, 102], atol=2)  # the reference's render

    other = SimpleNamespace(augment_from=ref, augment=AugmentConfig(delta_h=5.0, theta_pitch=40.0, every_n=2))
    recomputed = find_extra_views(other, td, dm.train_images.cameras)
    assert recomputed.source.startswith("recomputed") and recomputed.thumbnails == [None] * 4
    assert not torch.allclose(recomputed.cameras.camera_to_worlds, expected.camera_to_worlds)

    shutil.rmtree(ref / "augment_cache")
    gone = find_extra_views(config, td, dm.train_images.cameras)
    assert gone.source.startswith("recomputed") and torch.allclose(gone.cameras.camera_to_worlds, expected.camera_to_worlds, atol=1e-5)
    assert find_extra_views(SimpleNamespace(augment_from=None, augment=aug), td, dm.train_images.cameras) is None
