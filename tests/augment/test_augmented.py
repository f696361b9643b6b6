import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference, composite
from nerf2gs_plugin.augment.geometry import ViewGeometry
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.errors import CheckpointError
from nerf2gs_plugin.registry import get_method

BIN = Path(sys.executable).parent


class CountingRenderer:
    """A stand-in reference: a constant grey image, counting its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, camera):
        self.calls += 1
        h, w = int(camera.height[0]), int(camera.width[0])
        return {"rgb": torch.full((h, w, 3), 0.3), "depth": torch.ones(h, w, 1)}


def _augment(dm, render, key, root, cfg):
    """The AugmentedDataManager over ``dm`` (the enhancer built as the engine builds it); its views."""
    from nerf2gs_plugin.augment.reference import build_enhancer

    return AugmentedDataManager(dm, Reference(render, key, root), cfg, build_enhancer(cfg.enhancer)).views


def _dm(data):
    return FullImageDataManagerConfig().setup(data=data, device="cpu")


def test_bev_poses_are_delta_h_metres_up_and_pitched(tiny_scene):
    dm = _dm(tiny_scene)
    td = dm.train_data
    assert abs(td.dataparser_scale - 1.0) > 0.1  # the normalisation is not the identity
    cams = ViewGeometry(10.0, 30.0, pitch_mode="relative").cameras(dm.train_images.cameras, td)
    rise = cams.centers - dm.train_images.cameras.centers
    # back in the original (metric) frame: exactly 10 m along the data's up (+z)
    R = td.dataparser_transform[:, :3]
    rise_orig = (rise / td.dataparser_scale) @ R  # R is orthonormal: inverse = transpose
    assert torch.allclose(rise_orig * td.metres_per_unit, torch.tensor([0.0, 0.0, 10.0]).expand_as(rise_orig), atol=1e-4)
    # pitch relative to the input view's forward: 30 degrees further down
    up = td.up / td.up.norm()
    f_in = -dm.train_images.cameras.camera_to_worlds[:, :, 2]
    f_out = -cams.camera_to_worlds[:, :, 2]
    pitch_in = torch.rad2deg(torch.asin((f_in @ up).clamp(-1, 1)))
    pitch_out = torch.rad2deg(torch.asin((f_out @ up).clamp(-1, 1)))
    assert torch.allclose(pitch_in - pitch_out, torch.full_like(pitch_in, 30.0), atol=1e-3)
    assert len(ViewGeometry(1.0, 30.0, every_n=3).cameras(dm.train_images.cameras, td)) == 3


def test_composite_changes_only_masked_pixels():
    real = torch.rand(20, 30, 3)
    render = torch.rand(20, 30, 3)
    mask = torch.zeros(20, 30, 1, dtype=torch.bool)
    mask[5:8, 10:14] = True
    out = composite(real, render, mask, dilate_px=0)
    assert torch.equal(out[mask[..., 0]], render[mask[..., 0]])
    assert torch.equal(out[~mask[..., 0]], real[~mask[..., 0]])
    grown = composite(real, render, mask, dilate_px=2)
    changed = (grown != real).any(-1)
    assert changed[3:10, 8:16].all() and not changed[:2].any() and not changed[:, :7].any()


def test_augmentation_cache_reuse_and_invalidation(tiny_scene, tmp_path):
    cfg = AugmentConfig(delta_h=3.0, theta_pitch=30.0)
    dm = _dm(tiny_scene)
    real = [dm.train_images.image(i).clone() for i in range(len(dm.train_images))]
    r1 = CountingRenderer()
    views = _augment(dm, r1, "ref:abc", tmp_path, cfg)
    n_transient = sum(bool(dm.train_images.mask("transient", i).any()) for i in range(len(dm.train_images)))
    assert r1.calls == n_transient + len(dm.train_images) and not views.reused
    # composites: only transient (dilated) pixels changed, images without transients untouched
    for i in range(len(real)):
        m = dm.train_images.mask("transient", i)
        diff = (dm.train_images.image(i) - real[i]).abs().amax(-1) > 1.5 / 255
        if not m.any():
            assert not diff.any()
        else:
            assert diff.any() and not diff[~torch.nn.functional.max_pool2d(m.float().permute(2, 0, 1)[None], 5, 1, 2)[0, 0].bool()].any()
    assert dm.extra_images is not None and len(dm.extra_images) == len(dm.train_images)
    assert 0 < dm.extra_prob < 1
    # same parameters: nothing rendered again
    r2 = CountingRenderer()
    views2 = _augment(_dm(tiny_scene), r2, "ref:abc", tmp_path, cfg)
    assert r2.calls == 0 and views2.reused and views2.cache_dir == views.cache_dir
    # a changed parameter or another reference re-renders
    r3 = CountingRenderer()
    _augment(_dm(tiny_scene), r3, "ref:abc", tmp_path, dataclasses.replace(cfg, delta_h=5.0))
    r4 = CountingRenderer()
    _augment(_dm(tiny_scene), r4, "ref:other", tmp_path, cfg)
    assert r3.calls > 0 and r4.calls > 0
    assert not list((tmp_path / "augment_cache").glob(".tmp-*"))  # no half-written entries


def test_interrupted_render_leaves_no_cache_entry(tiny_scene, tmp_path):
    class Failing(CountingRenderer):
        def __call__(self, camera):
            if self.calls == 3:
                raise KeyboardInterrupt
            return super().__call__(camera)

    with pytest.raises(KeyboardInterrupt):
        _augment(_dm(tiny_scene), Failing(), "ref:x", tmp_path, AugmentConfig(delta_h=2.0))
    assert not [p for p in (tmp_path / "augment_cache").iterdir() if not p.name.startswith(".tmp-")]
    r = CountingRenderer()
    _augment(_dm(tiny_scene), r, "ref:x", tmp_path, AugmentConfig(delta_h=2.0))
    assert r.calls > 0


def _train_voxel(data, out, steps=20, **kw):
    cfg = dataclasses.replace(get_method("voxel-grid").config, data=data, output_dir=out, max_num_iterations=steps,
                              steps_per_eval_image=0, progress=False, timestamp="run", **kw)
    t = Trainer(cfg)
    t.setup()
    return t.train()


def test_plugin_trains_with_augment_from_cli(tiny_scene, tmp_path):
    ref = _train_voxel(tiny_scene, tmp_path / "ref")
    p = subprocess.run([str(BIN / "ns2gs-train"), "voxel-grid", "--data", str(tiny_scene), "--augment-from", str(ref),
                        "--augment.delta-h", "2", "--augment.min-coverage", "0", "--max-num-iterations", "10", "--progress", "False",
                        "--output-dir", str(tmp_path / "tgt")], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    manifests = list((ref / "augment_cache").glob("*/manifest.json"))
    assert len(manifests) == 1
    # the CLI flags reached the augmentation: composites of the transient images, one bird's-eye view per
    # training view, raised by --augment.delta-h 2 metres above it
    import json

    from nerf2gs_plugin.data import parse_dataset

    man = json.loads(manifests[0].read_text())
    train = parse_dataset(tiny_scene, "train")
    assert man["config"]["delta_h"] == 2.0 and man["num_extra"] == len(train) and man["composited_images"]
    extra = torch.tensor(man["extra_camera_to_worlds"])
    assert (manifests[0].parent / "extra" / "00000.png").is_file()
    rise = (extra[:, :3, 3] - train.cameras.camera_to_worlds[:, :3, 3]) @ train.up
    assert torch.allclose(rise, torch.full_like(rise, float(train.metres_to_world(2.0))), atol=1e-4)
    cfg = (next((tmp_path / "tgt").rglob("config.yml"))).read_text()
    assert str(ref) in cfg and "delta_h: 2.0" in cfg
    log = json.loads(next((tmp_path / "tgt").rglob("train_log.json")).read_text())
    assert log["reference_render_seconds"] > 0  # reported with the training time


def test_bad_references(tiny_scene, tmp_path):
    from tiny_scene import write_tiny_scene

    other = write_tiny_scene(tmp_path / "other", n_train=6)
    ref_other = _train_voxel(other, tmp_path / "ref_other", steps=2)
    with pytest.raises(CheckpointError, match="different dataset"):
        _train_voxel(tiny_scene, tmp_path / "t1", steps=2, augment_from=ref_other)
    with pytest.raises(CheckpointError, match="no such run directory"):
        _train_voxel(tiny_scene, tmp_path / "t2", steps=2, augment_from=tmp_path / "missing")
    empty = tmp_path / "empty_run"
    empty.mkdir()
    with pytest.raises(CheckpointError, match="holds no checkpoints"):
        _train_voxel(tiny_scene, tmp_path / "t3", steps=2, augment_from=empty)


def test_augmented_datamanager_wraps_a_plugin_datamanager(tiny_scene, tmp_path):
    """The third-party voxel-grid method's (ray) DataManager, wrapped: a DataManager itself, real
    rays plus bird's-eye rays in its batches, the inner manager's checkpoint state."""
    from nerf2gs_plugin.datamanagers.base import DataManager

    inner = get_method("voxel-grid").config.pipeline.datamanager.setup(data=tiny_scene, device="cpu")
    n_real = len(inner.train_images)
    dm = AugmentedDataManager(inner, Reference(CountingRenderer(), "ref:plugin", tmp_path), AugmentConfig(delta_h=3.0, every_n=2))
    assert isinstance(dm, DataManager) and type(inner).__name__ == "RayDataManager"
    assert dm.train_data is inner.train_data and dm.eval_split_names() == inner.eval_split_names()
    assert len(dm.extra_images) == n_real // 2 and dm.every_n == 2
    assert dm.all_train_cameras.camera_to_worlds.shape[0] == n_real + n_real // 2
    rays, batch = dm.next_train(0)
    assert (batch["image_idx"] >= n_real).any() and (batch["image_idx"] < n_real).any()
    assert set(dm.state_dict()) == set(inner.state_dict())
    assert dm.manifest.num_extra == n_real // 2 and dm.manifest.path.parent == dm.views.cache_dir
    assert not hasattr(inner, "augmented_views") and not hasattr(inner, "original_train_images")


def test_read_manifest_is_the_one_reader(tiny_scene, tmp_path, monkeypatch):
    """The viewer finds the bird's-eye views through read_manifest; a bad manifest is refused."""
    import json
    from types import SimpleNamespace

    from nerf2gs_plugin.augment import cache as augment_cache
    from nerf2gs_plugin.viewer.scene import find_extra_views

    aug = AugmentConfig(delta_h=3.0, composites=False)
    dm = AugmentedDataManager(_dm(tiny_scene), Reference(CountingRenderer(), "ref:m", tmp_path), aug)
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "step-000000001.ckpt").write_bytes(b"resolved, never loaded")
    calls = []
    real = augment_cache.read_manifest
    monkeypatch.setattr(augment_cache, "read_manifest", lambda p: calls.append(p) or real(p))
    found = find_extra_views(SimpleNamespace(augment_from=tmp_path, augment=aug), dm.train_data, dm.original_train_images.cameras)
    assert calls and found.source == str(dm.manifest.path)
    assert torch.allclose(found.cameras.camera_to_worlds, dm.extra_images.cameras.camera_to_worlds)
    doc = json.loads(dm.manifest.path.read_text())
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**doc, "format_version": 99}))
    with pytest.raises(ValueError, match="cache format 99"):
        real(bad)
    bad.write_text(json.dumps({k: v for k, v in doc.items() if k != "num_extra"}))
    with pytest.raises(ValueError, match="malformed"):
        real(bad)


