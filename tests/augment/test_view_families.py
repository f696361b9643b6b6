"""View families: each family's cameras on a known pose, the cache and manifest with several
families, the bird's-eye default's unchanged cache key, and a tiny training run with two families."""

import dataclasses
import json
import math
import subprocess
import sys
from dataclasses import asdict
from types import SimpleNamespace

import pytest
import torch

from nerf2gs_plugin.augment.cache import cache_key, read_manifest
from nerf2gs_plugin.augment.config import AugmentConfig, LaneShiftConfig, PosesFileConfig, RaiseConfig
from nerf2gs_plugin.augment.datamanager import find_cached_extra_views, render_augmented_views, same_families
from nerf2gs_plugin.augment.views import additional_views, get_family
from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.errors import ConfigError, DataError

UP = torch.tensor([0.0, 0.0, 1.0])


class World:
    """Half a world unit per metre (a scaled dataset), z up."""

    up = UP

    @staticmethod
    def metres_to_world(metres: float) -> float:
        return 0.5 * metres


def _rolled_camera(roll_deg: float = 20.0, pitch_deg: float = 10.0) -> Cameras:
    """One camera at (1, 2, 3) heading +x, pitched up and rolled about its viewing axis (OpenGL axes)."""
    r, p = math.radians(roll_deg), math.radians(pitch_deg)
    fwd = torch.tensor([math.cos(p), 0.0, math.sin(p)])
    left = torch.tensor([0.0, 1.0, 0.0])
    right = -left
    cam_up = torch.linalg.cross(right, fwd)  # OpenGL: x right, y up, z back
    # roll about the viewing axis
    right, cam_up = math.cos(r) * right + math.sin(r) * cam_up, -math.sin(r) * right + math.cos(r) * cam_up
    c2w = torch.stack([right, cam_up, -fwd, torch.tensor([1.0, 2.0, 3.0])], dim=1)[None]
    return Cameras(c2w, fx=20.0, fy=20.0, cx=16.0, cy=12.0, width=32, height=24)


def test_lane_shift_moves_along_the_ground_not_the_camera_roll():
    cam = _rolled_camera()
    assert abs(float(cam.camera_to_worlds[0, 2, 0])) > 0.3  # the camera's own x axis leaves the ground plane
    cfg = AugmentConfig(views=("lane-shift",), lane_shift=LaneShiftConfig(offsets=(-2.0, 4.0)))
    views = get_family("lane-shift").make(cam, World(), cfg)
    assert views.sources == [0, 0]
    c2w = views.cameras.camera_to_worlds
    # right of a +x heading with z up is -y; 0.5 world units per metre; no height change whatever the roll
    assert torch.allclose(c2w[:, :, 3], torch.tensor([[1.0, 3.0, 3.0], [1.0, 0.0, 3.0]]), atol=1e-6)
    assert torch.allclose(c2w[:, :, :3], cam.camera_to_worlds[:, :, :3].expand(2, 3, 3))  # orientation kept
    # look-ahead: each view turns toward the point 10 m ahead on the input's line of travel
    turned = get_family("lane-shift").make(cam, World(), dataclasses.replace(cfg, lane_shift=LaneShiftConfig(offsets=(4.0,), look_ahead=10.0)))
    c2w = turned.cameras.camera_to_worlds[0]
    fwd = -c2w[:, 2]
    heading = torch.nn.functional.normalize(fwd[:2], dim=0)
    target = torch.tensor([1.0 + 5.0, 2.0]) - c2w[:2, 3]  # 10 m = 5 units ahead of the input camera, from the shifted centre
    assert torch.allclose(heading, torch.nn.functional.normalize(target, dim=0), atol=1e-5)
    assert math.isclose(float(fwd[2]), math.sin(math.radians(10.0)), abs_tol=1e-5)  # the pitch is untouched


