"""The warped-conditioned enhancer (``ns2gs-enhance train --condition warped``): its 4-channel
reference (a real view warped in through rendered depth, and where that warp is valid), the
training pairs' conditions (never the pair's own target view), the ONNX export run through the
runtime with its reference input, the augmentation feeding it, and the default path unchanged."""

import dataclasses
import json
import math
from types import SimpleNamespace

import pytest
import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.enhancer.pairs import perturb_pose
from nerf2gs_plugin.enhancer.warp import clear_mask, condition_source, nearest_camera, ray_depth, warped_reference
from nerf2gs_plugin.errors import ConfigError


def _camera(c2w: torch.Tensor, w: int = 64, h: int = 48, f: float = 40.0) -> Cameras:
    return Cameras(camera_to_worlds=c2w[None], fx=torch.tensor([f]), fy=torch.tensor([f]), cx=torch.tensor([w / 2]),
                   cy=torch.tensor([h / 2]), width=torch.tensor([w]), height=torch.tensor([h]))


def _street_camera(height: float, pitch_deg: float, x: float = 0.0) -> torch.Tensor:
    """Looking along +y, pitched down, at (x, 0, height); z is up (OpenGL camera axes)."""
    p = math.radians(pitch_deg)
    forward = torch.tensor([0.0, math.cos(p), -math.sin(p)])
    right = torch.tensor([1.0, 0.0, 0.0])
    up = torch.linalg.cross(right, forward)
    return torch.stack([right, up, -forward, torch.tensor([x, 0.0, height])], 1)


def _ground(camera: Cameras) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Analytic render of the textured plane z = 0: (rgb ``[H, W, 3]``, ray depth ``[H, W, 1]``, points ``[H*W, 3]``)."""
    h, w = int(camera.height[0]), int(camera.width[0])
    rays = camera.generate_rays(0)
    t = -rays.origins[:, 2] / rays.directions[:, 2]
    p = rays.origins + rays.directions * t[:, None]
    rgb = torch.stack([0.5 + 0.4 * torch.sin(p[:, 0] * 1.3), 0.5 + 0.4 * torch.cos(p[:, 1] * 0.9), 0.5 + 0.2 * torch.sin(p[:, 0] + p[:, 1])], -1)
    return rgb.reshape(h, w, 3), t.reshape(h, w, 1), p


def _projects_inside(points: torch.Tensor, camera: Cameras) -> torch.Tensor:
    """Bool ``[P]``: the points fall inside ``camera``'s image, in front of it (a pinhole projection written out)."""
    c2w = camera.camera_to_worlds[0]
    local = (points - c2w[:, 3]) @ c2w[:, :3]
    z = -local[:, 2]
    u = camera.cx[0] + camera.fx[0] * local[:, 0] / z
    v = camera.cy[0] - camera.fy[0] * local[:, 1] / z
    return (z > 0) & (u >= 0) & (u <= camera.width[0]) & (v >= 0) & (v <= camera.height[0])


def test_warped_reference_copies_the_real_view_where_it_saw_and_is_zero_elsewhere():
    src = _camera(_street_camera(1.5, 20.0, x=0.8))
    src_rgb, src_depth, _ = _ground(src)
    raised = _camera(perturb_pose(_street_camera(1.5, 20.0), torch.tensor([0.0, 0.0, 1.0]), torch.Generator().manual_seed(3), metres=1.0))
    truth, depth, points = _ground(raised)
    ref = warped_reference(raised, depth, src, src_depth, src_rgb, torch.ones(1, 48, 64), "ray")
    assert ref.shape == (48, 64, 4)
    valid = ref[..., 3]
    assert set(valid.unique().tolist()) <= {0.0, 1.0} and 0.2 < float(valid.mean()) < 0.95
    # where it is valid the warped RGB is what the raised camera sees (the real view's texture)
    err = ((ref[..., :3] - truth).abs() * valid[..., None]).sum() / (valid.sum() * 3)
    assert err < 0.01, float(err)
    # a pixel whose surface point has no source pixel (outside the real view) is invalid, its RGB zero
    outside = ~_projects_inside(points, src).reshape(48, 64)
    assert outside.any() and (valid[outside] == 0).all() and (ref[..., :3][outside] == 0).all()
    # occluded in the real view (its depth says something nearer was there): invalid everywhere
    assert warped_reference(raised, depth, src, src_depth * 0.5, src_rgb, torch.ones(1, 48, 64))[..., 3].sum() == 0
    # transient pixels of the real view are never copied
    assert warped_reference(raised, depth, src, src_depth, src_rgb, torch.zeros(1, 48, 64))[..., 3].sum() == 0
    # camera-space z depth gives the same warp as ray depth (splatting references render z)
    z = lambda d, cam: d / ray_depth(torch.ones_like(d), cam, "z")  # noqa: E731  ray -> z: times cos
    same = warped_reference(raised, z(depth, raised), src, z(src_depth, src), src_rgb, torch.ones(1, 48, 64), "z")
    assert (same[..., 3] != valid).float().mean() < 0.01 and ((same - ref).abs()[..., :3] * (same[..., 3:] * valid[..., None])).max() < 1e-3


