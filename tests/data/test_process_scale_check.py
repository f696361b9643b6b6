"""The scale check of ``ns2gs-data process``: a capture joined at two scales is found, one scale is not flagged."""

from types import SimpleNamespace

import numpy as np
import pytest

from nerf2gs_plugin.data.process.scale_check import (MAX_HEIGHT_JUMP, MAX_STEP_JUMP_PHOTOS, local_camera_heights, path_jump,
                                                     scale_jump, standing_frames)


def _street(n: int, height: float, spacing: float, x0: float = 0.0, seed: int = 0):
    """Cameras ``height`` above a road (z = 0) along x, and per camera what it sees: road points below
    and ahead of it plus facade points up to 2x its height (all in one unit)."""
    rng = np.random.default_rng(seed)
    centres = np.stack([x0 + spacing * np.arange(n), np.zeros(n), np.full(n, height)], 1)
    seen = []
    for c in centres:
        road = np.stack([c[0] + rng.uniform(0, 10 * height, 40), rng.uniform(-height, height, 40), np.zeros(40)], 1)
        facade = np.stack([c[0] + rng.uniform(0, 10 * height, 60), np.full(60, 2 * height), rng.uniform(0, 2 * height, 60)], 1)
        seen.append(np.concatenate([road, facade]))
    return centres, seen


def test_local_height_is_the_road_below_each_camera():
    centres, seen = _street(5, 3.0, 1.0)
    h = local_camera_heights(centres, seen, np.array([0.0, 0.0, 2.0]))  # up need not be unit
    assert np.allclose(h, 3.0, rtol=0.05)
    seen[2] = seen[2][:5]  # too few points below: not measured
    assert np.isnan(local_camera_heights(centres, seen, np.array([0.0, 0.0, 1.0]))[2])


def test_two_stretches_at_different_scales_are_found_at_their_join():
    """A drive down and back: each pass right, the second at 25x the first's scale."""
    a = _street(30, 0.03, 0.01)
    b = _street(30, 0.75, 0.25, x0=1.0, seed=1)
    h = local_camera_heights(np.concatenate([a[0], b[0]]), a[1] + b[1], np.array([0.0, 0.0, 1.0]))
    names = [f"f{i:03d}" for i in range(60)]
    check = scale_jump(h, names)
    assert not check.consistent and check.split == 30 and check.first_name == "f030" and check.second_higher
    assert check.ratio == pytest.approx(25.0, rel=0.1)
    what, advice = check.problem()
    assert "f030" in what and "25.0x higher" in what and "--matching exhaustive" in advice
    assert check.to_json()["consistent"] is False


def test_one_scale_with_noise_and_outliers_is_consistent():
    rng = np.random.default_rng(3)
    h = np.exp(rng.normal(0.0, 0.2, 80))  # +-20% height noise
    h[[10, 50]] *= 5.0  # two frames whose lowest points are a wall's foot or a kerb
    h[20] = np.nan  # a camera that sees nothing below it
    check = scale_jump(h)
    assert check.consistent and check.ratio < 1.5 and check.measured == 79
    slope = np.linspace(1.0, 2.0, 60)  # a drive uphill away from one fitted plane: a gradual change, not a jump
    assert scale_jump(slope).ratio < MAX_HEIGHT_JUMP


def test_too_few_measured_cameras_compare_nothing():
    check = scale_jump(np.array([1.0, np.nan, 5.0, 1.0, np.nan]))
    assert check.split == 0 and check.consistent and "not compared" in check.summary


def test_a_jump_along_an_ordered_path_is_found():
    """The forward drive once joined as two halves 5 frame spacings apart: one step 6x the others."""
    x = np.concatenate([np.arange(30) * 0.5, 17.5 + np.arange(30) * 0.5])
    x[10:] += np.where(np.arange(50) % 7 == 0, 0.1, 0.0)  # a little unevenness everywhere
    centres = np.stack([x, np.zeros(60), np.zeros(60)], 1)
    jump = path_jump(centres, [f"f{i:02d}" for i in range(60)])
    assert not jump.consistent and jump.index == 29 and jump.names == ("f29", "f30") and jump.ratio == pytest.approx(6.0, rel=0.1)
    assert "f29 and f30" in jump.problem()[0]
    one = path_jump(np.stack([np.arange(60) * 0.5, np.zeros(60), np.zeros(60)], 1))
    assert one.consistent and one.ratio == pytest.approx(1.0)
    stop = np.concatenate([np.arange(20) * 0.5, np.full(15, 9.5), 9.5 + np.arange(1, 21) * 0.5])  # a car at a red light
    assert path_jump(np.stack([stop, np.zeros(55), np.zeros(55)], 1)).consistent
    # a stop with the SfM's noise on it, then the drive's own uneven speed: no jump (half the window standing
    # made the median of the steps around the first moving one a fraction of it)
    rng = np.random.default_rng(0)
    steps = np.concatenate([np.full(30, 1.2), rng.uniform(0, 0.002, 25), [1.25, 1.3, 1.13, 1.11, 0.9, 0.45, 0.3, 0.3], np.full(20, 1.0)])
    go = np.stack([np.concatenate([[0.0], np.cumsum(steps)]), np.zeros(len(steps) + 1), np.zeros(len(steps) + 1)], 1)
    assert path_jump(go).consistent
    # ... but a wrong join right after the stop is still one
    steps[55] = 6.5
    jumped = path_jump(np.stack([np.concatenate([[0.0], np.cumsum(steps)]), np.zeros(len(steps) + 1), np.zeros(len(steps) + 1)], 1))
    assert not jumped.consistent and jumped.index == 55
    assert path_jump(np.zeros((3, 3))) is None
    assert path_jump(centres, max_ratio=MAX_STEP_JUMP_PHOTOS).consistent  # a photo set may jump 6x (a walker's photos)


