"""Stressed dataset copies for the stability bench: exact pose noise on training frames only,
half the views, no masks, no points; the copies parse and reuse the original files."""

import json

import numpy as np
import pytest
import torch

from nerf2gs_plugin.data import list_splits, parse_dataset
from nerf2gs_plugin.errors import DataError
from nerf2gs_bench.perturb import Perturbation, perturb_pose, perturbed_copy, pose_difference, random_rotation


def test_random_rotation_has_the_requested_angle():
    rng = np.random.default_rng(3)
    for deg in (0.5, 10.0, 90.0):
        r = random_rotation(np.radians(deg), rng)
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.linalg.det(r) == pytest.approx(1.0)
        assert pose_difference(np.eye(4), np.block([[r, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]))[0] == pytest.approx(deg, abs=1e-6)
    c2w = np.eye(4)
    c2w[:3, 3] = [1, 2, 3]
    moved = perturb_pose(c2w.tolist(), 0.5, 0.05, rng)
    ang, dist = pose_difference(c2w, moved)
    assert ang == pytest.approx(0.5, abs=1e-6) and dist == pytest.approx(0.05, abs=1e-9)


def test_pose_noise_touches_train_frames_only(tiny_scene, tmp_path):
    src = json.loads((tiny_scene / "transforms.json").read_text())
    dst = perturbed_copy(tiny_scene, tmp_path, Perturbation(rotation_deg=0.5, translation_m=0.05, seed=1))
    out = json.loads((dst / "transforms.json").read_text())
    assert len(out["frames"]) == len(src["frames"])
    for a, b in zip(src["frames"], out["frames"]):
        ang, dist = pose_difference(a["transform_matrix"], b["transform_matrix"])
        assert ang == pytest.approx(0.5, abs=1e-4) and dist == pytest.approx(0.05 / src["metres_per_unit"], abs=1e-6)
        assert b["transient_mask_path"].endswith(f"masks/transient/{a['file_path'].split('/')[-1]}")
    for split, entries in src["eval_splits"].items():  # eval poses are exact
        for a, b in zip(entries, out["eval_splits"][split]):
            assert pose_difference(a["transform_matrix"], b["transform_matrix"]) == pytest.approx((0.0, 0.0), abs=1e-5)
    train = parse_dataset(dst, "train")
    orig = parse_dataset(tiny_scene, "train")
    assert [p.name for p in train.image_filenames] == [p.name for p in orig.image_filenames]
    assert list_splits(dst) == list_splits(tiny_scene)
    assert not (dst / "images").exists()  # no copies of images
    # same parameters -> same folder, reused; other seed -> other folder
    assert perturbed_copy(tiny_scene, tmp_path, Perturbation(rotation_deg=0.5, translation_m=0.05, seed=1)) == dst
    assert perturbed_copy(tiny_scene, tmp_path, Perturbation(rotation_deg=0.5, translation_m=0.05, seed=2)) != dst


def test_half_views_no_masks_no_points(tiny_scene, tmp_path):
    orig = parse_dataset(tiny_scene, "train")
    half = parse_dataset(perturbed_copy(tiny_scene, tmp_path, Perturbation(keep_every=2)), "train")
    assert [p.name for p in half.image_filenames] == [p.name for p in orig.image_filenames[::2]]
    assert len(parse_dataset(perturbed_copy(tiny_scene, tmp_path, Perturbation(keep_every=2)), "bev_1")) == 2
    bare = perturbed_copy(tiny_scene, tmp_path, Perturbation(drop_masks=True, drop_points=True))
    out = json.loads((bare / "transforms.json").read_text())
    assert "ply_file_path" not in out and not any(k.endswith("_mask_path") for f in out["frames"] for k in f)
    parsed = parse_dataset(bare, "train")
    assert parsed.points3D_xyz is None and all(m is None for v in parsed.mask_filenames.values() for m in v)
    assert parse_dataset(tiny_scene, "train").points3D_xyz is not None
    assert all(m is not None for m in parse_dataset(tiny_scene, "train").mask_filenames["sky"])
    with_masks = parse_dataset(perturbed_copy(tiny_scene, tmp_path, Perturbation()), "train")
    assert torch.equal(with_masks.cameras.camera_to_worlds, orig.cameras.camera_to_worlds)


def test_bad_sources_are_clear_errors(tmp_path):
    with pytest.raises(DataError, match="transforms.json"):
        perturbed_copy(tmp_path / "nothing", tmp_path / "out", Perturbation())
    d = tmp_path / "nosplits"
    d.mkdir()
    (d / "transforms.json").write_text(json.dumps({"frames": [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}]}))
    with pytest.raises(DataError, match="explicit eval splits"):
        perturbed_copy(d, tmp_path / "out", Perturbation(keep_every=2))