def test_raise_and_birds_eye_and_pose_file(tmp_path):
    cam = Cameras.cat([_rolled_camera(0.0, 0.0), _rolled_camera(5.0, 0.0)])
    up = get_family("raise").make(cam, World(), AugmentConfig(raise_=RaiseConfig(heights=(2.0, 6.0))))
    assert up.sources == [0, 0, 1, 1]
    assert torch.allclose(up.cameras.camera_to_worlds[:, 2, 3], torch.tensor([4.0, 6.0, 4.0, 6.0]))
    assert torch.allclose(up.cameras.camera_to_worlds[:, :, :3], cam.camera_to_worlds[[0, 0, 1, 1], :, :3])  # no pitch
    bev = get_family("birds-eye").make(cam, World(), AugmentConfig(delta_h=10.0, theta_pitch=30.0))
    fwd = -bev.cameras.camera_to_worlds[:, :, 2]
    assert torch.allclose(bev.cameras.camera_to_worlds[:, 2, 3], torch.tensor([8.0, 8.0]))
    assert torch.allclose(fwd[:, 2], torch.full((2,), -0.5), atol=1e-5)  # 30 deg down
    # a user's file: a 3x4 and a 4x4 pose; each view takes the intrinsics of the nearest input camera
    far = torch.eye(4)
    far[:3, 3] = torch.tensor([1.0, 2.0, 30.0])
    path = tmp_path / "poses.json"
    path.write_text(json.dumps({"camera_to_worlds": [cam.camera_to_worlds[1].tolist(), far.tolist()]}))
    got = get_family("poses").make(cam, World(), AugmentConfig(poses=PosesFileConfig(file=path)))
    assert got.sources == [0, 0]  # both input cameras sit at (1, 2, 3): the first is the nearest
    assert torch.allclose(got.cameras.camera_to_worlds[1, :, 3], torch.tensor([1.0, 2.0, 30.0]))
    path.write_text(json.dumps({"camera_to_worlds": [[1, 2, 3]]}))
    with pytest.raises(DataError, match="poses.json.*malformed pose file"):
        get_family("poses").make(cam, World(), AugmentConfig(poses=PosesFileConfig(file=path)))
    with pytest.raises(ConfigError, match="unknown view family 'sideways'; known: birds-eye, lane-shift, raise, poses"):
        additional_views(cam, World(), AugmentConfig(views=("birds-eye", "sideways")))
    with pytest.raises(ConfigError, match="named twice"):
        additional_views(cam, World(), AugmentConfig(views=("raise", "raise")))


def test_default_config_keeps_its_cache_key():
    """The bird's-eye views alone key an entry as before the families (their fields did not exist)."""
    cams = _rolled_camera()
    cfg = asdict(AugmentConfig())
    before = {k: v for k, v in cfg.items() if k not in ("views", "lane_shift", "raise_", "poses")}
    assert cache_key("ref", "data", cfg, cams, cams, "none") == cache_key("ref", "data", before, cams, cams, "none")
    lanes = asdict(AugmentConfig(views=("birds-eye", "lane-shift")))
    other = asdict(AugmentConfig(views=("birds-eye", "lane-shift"), lane_shift=LaneShiftConfig(offsets=(3.0,))))
    assert len({cache_key("ref", "data", c, cams, cams, "none") for c in (cfg, lanes, other)}) == 3
    # an unused family's parameters do not key the entry
    unused = asdict(AugmentConfig(raise_=RaiseConfig(heights=(9.0,))))
    assert cache_key("ref", "data", unused, cams, cams, "none") == cache_key("ref", "data", cfg, cams, cams, "none")


def _constant_render(cam):
    h, w = int(cam.height[0]), int(cam.width[0])
    return {"rgb": torch.tensor([0.2, 0.8, 0.4]).expand(h, w, 3).clone(), "depth": torch.ones(h, w, 1),
            "accumulation": torch.ones(h, w, 1)}