def test_check_reconstruction_reads_a_reconstruction_and_warns(recwarn):
    """``process`` wiring: the tracks of each image of a (pycolmap-shaped) reconstruction -> the checks."""
    from nerf2gs_plugin.data.process.capture_check import check_reconstruction

    a = _street(10, 0.03, 0.01)
    b = _street(10, 0.75, 0.25, x0=1.0, seed=1)
    centres, seen = np.concatenate([a[0], b[0]]), a[1] + b[1]
    points, images = {}, {}
    for i, pts in enumerate(seen):
        ids = []
        for p in pts:
            points[len(points) + 1] = SimpleNamespace(xyz=p)
            ids.append(len(points))
        obs = [SimpleNamespace(point3D_id=j, has_point3D=lambda: True) for j in ids]
        obs.append(SimpleNamespace(point3D_id=-1, has_point3D=lambda: False))  # an unmatched keypoint
        images[i] = SimpleNamespace(name=f"frame_{i:03d}.jpg", points2D=obs)
    rec = SimpleNamespace(images=images, points3D=points)
    c2w = np.zeros((20, 3, 4))
    c2w[:, :3, 3] = centres
    names = [f"frame_{i:03d}.jpg" for i in range(20)]
    check = check_reconstruction(rec, names, c2w, np.array([0.0, 0.0, 1.0]))
    # a photo set (exhaustive matching): its path is held to the looser photo-set bound (the 0.01 -> 0.9 step is 8.9x)
    assert not check["consistent"] and check["split"] == 10 and check["path_jump"]["consistent"]
    assert check["path_jump"]["max_ratio"] == MAX_STEP_JUMP_PHOTOS
    assert any("changes scale along the capture" in str(w.message) and "frame_010.jpg" in str(w.message) for w in recwarn)
    ordered = check_reconstruction(rec, names, c2w, np.array([0.0, 0.0, 1.0]), ordered=True)
    assert ordered["path_jump"]["index"] == 9 and not ordered["path_jump"]["consistent"]  # 0.01-unit steps, then 0.25
    assert ordered["line"].startswith("capture check FAILED: scale 25.0x apart from frame_010.jpg on; path jump ")
    assert ordered["line"].endswith("x between frame_009.jpg and frame_010.jpg (warnings above)")
    one = check_reconstruction(rec, names[:10], c2w[:10], np.array([0.0, 0.0, 1.0]), ordered=True)
    assert one["consistent"] and one["line"].startswith("capture check: one scale (camera height above the road within")


def test_a_broken_capture_whose_longest_stretch_is_short_is_an_error(tmp_path):
    from nerf2gs_plugin.data.process.pipeline import _check_kept
    from nerf2gs_plugin.errors import DataError

    with pytest.raises(DataError, match=r"longest consistent stretch holds only 12 of 30 frames.*--broken-join keep"):
        _check_kept(tmp_path, 12, 30, 0.5)
    _check_kept(tmp_path, 15, 30, 0.5)


def test_a_stop_keeps_its_first_frame_and_a_turn_on_the_spot():
    """A red light: the frames after the first of a stop repeat its view (SfM noise on the pose) and go; a camera
    that turns while it stands sees something new and stays; the drive's slow steps stay."""
    rng = np.random.default_rng(1)
    x = np.concatenate([np.arange(10) * 1.0, 9.0 + rng.normal(0, 0.003, 8), 9.0 + np.cumsum([0.3, 0.6, 1.0, 1.0, 1.0, 1.0])])
    yaw = np.zeros(len(x))
    yaw[14:18] = [5.0, 10.0, 10.0, 10.5]  # standing, the camera turns 5 degrees twice, then holds
    c2w = np.tile(np.eye(4), (len(x), 1, 1))
    a = np.radians(yaw)
    c2w[:, 0, 0], c2w[:, 0, 1], c2w[:, 1, 0], c2w[:, 1, 1] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    c2w[:, 0, 3] = x
    names = [f"f{i:02d}" for i in range(len(x))]
    assert standing_frames(c2w, names) == ["f10", "f11", "f12", "f13", "f16", "f17"]
    assert standing_frames(c2w[:3], names[:3]) == []