def _train_masks(dataset, kind):
    from nerf2gs_plugin.data.images import load_mask

    return [load_mask(p).numpy() for p in parse_dataset(dataset, "train").mask_filenames[kind]]


def test_mask_erosion_shrinks_and_dilation_grows_training_masks(tiny_scene, tmp_path):
    orig = _train_masks(tiny_scene, "transient")
    eroded = _train_masks(perturbed_copy(tiny_scene, tmp_path, Perturbation(mask_erode_px=1)), "transient")
    dilated = _train_masks(perturbed_copy(tiny_scene, tmp_path, Perturbation(mask_dilate_px=1)), "transient")
    assert sum(o.sum() for o in orig) > 0
    for o, e, d in zip(orig, eroded, dilated):
        assert not (e & ~o).any() and not (o & ~d).any()  # eroded inside the original, original inside dilated
        if o.any() and not o.all():
            assert e.sum() < o.sum() < d.sum()
    out = perturbed_copy(tiny_scene, tmp_path, Perturbation(mask_erode_px=1))
    meta = json.loads((out / "transforms.json").read_text())
    src = json.loads((tiny_scene / "transforms.json").read_text())
    for split, entries in src["eval_splits"].items():  # eval masks untouched
        assert all(str(tiny_scene) in e.get("sky_mask_path", str(tiny_scene)) for e in meta["eval_splits"][split])


def test_mask_drop_removes_half_the_training_masks_deterministically(tiny_scene, tmp_path):
    n = len(parse_dataset(tiny_scene, "train").image_filenames)
    a = perturbed_copy(tiny_scene, tmp_path / "a", Perturbation(mask_drop_fraction=0.5, seed=3))
    b = perturbed_copy(tiny_scene, tmp_path / "b", Perturbation(mask_drop_fraction=0.5, seed=3))
    c = perturbed_copy(tiny_scene, tmp_path / "c", Perturbation(mask_drop_fraction=0.5, seed=4))
    masks = parse_dataset(a, "train").mask_filenames
    missing = [i for i in range(n) if masks["sky"][i] is None]
    assert len(missing) == round(n / 2)
    assert all((masks[k][i] is None) == (i in missing) for k in ("sky", "ground", "transient") for i in range(n))
    info = json.loads((a / "perturbation.json").read_text())
    assert info["masks_dropped"] == json.loads((b / "perturbation.json").read_text())["masks_dropped"]
    assert len(info["masks_dropped"]) == len(missing)
    other = json.loads((c / "perturbation.json").read_text())["masks_dropped"]
    assert len(other) == len(missing)  # another seed: the same count (which ones may differ)


def test_exposure_changes_each_training_image_by_its_gain_and_offset(tiny_scene, tmp_path):
    from nerf2gs_plugin.data.images import load_image

    spread = 1.0
    dst = perturbed_copy(tiny_scene, tmp_path, Perturbation(exposure_spread=spread, seed=5))
    orig, new = parse_dataset(tiny_scene, "train"), parse_dataset(dst, "train")
    info = json.loads((dst / "perturbation.json").read_text())["exposure"]
    assert len(info) == len(orig.image_filenames)
    log_gains = []
    for a, b in zip(orig.image_filenames, new.image_filenames):
        gain, offset = next(v for k, v in info.items() if k.endswith(a.name))
        assert 2 ** -spread <= gain <= 2 ** spread and abs(offset) <= 0.05 * spread
        log_gains.append(np.log2(gain))
        x, y = load_image(a).numpy(), load_image(b).numpy()
        want = np.clip(x * gain + offset, 0, 1)
        assert np.abs(y - want).max() <= 1 / 255 + 1e-6  # the stated change, up to 8-bit rounding
    assert max(log_gains) - min(log_gains) > spread / 2  # the frames really differ from one another
    assert len(set(np.round(log_gains, 6))) == len(log_gains)
    ev = parse_dataset(dst, "bev_1")  # eval images are the originals
    assert all(str(tiny_scene) in str(p) for p in ev.image_filenames)