def test_clear_mask_and_nearest_camera():
    t = torch.zeros(10, 12, 1, dtype=torch.bool)
    t[5, 6] = True
    m = clear_mask(t, 10, 12)
    assert m.shape == (1, 10, 12) and m[0, 3:8, 4:9].sum() == 0 and m.sum() == 120 - 25  # grown by 2 px
    assert clear_mask(None, 4, 5).shape == (1, 4, 5) and clear_mask(None, 4, 5).min() == 1
    centres = torch.tensor([[0.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0]])
    assert nearest_camera(torch.tensor([0.9, 0, 0]), centres) == 1
    assert nearest_camera(centres[1], centres, exclude=1) == 0
    # the condition's source faces the same way: the other pass of a street, looking back, is never it
    fwd, back = _street_camera(1.5, 10.0), _street_camera(1.5, 10.0)
    back[:, :3] = back[:, :3] @ torch.diag(torch.tensor([-1.0, 1.0, -1.0]))  # turned 180 deg about up
    poses = torch.stack([back.clone(), fwd.clone(), fwd.clone()])
    poses[1, 0, 3], poses[2, 0, 3] = 0.5, 3.0  # the same-way cameras are farther than the turned one
    raised = _street_camera(6.0, 40.0)
    assert nearest_camera(raised[:, 3], poses[:, :, 3]) == 0 and condition_source(raised, poses) == 1
    assert condition_source(raised, poses, exclude=1) == 2 and condition_source(raised, poses[:1]) == 0  # none faces it: the nearest


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    """A voxel-grid reference trained 5 steps on the tiny scene (it renders depth along the ray)."""
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    torch.set_num_threads(1)
    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path_factory.mktemp("ref"),
                              max_num_iterations=5, steps_per_eval_image=0, progress=False, timestamp="ref")
    t = Trainer(cfg)
    t.setup()
    return t.train()


def test_conditioned_pairs_are_warped_from_another_view(tiny_scene, tiny_run):
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.enhancer.pairs import reference_pairs

    gen = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    plain = reference_pairs([tiny_run], tiny_scene, [1, 2], gen(), progress=False)
    cond = reference_pairs([tiny_run], tiny_scene, [1, 2], gen(), progress=False, condition_of={1: 2, 2: 3})
    assert [q.kind for q in cond] == ["pose", "perturbed"] * 2 and all(q.condition is None for q in plain)
    run = load_run(tiny_run, data=tiny_scene)
    imgs = run.pipeline.datamanager.train_images
    for p, q in zip(plain, cond):  # the pairs themselves are unchanged by conditioning
        assert torch.equal(p.render, q.render) and torch.equal(p.target, q.target) and torch.equal(p.mask, q.mask)
        assert q.condition.shape == (4, 24, 32) and q.condition_index == {1: 2, 2: 3}[q.index] != q.index
        valid = q.condition[3]
        assert set(valid.unique().tolist()) <= {0.0, 1.0} and (q.condition[:3] * (1 - valid)).abs().max() == 0
    # the pose pair's condition, recomputed: view j warped into camera i through the reference's depth
    with torch.no_grad():
        cam_i, cam_j = imgs.cameras[1], imgs.cameras[2]
        expect = warped_reference(cam_i, run.model.render_camera(cam_i)["depth"], cam_j, run.model.render_camera(cam_j)["depth"],
                                  imgs.image(2), clear_mask(imgs.mask("transient", 2), 24, 32), run.model.depth_along)
    assert cond[0].condition[3].sum() > 0 and torch.allclose(cond[0].condition, expect.permute(2, 0, 1), atol=1e-5)
    with pytest.raises(ValueError, match="another training view"):
        reference_pairs([tiny_run], tiny_scene, [1, 2], gen(), progress=False, condition_of={1: 2, 2: 2})