def test_real_only_from_ends_on_the_input_views(tiny_scene, tmp_path):
    """--augment.real-only-from 0.5 over 40 steps: bird's-eye views are drawn before step 20, never
    after; the default (1.0) draws them to the end; a fraction outside (0, 1] is refused."""
    from nerf2gs_plugin.errors import ConfigError

    def drawn(frac):
        dm = AugmentedDataManager(_dm(tiny_scene), Reference(CountingRenderer(), "ref:r", tmp_path),
                                  AugmentConfig(delta_h=3.0, extra_prob=0.5, real_only_from=frac), total_steps=40)
        n_real = len(dm.train_images)
        return [int(dm.next_train(s)[1]["image_idx"]) >= n_real for s in range(40)]

    half, full = drawn(0.5), drawn(1.0)
    assert any(half[:20]) and not any(half[20:])
    assert any(full[20:])
    assert half[:20] == full[:20]  # the same draws until the switch
    with pytest.raises(ConfigError, match="real-only-from"):
        drawn(0.0)


class PoseRecorder(CountingRenderer):
    """A stand-in reference that records the camera centre of every render."""

    def __init__(self):
        super().__init__()
        self.centres = []

    def __call__(self, camera):
        self.centres.append(camera.centers[0].clone())
        return super().__call__(camera)


