"""The synthetic street: determinism per seed, exact masks and depth, metric poses, BEV coverage."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from nerf2gs_plugin.data import list_splits, parse_dataset
from nerf2gs_plugin.data.images import load_depth, load_mask
from nerf2gs_plugin.data.synthetic.layout import SIDEWALK_H
from nerf2gs_plugin.data.synthetic_street import generate_street
from nerf2gs_plugin.errors import ConfigError


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and p.name != "synth_stats.json" and ".ns2gs_cache" not in p.parts}


def test_same_seed_same_bytes_other_seed_differs(small_street, make_config, tmp_path):
    again = tmp_path / "again"
    generate_street(make_config(again))
    a, b = _files(small_street), _files(again)
    assert a.keys() == b.keys() and len(a) > 50
    assert [k for k in a if a[k] != b[k]] == []
    other = tmp_path / "other"
    generate_street(make_config(other, seed=1))
    c = _files(other)
    differ = [k for k in a if k.startswith("images/") and a[k] != c.get(k)]
    assert len(differ) == len([k for k in a if k.startswith("images/")])


def test_splits_sizes_and_metadata(small_street):
    assert list_splits(small_street) == ["train", "street", "bev_1", "bev_2", "val_street", "val_bev", "lane_1", "lane_2", "lane_4", "val_lane"]
    sizes = {s: len(parse_dataset(small_street, s)) for s in list_splits(small_street)}
    assert sizes == {"train": 6, "street": 2, "bev_1": 3, "bev_2": 3, "val_street": 2, "val_bev": 2,
                     "lane_1": 2, "lane_2": 2, "lane_4": 2, "val_lane": 2}
    train = parse_dataset(small_street, "train")
    assert set(train.mask_filenames) == {"sky", "ground", "transient"}
    assert train.points3D_xyz is not None and len(train.points3D_xyz) == 300
    assert int(train.cameras.width[0]) == 48 and int(train.cameras.height[0]) == 32
    # metres survive normalisation: the up vector is +z and the training cameras are 3 m above the road
    assert torch.allclose(train.up, torch.tensor([0.0, 0.0, 1.0]), atol=1e-5)
    bev1 = parse_dataset(small_street, "bev_1")
    dz = float(bev1.cameras.centers[:, 2].mean() - train.cameras.centers[:, 2].mean())
    assert train.world_to_metres(dz) == pytest.approx(10.0, abs=1e-3)
    # BEV cameras look down by 25 deg (bev_1) and 30 deg (bev_2)
    for split, pitch in (("bev_1", 25.0), ("bev_2", 30.0)):
        fwd = -parse_dataset(small_street, split).cameras.camera_to_worlds[:, :, 2]
        assert torch.allclose(torch.rad2deg(torch.asin(-fwd[:, 2])), torch.full((3,), pitch), atol=1e-3)
    fwd = -train.cameras.camera_to_worlds[:, :, 2]
    assert float(fwd[:, 2].abs().max()) < 1e-5  # level training cameras


def test_masks_depth_and_geometry_agree(small_street):
    """Sky exactly where depth is 0; cars only in training views; ground pixels lie on the road,
    the sidewalk top or the kerb (checked by casting the PARSED cameras' rays with the stored depth)."""
    any_transient = False
    for split in list_splits(small_street):
        out = parse_dataset(small_street, split)
        for i in range(len(out)):
            hw = (int(out.cameras.height[i]), int(out.cameras.width[i]))
            sky = load_mask(out.mask_filenames["sky"][i], hw)
            ground = load_mask(out.mask_filenames["ground"][i], hw)
            transient = load_mask(out.mask_filenames["transient"][i], hw)
            depth = load_depth(out.depth_filenames[i], hw)
            assert torch.equal(sky, depth == 0)
            assert not (sky & ground).any()
            if split != "train":
                assert not transient.any()
            any_transient |= bool(transient.any())
            rays = out.cameras.generate_rays(i)
            fwd = -out.cameras.camera_to_worlds[i, :, 2]
            g = ground.reshape(-1)
            t = out.metres_to_world(1.0) * depth.reshape(-1)[g] / (rays.directions[g] @ fwd)
            p = rays.origins[g] + t[:, None] * rays.directions[g]
            z_m = np.array([out.world_to_metres(float(v)) for v in p[:, 2] - _ground_z(out)])
            # road plane, sidewalk top, or the kerb between them
            assert np.all((z_m > -0.02) & (z_m < SIDEWALK_H + 0.02)), split
            flat = (np.abs(z_m) < 0.02) | (np.abs(z_m - SIDEWALK_H) < 0.02)
            assert flat.mean() > 0.9, split
    assert any_transient


def _ground_z(out) -> float:
    """The road plane's height in the normalised world (the original z = 0)."""
    from nerf2gs_plugin.data.normalize import DataparserTransform

    tf = DataparserTransform(out.dataparser_transform, out.dataparser_scale)
    return float(tf.apply_points(torch.zeros(1, 3))[0, 2])


def test_bev_views_see_ground_no_training_view_saw(small_street):
    stats = json.loads((small_street / "synth_stats.json").read_text())
    cov = stats["ground_coverage"]
    for split in ("bev_1", "bev_2"):
        assert cov[split]["ground_pixels"] > 0
        assert cov[split]["unseen_at_similar_angle"] > 0.3
        assert cov[split]["unseen_at_similar_angle"] >= cov[split]["unseen_at_all"]
    # the higher, steeper bev_2 sees at least as much new ground as street-level held-out views
    assert cov["bev_2"]["unseen_at_similar_angle"] > cov["street"]["unseen_at_similar_angle"]


def test_refuses_to_overwrite_without_flag(small_street, make_config, tmp_path):
    with pytest.raises(ConfigError, match="overwrite"):
        generate_street(make_config(small_street))
    with pytest.raises(ConfigError, match="num_train"):
        generate_street(make_config(tmp_path / "x", num_train=1))


def test_validation_splits_are_new_views_and_leave_train_test_bytes_alone(small_street, make_config, tmp_path):
    """Adding val_street/val_bev must not change a single train/test file (the committed figures
    stay valid), and no validation camera may coincide with a test camera."""
    bare = tmp_path / "bare"
    generate_street(make_config(bare, num_val_street=0, num_val_bev=0, num_lane=0, num_val_lane=0))
    a, b = _files(small_street), _files(bare)
    shared = [k for k in b if k != "transforms.json"]
    assert len(shared) > 50 and [k for k in shared if a[k] != b[k]] == []
    meta_a, meta_b = (json.loads((d / "transforms.json").read_text()) for d in (small_street, bare))
    assert meta_a["frames"] == meta_b["frames"]
    assert {k: meta_a["eval_splits"][k] for k in meta_b["eval_splits"]} == meta_b["eval_splits"]
    assert meta_a["synthetic_street"]["generator_version"] == 3
    test_c = torch.cat([parse_dataset(small_street, s).cameras.camera_to_worlds for s in ("street", "bev_1", "bev_2")])
    train = parse_dataset(small_street, "train")
    for split, pitches in (("val_street", {0.0}), ("val_bev", {27.5, 22.0})):
        val_c = parse_dataset(small_street, split).cameras.camera_to_worlds
        dist = train.world_to_metres(torch.cdist(val_c[:, :, 3], test_c[:, :, 3]).min())
        assert float(dist) > 0.5, split  # metres from the nearest test camera
        fwd = -val_c[:, :, 2]
        got = {round(float(v), 1) for v in torch.rad2deg(torch.asin(-fwd[:, 2]))}
        assert got == pitches, split


def test_lane_splits_sit_beside_the_drive_on_the_road(small_street):
    """lane_<d>: level cameras at the training height, d metres across the road from a driven lane
    (the lane centres are at y = -+ROAD_HALF/2), inside the road, facing along it."""
    from nerf2gs_plugin.data.synthetic.layout import ROAD_HALF

    meta = json.loads((small_street / "transforms.json").read_text())
    assert meta["synthetic_street"]["lane"]["offsets_m"] == [1.0, 2.0, 4.0]
    for split, d in (("lane_1", 1.0), ("lane_2", 2.0), ("lane_4", 4.0)):
        c2w = torch.tensor([f["transform_matrix"] for f in meta["eval_splits"][split]])[:, :3]
        y = c2w[:, 1, 3]
        lane_y = torch.where(-c2w[:, 0, 2] > 0, -ROAD_HALF / 2, ROAD_HALF / 2)  # driving +x: right-hand lane
        assert torch.allclose((y - lane_y).abs(), torch.full_like(y, d), atol=1e-4), split
        assert float(y.abs().max()) <= ROAD_HALF, split
        assert torch.allclose(c2w[:, 2, 3], torch.full_like(y, 3.0), atol=1e-5)
        assert float(c2w[:, 2, 2].abs().max()) < 1e-5  # level: the view axis has no vertical part


def test_lane_split_sides_alternate_where_the_road_allows():
    from nerf2gs_plugin.data.synthetic.layout import ROAD_HALF
    from nerf2gs_plugin.data.synthetic.poses import lane_shift_poses

    c2w = lane_shift_poses(8, 24.0, 3.0, 1.0, torch.Generator().manual_seed(0))
    lane_y = torch.where(torch.arange(8) % 2 == 1, ROAD_HALF / 2, -ROAD_HALF / 2)
    side = torch.sign(c2w[:, 1, 3] - lane_y)
    assert int((side > 0).sum()) == 4 and int((side < 0).sum()) == 4
    far = lane_shift_poses(8, 24.0, 3.0, 4.0, torch.Generator().manual_seed(0))
    assert float(far[:, 1, 3].abs().max()) <= ROAD_HALF  # flipped toward the other lane, never off the road

def test_movers_ride_with_the_camera_and_parked_cars_are_static():
    """``--movers``: the lead car and the cyclist keep their place in the image as the camera drives
    on (exact transient masks), pedestrians cross, parked cars are drawn but not transient."""
    from nerf2gs_plugin.data.synthetic.layout import PARKED_CAR, build_layout
    from nerf2gs_plugin.data.synthetic.movers import build_movers
    from nerf2gs_plugin.data.synthetic.poses import heading_pose
    from nerf2gs_plugin.data.synthetic.raycast import Pinhole, ShadowMap, render_view

    layout = build_layout(0, num_cars=0)
    movers = build_movers(layout)
    assert (movers.parked.material == PARKED_CAR).any()
    layout.static = type(layout.static).cat([layout.static, movers.parked])
    intr = Pinhole.from_fov(64, 36, 80.0)
    walkers, movers.pedestrians = movers.pedestrians, []  # the riders alone first
    views = []
    for x in (-10.0, -8.5):
        c2w = heading_pose(torch.tensor([x]), torch.tensor([-1.75]), torch.tensor([3.0]), torch.tensor([0.0]), 0.0)[0]
        views.append(render_view(layout, c2w, intr, movers.boxes(0.0, c2w), ShadowMap(layout), spp=1))
    a, b = views[0].transient, views[1].transient
    assert a.sum() > 20 and float((a & b).sum()) / float((a | b).sum()) > 0.8  # rides along: the same pixels
    assert not bool(((views[0].material == PARKED_CAR).reshape(a.shape) & a).any())
    movers.pedestrians = walkers
    body_y = [float(movers.boxes(t, c2w).lo[-2, 1]) for t in (0.0, 3.0)]  # the last pedestrian's body
    assert abs(body_y[1] - body_y[0]) > 2.0  # walked across