def test_train_warped_conditions_never_on_the_target_and_exports_the_kind(tiny_scene, tiny_run, tmp_path, monkeypatch):
    from nerf2gs_plugin.enhancer import pairs as pairs_mod
    from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig, train_enhancer
    from nerf2gs_plugin.enhancer import make_enhancer

    seen = []
    real = pairs_mod.reference_pairs
    monkeypatch.setattr(pairs_mod, "reference_pairs", lambda *a, **k: seen.extend(real(*a, **k)) or seen)
    out = tmp_path / "warped.onnx"
    report = train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=out, reference=(tiny_run,), condition="warped", steps=3, batch_size=2,
                                                crop=16, max_renders=4, holdout_every=4, checkpoints=1, progress=False,
                                                eval_splits=("street",)))
    held = {0, 4}
    assert seen and report.pairs == {"pose": 4, "perturbed": 4}
    for q in seen:  # every pair's condition: another view, never a held-out one
        assert q.condition is not None and q.condition_index != q.index and q.condition_index not in held
    assert {q.index for q in seen} >= held  # held-out views are scored with their conditions too
    enh = make_enhancer(f"onnx:{out}")
    assert enh.reference_kind == "warped" and enh.runtime.reference_name == "reference"
    import onnx

    meta = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert meta["reference_kind"] == "warped" and meta["nerf2gs.condition"] == "warped"
    assert json.loads((tmp_path / "warped.report.json").read_text())["config"]["condition"] == "warped"
    with pytest.raises(ConfigError, match="needs --reference"):
        train_enhancer(EnhancerTrainConfig(data=tiny_scene, out=tmp_path / "x.onnx", condition="warped", steps=1, progress=False))


def test_onnx_round_trip_with_the_warped_reference_equals_torch(tmp_path):
    from nerf2gs_plugin.enhancer.unet import ResidualUNet, export_onnx
    from nerf2gs_plugin.enhancer.onnx_runtime import OnnxEnhancer

    torch.manual_seed(0)
    net = ResidualUNet(8, condition=True, reference_channels=4)
    with torch.no_grad():  # a trained-looking head (it starts at zero: the identity)
        net.head.weight.normal_(0, 0.05)
        net.head.bias.normal_(0, 0.05)
    path = tmp_path / "w.onnx"
    path.write_bytes(export_onnx(net, path, {"overlap": "8"}))
    rt = OnnxEnhancer(path)
    assert rt.reference_kind == "warped" and rt.reference_name == "reference"
    img = torch.rand(24, 32, 3)
    ref = torch.cat([torch.rand(24, 32, 3), (torch.rand(24, 32, 1) > 0.5).float()], -1)
    with torch.no_grad():
        want = net(img.permute(2, 0, 1)[None], ref.permute(2, 0, 1)[None])[0].permute(1, 2, 0)
        want_none = net(img.permute(2, 0, 1)[None])[0].permute(1, 2, 0)
    got = rt.enhance(img, reference=ref)
    assert (got - want).abs().max() < 1e-5 and (got - img).abs().max() > 1e-3  # the reference matters...
    assert (rt.enhance(img) - want_none).abs().max() < 1e-5  # ...and without one, no valid warped pixel (zeros)
    assert (rt.enhance(img) - got).abs().max() > 1e-4
    # tiled (24 px tiles, 8 px overlap: smaller than the U-Net's reach, so not exact) the reference
    # tiles line up with the image's: the same image within rounding of an 8-bit PNG
    assert (OnnxEnhancer(path, tile_size=24).enhance(img, reference=ref) - want).abs().max() < 2e-3
    with pytest.raises(ConfigError, match="warped reference view"):
        rt.enhance(img, reference=torch.rand(24, 32, 3))  # a plain image is not a warped reference
    (tmp_path / "w.onnx.json").write_text(json.dumps({"reference_kind": "depth"}))
    with pytest.raises(ConfigError, match="reference_kind must be"):
        OnnxEnhancer(path)