@pytest.mark.parametrize("confidence", ["none", "visibility"])
def test_a_reference_with_refined_poses_renders_the_input_views_from_them(tiny_scene, tmp_path, confidence):
    """A camera optimizer's reference: composites (and the confidence's depths) are rendered at its
    refined training poses; the bird's-eye views and the target's cameras stay the dataset's."""
    dm = _dm(tiny_scene)
    cams = dm.train_images.cameras
    shift = torch.tensor([0.01, 0.02, -0.03])

    def refine(c):
        return c.with_poses(torch.cat([c.camera_to_worlds[:, :, :3], c.camera_to_worlds[:, :, 3:] + shift[:, None]], -1))

    rec = PoseRecorder()
    aug = AugmentConfig(delta_h=3.0, every_n=2, confidence=confidence)
    views = AugmentedDataManager(dm, Reference(rec, f"ref:refined-{confidence}", tmp_path, "z", refine), aug).views
    rendered = torch.stack(rec.centres)

    def was_rendered(c):
        return bool((rendered - c).norm(dim=-1).min() < 1e-6)

    comp = views.manifest.composited_images
    assert comp and all(was_rendered(cams.centers[i] + shift) and not was_rendered(cams.centers[i]) for i in comp)
    if confidence != "none":  # every input view's depth, from its refined pose
        assert all(was_rendered(cams.centers[i] + shift) for i in range(len(cams)))
    bev = ViewGeometry(3.0, aug.theta_pitch, 2, aug.pitch_mode).cameras(cams, dm.train_data)
    assert views.extra is not None
    assert all(was_rendered(c) for c in views.extra.cameras.centers)
    torch.testing.assert_close(views.extra.cameras.camera_to_worlds, bev[torch.tensor(views.manifest.extra_indices)].camera_to_worlds)
    assert torch.equal(views.composites.cameras.camera_to_worlds, cams.camera_to_worlds)