def test_cache_and_manifest_round_trip_with_several_families(tiny_scene, tmp_path):
    from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
    from nerf2gs_plugin.engine.checkpoints import dataset_fingerprint
    from nerf2gs_plugin.viewer.scene import find_extra_views

    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    td, train = dm.train_data, dm.train_images
    n = len(train)
    aug = AugmentConfig(views=("birds-eye", "lane-shift", "raise"), delta_h=1.0, every_n=2, composites=False, min_coverage=0.0,
                        lane_shift=LaneShiftConfig(offsets=(-0.5, 0.5)), raise_=RaiseConfig(heights=(0.3,), every_n=4))
    data = dataset_fingerprint(td.image_filenames)
    ref = tmp_path / "ref"
    (ref / "checkpoints").mkdir(parents=True)  # the viewer finds the reference run by its checkpoint
    (ref / "checkpoints" / "step-000000009.ckpt").write_bytes(b"only resolved, never loaded here")
    views = render_augmented_views(train, td, _constant_render, "ref:a", data, ref, aug)
    made = additional_views(train.cameras, td, aug)
    n_bev, n_lane, n_raise = len(range(0, n, 2)), 2 * n, len(range(0, n, 4))
    assert made.families == ["birds-eye"] * n_bev + ["lane-shift"] * n_lane + ["raise"] * n_raise
    manifest = read_manifest(views.cache_dir)
    assert manifest.num_extra == len(made.cameras) and manifest.extra_families == made.families
    assert manifest.extra_sources == made.sources
    assert torch.allclose(manifest.extra_poses(), made.cameras.camera_to_worlds, atol=1e-6)  # the poses are saved
    assert views.extra.names[0] == "bev_00000" and views.extra.names[n_bev] == f"lane-shift_{n_bev:05d}"
    assert len(views.extra) == len(made.cameras)
    again = render_augmented_views(train, td, _constant_render, "ref:a", data, ref, aug)
    assert again.reused and again.cache_dir == views.cache_dir
    assert torch.equal(again.extra.cameras.camera_to_worlds, views.extra.cameras.camera_to_worlds)
    # the viewer reads the poses back from the manifest; another family list is another entry
    assert same_families(manifest.config, aug) and not same_families(manifest.config, dataclasses.replace(aug, views=("birds-eye",)))
    assert find_cached_extra_views(ref, data, aug, len(made.cameras)).path == manifest.path
    found = find_extra_views(SimpleNamespace(augment_from=ref, augment=aug), td, train.cameras, thumb_side=8)
    assert found.source == str(manifest.path) and len(found.cameras) == len(made.cameras)


def test_tiny_training_run_with_two_families(tiny_scene, tmp_path):
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path / "ref", max_num_iterations=4,
                              steps_per_eval_image=0, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    ref = trainer.train()
    p = subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.train", "voxel-grid", "--data", str(tiny_scene),
                        "--augment-from", str(ref), "--augment.views", "birds-eye", "lane-shift",
                        "--augment.lane-shift.offsets", "-1", "1", "--augment.lane-shift.share", "0.2", "--augment.delta-h", "2",
                        "--augment.min-coverage", "0",
                        "--max-num-iterations", "6", "--progress", "False", "--output-dir", str(tmp_path / "tgt")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    (entry,) = (ref / "augment_cache").glob("*/manifest.json")
    man = json.loads(entry.read_text())
    assert man["config"]["views"] == ["birds-eye", "lane-shift"] and man["config"]["lane_shift"]["offsets"] == [-1.0, 1.0]
    fams = man["extra_families"]
    assert fams.count("lane-shift") == 2 * fams.count("birds-eye") > 0
    log = json.loads(next((tmp_path / "tgt").rglob("train_log.json")).read_text())
    assert log["reference_render_seconds"] > 0


def test_each_family_has_its_own_share_of_the_samples():
    from nerf2gs_plugin.augment.shares import DEFAULT_SHARE_CAP, extra_sampling, family_shares

    bev, lanes = ["birds-eye"] * 10, ["lane-shift"] * 20
    alone = family_shares(bev, 30, AugmentConfig())
    assert alone == {"birds-eye": 0.25}  # the draw of one image among all, as before the families
    # as many views from above as input views: the draw would give them half the samples, the cap gives them less
    assert family_shares(bev, 10, AugmentConfig()) == {"birds-eye": DEFAULT_SHARE_CAP} and DEFAULT_SHARE_CAP < 0.5
    assert family_shares(bev, 10, AugmentConfig(birds_eye_share=0.5)) == {"birds-eye": 0.5}  # a given share is taken as given
    both = AugmentConfig(views=("birds-eye", "lane-shift"), lane_shift=LaneShiftConfig(share=None))
    # lane-shift (share unset) added after birds-eye: its share comes out of the input views' share only
    assert family_shares(bev + lanes, 30, both) == pytest.approx({"birds-eye": 0.25, "lane-shift": 0.75 * 20 / 50})
    assert family_shares(bev + lanes, 30, AugmentConfig(views=("birds-eye", "lane-shift")))["birds-eye"] == 0.25
    given = dataclasses.replace(both, lane_shift=LaneShiftConfig(share=0.2))
    assert family_shares(bev + lanes, 30, given) == pytest.approx({"birds-eye": 0.25, "lane-shift": 0.2})
    # --augment.extra-prob: all additional views together, split in proportion to the shares
    assert family_shares(bev + lanes, 30, dataclasses.replace(given, extra_prob=0.45)) == pytest.approx({"birds-eye": 0.25, "lane-shift": 0.2})
    assert family_shares(bev + lanes, 30, dataclasses.replace(given, extra_prob=0.09)) == pytest.approx({"birds-eye": 0.05, "lane-shift": 0.04})
    prob, per_view = extra_sampling(bev + lanes, 30, given)
    assert prob == pytest.approx(0.45) and per_view[:10].sum() == pytest.approx(0.25 / 0.45) and per_view[10:].sum() == pytest.approx(0.2 / 0.45)
    assert extra_sampling(bev, 10, AugmentConfig())[1] is None  # one family: the uniform draw of before
    with pytest.raises(ConfigError, match="lane-shift.share"):
        family_shares(bev + lanes, 30, dataclasses.replace(both, lane_shift=LaneShiftConfig(share=0.8)))
    with pytest.raises(ConfigError, match="birds-eye-share"):
        family_shares(bev, 10, AugmentConfig(birds_eye_share=1.0))
    # a share is how often the views are drawn, not what they are: it keys no cache entry
    cams = _rolled_camera()
    assert cache_key("ref", "data", asdict(given), cams, cams, "none") == cache_key("ref", "data", asdict(both), cams, cams, "none")
    assert same_families(json.loads(json.dumps(asdict(both))), given)