class _Recorder:
    """An enhancer that records the reference it is given and returns the image unchanged."""

    def __init__(self, kind: str):
        self.reference_kind, self.refs = kind, []

    def enhance(self, rgb, reference=None):
        self.refs.append(reference)
        return rgb

    def cache_key(self):
        return f"recorder-{self.reference_kind}"


def test_augmentation_feeds_each_birds_eye_view_its_reference(tiny_scene, tiny_run, tmp_path):
    from nerf2gs_plugin.augment.datamanager import AugmentConfig, render_augmented_views
    from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
    from nerf2gs_plugin.runs.load import load_run

    run = load_run(tiny_run, data=tiny_scene)
    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    train = dm.train_images
    world = SimpleNamespace(up=torch.tensor([0.0, 0.0, 1.0]), metres_to_world=lambda m: m / 10)  # delta-h 3 m: 0.3 units
    cfg = AugmentConfig(composites=False, delta_h=3.0, min_coverage=0.0, use_cache=False, view_downscale=1)
    with torch.no_grad():
        default, warped = _Recorder("image"), _Recorder("warped")
        v1 = render_augmented_views(train, world, run.model.render_camera, "ref:a", "d", tmp_path, cfg, default, depth_along="ray")
        v2 = render_augmented_views(train, world, run.model.render_camera, "ref:b", "d", tmp_path, cfg, warped, depth_along="ray")
        # default: the source training view as it is (unchanged behaviour)
        kept = v1.manifest.extra_indices
        assert len(default.refs) == len(kept) > 0
        for ref, j in zip(default.refs, kept):
            assert torch.equal(ref, train.image(j).cpu())
        # warped: the nearest training view warped into the bird's-eye camera through its render's depth
        bev = v2.extra.cameras
        assert len(warped.refs) == len(bev)
        for k, ref in enumerate(warped.refs):
            cam = bev[k]
            src = condition_source(cam.camera_to_worlds[0], train.cameras.camera_to_worlds)
            expect = warped_reference(cam, run.model.render_camera(cam)["depth"], train.cameras[src],
                                      run.model.render_camera(train.cameras[src])["depth"], train.image(src),
                                      clear_mask(train.mask("transient", src), 24, 32), "ray")
            assert ref.shape == (24, 32, 4) and torch.allclose(ref, expect, atol=1e-5)


def test_default_is_unconditioned(tiny_scene, tmp_path):
    """--condition none (the default): one input, no reference metadata, the network of before."""
    import onnx

    from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig, train_enhancer
    from nerf2gs_plugin.enhancer.unet import ResidualUNet
    from nerf2gs_plugin.enhancer import make_enhancer

    cfg = EnhancerTrainConfig(data=tiny_scene, out=tmp_path / "d.onnx", steps=2, batch_size=2, crop=16, progress=False, eval_splits=("street",))
    assert cfg.condition == "none"
    train_enhancer(cfg)
    model = onnx.load(str(cfg.out))
    assert [i.name for i in model.graph.input] == ["image"]
    assert not {"reference_input", "reference_kind", "nerf2gs.condition"} & {p.key for p in model.metadata_props}
    assert make_enhancer(f"onnx:{cfg.out}").reference_kind == "image"
    net = ResidualUNet()
    assert not net.condition and net.enc1[0].in_channels == 3 and ResidualUNet(16, True).enc1[0].in_channels == 6