def test_extra_decay_gives_the_input_views_the_later_samples(tiny_scene, tmp_path):
    """--augment.extra-decay over 80 steps (real-only-from 1.0): the views from above are drawn about as
    often as without it in the first steps, far less in the second half, and the share falls to 0 at the end."""

    def drawn(decay):
        dm = AugmentedDataManager(_dm(tiny_scene), Reference(CountingRenderer(), "ref:r", tmp_path),
                                  AugmentConfig(delta_h=3.0, extra_prob=0.5, real_only_from=1.0, extra_decay=decay), total_steps=80)
        n_real = len(dm.train_images)
        draws = [int(dm.next_train(s)[1]["image_idx"]) >= n_real for s in range(80)]
        return draws, dm.extra_prob

    (flat, p_flat), (decayed, p_end) = drawn(False), drawn(True)
    assert p_flat == 0.5 and p_end < 0.5 / 70
    assert sum(decayed[40:]) < sum(flat[40:]) / 2
    assert sum(decayed[:10]) > 0



def test_extra_decay_floor_keeps_a_share_of_the_views_from_above(tiny_scene, tmp_path):
    """--augment.extra-decay-floor 0.5: the share falls to half of its full value at the end, not to 0."""
    dm = AugmentedDataManager(_dm(tiny_scene), Reference(CountingRenderer(), "ref:r", tmp_path),
                              AugmentConfig(delta_h=3.0, extra_prob=0.5, real_only_from=1.0, extra_decay=True,
                                            extra_decay_floor=0.5), total_steps=80)
    dm.next_train(40)
    assert dm.extra_prob == pytest.approx(0.5 * 0.75)
    dm.next_train(80)
    assert dm.extra_prob == pytest.approx(0.25)
