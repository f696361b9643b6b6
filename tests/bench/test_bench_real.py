"""ns2gs-bench real: the eval-camera mapping (inverse Sim(3); identity on ground truth), the gain
ratio, and the capture plumbing (video -> process -> masks -> capture figures -> real.json/md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from nerf2gs_bench import real as br
from nerf2gs_plugin.eval.pose_eval import LocalAlignment, Sim3, align_poses, rotation_angle_deg

SMALL = dict(width=48, height=32, num_train=6, num_street=2, num_bev=3, num_val_street=0, num_val_bev=0, num_lane=0, num_val_lane=0, num_cars=2,
             spp=1, num_points=300, progress=False)


def small_config(out: Path, **kw):
    from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig

    return SynthStreetConfig(out=out, **{**SMALL, **kw})


@pytest.fixture(scope="module")
def small_street(tmp_path_factory) -> Path:
    from nerf2gs_plugin.data.synthetic_street import generate_street

    out = tmp_path_factory.mktemp("street") / "street"
    generate_street(small_config(out))
    return out


def _rot(axis, deg):
    a = np.radians(deg)
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def _poses(n=7, seed=0):
    g = np.random.default_rng(seed)
    out = np.zeros((n, 3, 4))
    for i in range(n):
        out[i, :, :3] = _rot(g.normal(size=3), g.uniform(0, 180))
        out[i, :, 3] = g.normal(size=3) * 5
    return out


def test_sim3_inverse_round_trips_points_and_poses():
    sim = Sim3(2.5, _rot([1, 2, 3], 40), np.array([1.0, -2.0, 0.5]))
    inv = sim.inverse()
    x = np.random.default_rng(1).normal(size=(10, 3))
    assert np.allclose(inv.apply(sim.apply(x)), x) and np.allclose(sim.apply(inv.apply(x)), x)
    c2w = _poses()
    assert np.allclose(inv.apply_poses(sim.apply_poses(c2w)), c2w)
    assert inv.s == pytest.approx(0.4)


def test_eval_cameras_mapped_into_the_estimated_frame(small_street):
    """Training cameras seen in another frame (a known Sim(3)): the alignment recovers it and the
    true eval cameras land where that frame has them."""
    groups = br.read_frames(small_street)
    true_train = br.c2w_array(groups["train"])
    truth = Sim3(0.3, _rot([0.2, 1, 0.4], 70), np.array([4.0, -1.0, 2.0]))  # true -> estimated
    est_train = truth.apply_poses(true_train)
    sim = align_poses(est_train, true_train)  # estimated -> true
    assert sim.s == pytest.approx(1 / 0.3, rel=1e-6)
    frames = br.mapped_eval_frames(groups, sim.inverse())
    assert set(frames) == {"street", "bev_1", "bev_2"}
    got = np.array([np.array(f["transform_matrix"])[:3] for f in frames["bev_1"]])
    assert np.allclose(got, truth.apply_poses(br.c2w_array(groups["bev_1"])), atol=1e-5)
    f0, t0 = frames["street"][0], groups["street"][0]
    assert Path(f0["file_path"]) == Path(t0.image).resolve() and f0["fl_x"] == t0.intr.fx and f0["w"] == t0.intr.width


def test_identity_mapping_reproduces_the_ground_truth_eval_cameras(small_street, tmp_path):
    """The ground-truth column goes through the same mapping with its own (identity) alignment: the
    parsed eval cameras, images and masks equal those of the original eval splits."""
    from nerf2gs_plugin.data import parse_dataset

    gt = br.ground_truth_dataset(small_street, tmp_path / "gt", 6)
    meta = json.loads((small_street / "transforms.json").read_text())
    ref = tmp_path / "ref"
    br.ground_truth_dataset(small_street, ref, 6)
    doc = json.loads((ref / "transforms.json").read_text())
    doc["eval_splits"] = meta["eval_splits"]  # the original, unmapped eval cameras
    (ref / "transforms.json").write_text(json.dumps(doc))
    groups = br.read_frames(gt)
    train = br.c2w_array(groups["train"])
    local = br.attach_eval(gt, br.read_frames(small_street), train, train)
    sim = local.global_sim
    assert sim.s == pytest.approx(1.0) and np.allclose(sim.R, np.eye(3))
    assert local.leave_one_out_rotation_deg() == pytest.approx(0.0, abs=1e-5)
    for split in ("street", "bev_1", "bev_2"):
        a, b = parse_dataset(gt, split), parse_dataset(ref, split)
        assert torch.allclose(a.cameras.camera_to_worlds, b.cameras.camera_to_worlds, atol=1e-6)
        assert torch.equal(a.cameras.fx, b.cameras.fx) and torch.equal(a.cameras.width, b.cameras.width)
        assert [p.resolve() for p in a.image_filenames] == [p.resolve() for p in b.image_filenames]
        assert [p.resolve() for p in a.mask_filenames["ground"]] == [p.resolve() for p in b.mask_filenames["ground"]]


def _drive(n: int, offset: float = 0.0) -> np.ndarray:
    """A straight forward drive ``[n, 3, 4]``: 1.5 m apart along x, looking along x (OpenGL: -z)."""
    look = np.array([[0.0, 0, -1], [-1, 0, 0], [0, 1, 0]]).T  # columns: camera x, y, z axes in the world
    return np.stack([np.concatenate([look, [[1.5 * (i + offset)], [0.0], [1.5]]], axis=1) for i in range(n)])


def test_local_alignment_follows_a_drifting_trajectory():
    """Estimated training cameras whose orientation drifts along the drive (a growing turn about
    their own axes, as SfM of a low-resolution forward drive gives) on top of a known Sim(3): one
    Sim(3) leaves cameras degrees off, the local mapping follows the drift, and a global frame
    change alone is recovered exactly (as the single Sim(3) would)."""
    true_train, ev = _drive(30), _drive(29, offset=0.5)
    truth = Sim3(0.3, _rot([0.2, 1, 0.4], 70), np.array([4.0, -1.0, 2.0]))  # true -> estimated
    exact = LocalAlignment.fit(truth.apply_poses(true_train), true_train)
    assert np.allclose(exact.apply_poses(ev), truth.apply_poses(ev), atol=1e-6)

    n = len(true_train)
    drifted = true_train.copy()
    drifted[:, :, :3] = np.einsum("nij,njk->nik", drifted[:, :, :3], np.stack([_rot([0, 1, 0.3], 3.0 * i / (n - 1)) for i in range(n)]))
    est_train = truth.apply_poses(drifted)
    local = LocalAlignment.fit(est_train, true_train)
    glob = align_poses(est_train, true_train).inverse()
    loo = np.mean([rotation_angle_deg(local.map_pose(true_train[i], skip=i)[:, :3], est_train[i, :, :3]) for i in range(n)])
    one = np.mean([rotation_angle_deg(a[:, :3], b[:, :3]) for a, b in zip(glob.apply_poses(true_train), est_train)])
    assert local.leave_one_out_rotation_deg() == pytest.approx(loo)
    assert one > 0.5 and loo < 0.3 * one


def test_gain_ratio():
    def res(base, aug):
        return {"splatfacto": {"results": {"bev_1": {"psnr": base}}}, br.NERF_VIEWS: {"results": {"bev_1": {"psnr": aug}}}}

    assert br.gain_ratio(res(19.0, 20.0), res(19.0, 21.0), "bev_1") == pytest.approx(0.5)
    assert br.gain_ratio(res(19.0, 20.0), res(19.0, 19.0), "bev_1") is None  # no gain with ground truth: no ratio
    assert br.gain_ratio({"splatfacto": {"failed": True}}, res(19.0, 21.0), "bev_1") is None


def _fake_sfm(truth: Sim3, scale_bias: float):
    """A stand-in for ``process video`` (pycolmap is tested in tests/data/test_process.py and is not
    deterministic on tiny frames): the video's frames with their true poses seen through ``truth``
    (true -> SfM frame), the sparse points likewise, and a metric scale off by ``scale_bias``."""
    import cv2

    from nerf2gs_plugin.data.ply import read_ply_points, write_ply_points
    from nerf2gs_plugin.data.process.export import write_downscaled
    from nerf2gs_plugin.data.process.pipeline import ProcessReport

    def process(video, out, n, fov_deg, camera_height):
        street = Path(video).parent / "gt"
        meta = json.loads((street / "transforms.json").read_text())
        out = Path(out)
        (out / "images").mkdir(parents=True, exist_ok=True)
        cap, frames = cv2.VideoCapture(str(video)), []
        for i, fr in enumerate(meta["frames"][:n]):
            ok, img = cap.read()
            assert ok
            cv2.imwrite(str(out / "images" / f"frame_{i:06d}.png"), img)
            c2w = truth.apply_poses(np.array(fr["transform_matrix"])[None, :3])[0]
            frames.append({"file_path": f"images/frame_{i:06d}.png", "transform_matrix": c2w.tolist() + [[0, 0, 0, 1]]})
        xyz, rgb = read_ply_points(street / meta["ply_file_path"])
        write_ply_points(out / "sparse_pc.ply", truth.apply(xyz).astype(np.float32), rgb)
        h, w = img.shape[:2]
        k = w / meta["w"]  # a video at another size than the street: the intrinsics follow it, as SfM's would
        write_downscaled(out, [f"frame_{i:06d}.png" for i in range(n)])
        doc = {"camera_model": "PINHOLE", "fl_x": meta["fl_x"] * k, "fl_y": meta["fl_y"] * k, "cx": w / 2, "cy": h / 2, "w": w, "h": h,
               "frames": frames, "ply_file_path": "sparse_pc.ply", "metres_per_unit": (1 + scale_bias) / truth.s,
               "up": (truth.R @ np.array([0.0, 0.0, 1.0])).tolist()}
        (out / "transforms.json").write_text(json.dumps(doc))
        return ProcessReport(out, n, n, len(xyz), "sequential", doc["metres_per_unit"], "camera-height", {"sfm": 0.0})

    return process


@pytest.mark.timeout(120)
@pytest.mark.parametrize("video_scale", [1, 2])
def test_capture_plumbing_writes_the_required_keys(small_street, tmp_path, monkeypatch, video_scale):
    """The forward drive as a video -> (stand-in SfM in a known similarity frame) -> masks (a
    3-step reference) -> capture figures and real.json/md; no training of the targets. At video
    scale 2 the video is the street at twice its size and the estimated column is made from the
    capture's ``images_2``: at the ground-truth column's size and intrinsics."""
    from nerf2gs_plugin.data.synthetic_street import generate_street

    truth = Sim3(0.5, np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), np.array([3.0, 1.0, -2.0]))
    monkeypatch.setattr(br, "process_capture", _fake_sfm(truth, 0.02))

    def large_street(root, opts, scale):
        out = Path(root) / f"street_x{scale}"
        generate_street(small_config(out, width=SMALL["width"] * scale, height=SMALL["height"] * scale))
        return out

    monkeypatch.setattr(br, "make_street", large_street)
    opts = br.RealBenchOptions(frames=3, reference_steps=3, video_scale=video_scale)
    doc = br.run_real_bench(tmp_path / "runs", tmp_path / "out", opts, log=lambda s: None, train=False, street=small_street)
    js = json.loads((tmp_path / "out" / "real.json").read_text())
    for key in ("registered_fraction", "ate_percent", "scale_error_percent", "mask_iou", "stage_seconds", "machine"):
        assert key in js, key
    assert js["registered_fraction"] == 1.0 and js["ate_percent"] < 1e-3 and js["up_error_deg"] < 1e-3
    assert js["scale_error_percent"] == pytest.approx(2.0, abs=1e-3)
    assert set(js["mask_iou"]) == {"sky", "ground", "transient"}
    assert all(v is None or 0.0 <= v <= 1.0 for v in js["mask_iou"].values())
    assert js["alignment"]["gt_identity_scale"] == pytest.approx(1.0)
    md = (tmp_path / "out" / "real.md").read_text()
    assert "registered_fraction" in md and "mask_iou.sky" in md
    # the eval cameras in the estimated frame are the true ones seen through the same similarity
    est_dir = tmp_path / "runs" / "real" / ("estimated" if video_scale == 1 else f"estimated_x{video_scale}")
    est, gt = br.read_frames(est_dir), br.read_frames(tmp_path / "runs" / "real" / "gt")
    assert set(est) == {"train", "street", "bev_1", "bev_2"} and doc["process"]["registered"] == len(est["train"]) == 3
    assert np.allclose(br.c2w_array(est["bev_2"]), truth.apply_poses(br.c2w_array(gt["bev_2"])), atol=1e-4)
    assert all((est_dir / "masks" / k / "frame_000001.png").is_file() for k in ("sky", "ground"))
    # the estimated training frames at the ground-truth ones' size and intrinsics
    from nerf2gs_plugin.data.images import image_size, load_mask

    e0, g0 = est["train"][0], gt["train"][0]
    assert (e0.intr.width, e0.intr.height) == (g0.intr.width, g0.intr.height) == image_size(e0.image)
    assert e0.intr.fx == pytest.approx(g0.intr.fx) and e0.intr.cx == pytest.approx(g0.intr.cx)
    assert tuple(load_mask(est_dir / "masks" / "sky" / "frame_000001.png").shape) == (g0.intr.height, g0.intr.width)
    assert (f"images_{video_scale}" in str(e0.image)) == (video_scale != 1)
    # the third column: the true cameras, eval splits and masks, the capture's points carried into the true frame
    from nerf2gs_plugin.data.ply import read_ply_points

    pts = tmp_path / "runs" / "real" / "gt_capture_points"
    sfm = br.read_frames(pts)
    assert set(sfm) == set(gt) and np.allclose(br.c2w_array(sfm["train"]), br.c2w_array(gt["train"]))
    assert np.allclose(br.c2w_array(sfm["bev_1"]), br.c2w_array(gt["bev_1"]), atol=1e-6)
    est_xyz, _ = read_ply_points(est_dir / json.loads((est_dir / "transforms.json").read_text())["ply_file_path"])
    got, _ = read_ply_points(pts / "sparse_pc.ply")
    assert not (pts / "sparse_pc.ply").is_symlink() and np.allclose(got, truth.inverse().apply(est_xyz), atol=1e-3)


def test_video_scale_must_be_a_downscale_that_process_writes(tmp_path):
    from nerf2gs_plugin.errors import ConfigError

    with pytest.raises(ConfigError, match="video-scale"):
        br.run_real_bench(tmp_path, tmp_path, br.RealBenchOptions(video_scale=3), train=False, street=tmp_path)


def test_resample_mask_between_pinholes():
    from nerf2gs_plugin.masks.evaluate import resample_mask

    m = torch.zeros(20, 30, dtype=torch.bool)
    m[5:10, 12:18] = True
    same = (40.0, 40.0, 15.0, 10.0)
    assert torch.equal(resample_mask(m, same, same, (20, 30)), m)  # the same camera: unchanged
    # a camera with twice the focal and a shifted principal point sees the block twice as large, moved
    dst = (80.0, 80.0, 30.0, 20.0)
    out = resample_mask(m, same, dst, (40, 60))
    exp = torch.zeros(40, 60, dtype=torch.bool)
    exp[10:20, 24:36] = True
    assert torch.equal(out, exp)
    # a narrower source: pixels it never saw are False
    assert not resample_mask(torch.ones(20, 30, dtype=torch.bool), same, (20.0, 20.0, 15.0, 10.0), (20, 30))[0, 0]


def test_masks_reference_keyed_by_the_capture_not_its_stage_times(tmp_path):
    """A capture re-processed with other intrinsics (same images: the checkpoint's image fingerprint
    cannot tell) gets a new reference; new stage times, eval splits or mask keys do not."""
    frame = {"file_path": "images/frame_000000.jpg", "fl_x": 119.0, "fl_y": 119.0, "cx": 100.0, "cy": 56.0, "w": 200, "h": 112,
             "transform_matrix": np.eye(4).tolist()}
    meta = {"frames": [frame], "metres_per_unit": 4.2, "process": {"stage_seconds": {"mapping": 1.0}}}

    def ref(m: dict, name: str) -> Path:
        (tmp_path / name).mkdir(exist_ok=True)
        (tmp_path / name / "transforms.json").write_text(json.dumps(m))
        return br.reference_dir(tmp_path, tmp_path / name, 1000)

    a = ref(meta, "a")
    same = json.loads(json.dumps(meta))
    same["process"]["stage_seconds"]["mapping"] = 2.0
    same["eval_splits"] = {"bev_1": []}
    same["frames"][0]["sky_mask_path"] = "masks/sky/frame_000000.png"
    assert ref(same, "b") == a
    other = json.loads(json.dumps(meta))
    other["frames"][0].update(fl_y=100.0, cx=56.0, cy=0.0)  # the old export's reading of a SIMPLE_RADIAL camera
    assert ref(other, "c") != a and a.name.startswith("masks-reference-1000-")
    turned = json.loads(json.dumps(meta))
    turned["up"] = [0.0, 0.0, 1.0]  # re-processed with another up: another normalised world
    assert ref(turned, "d") != a
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "transforms.json").write_text(json.dumps(meta))
    assert br.reference_dir(tmp_path, tmp_path / "e", 1000, "downscale 4.0") != a  # trained otherwise


def test_masks_reference_keyed_by_the_model_code(tmp_path, monkeypatch):
    """A changed model (a new default) trains a new first reference: the old one is stale."""
    import nerf2gs_bench.code_version as cv

    (tmp_path / "transforms.json").write_text(json.dumps({"frames": [], "metres_per_unit": 1.0}))
    a = br.reference_dir(tmp_path, tmp_path, 1000)
    monkeypatch.setattr(cv, "model_code_hash", lambda root=None: "another model")
    b = br.reference_dir(tmp_path, tmp_path, 1000)
    assert b != a
    import nerf2gs_plugin.masking.mask_reference as mr  # and by what the reference changes of StreetNeRF

    monkeypatch.setattr(mr, "REFERENCE_OVERRIDES", {"pipeline": {"model": {"appearance_reg_weight": 0.5}}})
    assert br.reference_dir(tmp_path, tmp_path, 1000) not in (a, b)


def test_camera_optimizer_option_reaches_only_the_estimated_streetnerf():
    from nerf2gs_plugin.registry import get_method
    from nerf2gs_plugin.utils.config import apply_plain

    opts = br.RealBenchOptions()
    assert opts.camera_optimizer == "off"
    off, on = br.real_plan(opts), br.real_plan(opts, "SO3xR3")
    assert [s.label for s in off] == [s.label for s in on]
    assert off[1:] == on[1:] and "camera_optimizer" not in str(off[0].overrides)
    cfg = apply_plain(get_method("streetnerf").config, on[0].overrides)
    assert cfg.pipeline.model.camera_optimizer.mode == "SO3xR3" and cfg.max_num_iterations == opts.streetnerf_steps


def test_seed_option_reaches_every_run_and_is_absent_by_default():
    import dataclasses

    from nerf2gs_plugin.registry import get_method
    from nerf2gs_plugin.utils.config import apply_plain

    plain = br.real_plan(br.RealBenchOptions())
    assert all("seed" not in s.overrides for s in plain)  # the plain bench's run keys unchanged
    seeded = br.real_plan(dataclasses.replace(br.RealBenchOptions(), seed=43))
    for spec in seeded:
        assert apply_plain(get_method(spec.method).config, spec.overrides).seed == 43


def test_street_seed_makes_another_street_under_its_own_folder(tmp_path, monkeypatch):
    """--street-seed N: the generator gets the seed (another layout, other cars), at every size the bench asks for."""
    import nerf2gs_plugin.data.synthetic_street as synth

    made = []
    monkeypatch.setattr(synth, "generate_street", lambda cfg: made.append(cfg))
    opts = br.RealBenchOptions(street_seed=7)
    assert br.make_street(tmp_path, opts).name == "street" and br.make_street(tmp_path, opts, 4).name == "street_x4"
    assert [(c.seed, c.width) for c in made] == [(7, 200), (7, 800)]
    assert br.RealBenchOptions().street_seed == 0