@pytest.mark.parametrize("manager", ["full-image", "rays"])
def test_training_samples_each_family_at_its_share(tiny_scene, tmp_path, manager):
    from nerf2gs_plugin.augment.datamanager import AugmentedDataManager, Reference
    from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
    from nerf2gs_plugin.datamanagers.rays import RayDataManagerConfig

    config = FullImageDataManagerConfig() if manager == "full-image" else RayDataManagerConfig(rays_per_batch=64)
    dm = config.setup(data=tiny_scene, device="cpu")
    aug = AugmentConfig(views=("birds-eye", "lane-shift"), delta_h=1.0, composites=False, min_coverage=0.0, real_only_from=1.0,
                        lane_shift=LaneShiftConfig(offsets=(-0.5, 0.5), share=0.2))
    adm = AugmentedDataManager(dm, Reference(_constant_render, "ref:a", tmp_path), aug)
    n_real = len(adm.train_images)
    families = adm.manifest.extra_families
    assert families.count("lane-shift") == 2 * families.count("birds-eye") == 2 * n_real
    drawn = torch.cat([torch.as_tensor(adm.next_train(step)[1]["image_idx"]).reshape(-1) for step in range(1500 if manager == "full-image" else 60)])
    extra = drawn[drawn >= n_real] - n_real
    frac = {f: sum(families[j] == f for j in extra.tolist()) / len(drawn) for f in ("birds-eye", "lane-shift")}
    # birds-eye keeps its share of before (its views' share of them and the input views, 0.5, at most the cap), lane-shift has its 0.2
    from nerf2gs_plugin.augment.shares import DEFAULT_SHARE_CAP

    assert frac["birds-eye"] == pytest.approx(DEFAULT_SHARE_CAP, abs=0.04) and frac["lane-shift"] == pytest.approx(0.2, abs=0.04)


def test_export_names_each_view_by_its_family(tiny_scene, tmp_path):
    from nerf2gs_plugin.augment.datamanager import AugmentedDataManager, Reference
    from nerf2gs_plugin.augment.export import export_augmented_dataset
    from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig

    dm = FullImageDataManagerConfig().setup(data=tiny_scene, device="cpu")
    n = len(dm.train_images)
    aug = AugmentConfig(views=("birds-eye", "lane-shift"), delta_h=1.0, composites=False, min_coverage=0.0,
                        lane_shift=LaneShiftConfig(offsets=(0.5,)))
    adm = AugmentedDataManager(dm, Reference(_constant_render, "ref:a", tmp_path / "ref"), aug)
    out = export_augmented_dataset(adm, tmp_path / "export")
    names = [f["file_path"] for f in json.loads((out / "transforms.json").read_text())["frames"]]
    assert names[n] == "images/birdseye_00000.png" and names[2 * n] == f"images/lane-shift_{n:05d}.png"
    assert sum(x.startswith("images/lane-shift_") for x in names) == n and all((out / x).is_file() for x in names)
