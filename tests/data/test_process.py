"""``ns2gs-data process``: frames, blur filter, bad inputs, and (slow) the real SfM on a short video
made from the synthetic street's forward drive."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from nerf2gs_plugin.cli.data import main
from nerf2gs_plugin.data import folder_fingerprint
from nerf2gs_plugin.data.process.frames import extract_video_frames, relative_blur_drop
from nerf2gs_plugin.data.process.sfm import SfmOptions, match
from nerf2gs_plugin.errors import DataError


def _write_video(path: Path, frames: list[np.ndarray], fps: float = 10.0) -> Path:
    h, w = frames[0].shape[:2]
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    for f in frames:
        wr.write(f)
    wr.release()
    return path


def _textured(rng, n: int, w: int = 96, h: int = 64) -> list[np.ndarray]:
    base = cv2.resize(rng.integers(0, 255, (h // 4, w // 4 + n), dtype=np.uint8), ((w + 4 * n), h), interpolation=cv2.INTER_NEAREST)
    return [cv2.cvtColor(np.ascontiguousarray(base[:, 4 * i:4 * i + w]), cv2.COLOR_GRAY2BGR) for i in range(n)]


def _pair_offsets(db: Path) -> set[int]:
    """How many frames apart the matched pairs of a COLMAP database are (image ids follow the frame order)."""
    import pycolmap

    with pycolmap.Database.open(str(db)) as d:
        ids = d.read_all_matches()[0]
    big = 2147483647  # COLMAP's pair id: id1 * big + id2
    return {abs(int(p) // big - int(p) % big) for p in ids}


def test_blur_drop_is_relative_to_neighbours():
    s = np.array([100.0, 110, 20, 105, 95, 5.0, 90])
    keep = relative_blur_drop(s, 0.5)
    assert keep.tolist() == [True, True, False, True, True, False, True]
    assert relative_blur_drop(s * 0.01, 0.5).tolist() == keep.tolist()  # a dark scene: same decision
    assert relative_blur_drop(s, 0.0).all()


def test_video_frames_sharpest_kept_in_order(tmp_path):
    frames = _textured(np.random.default_rng(0), 24)
    frames[7] = cv2.GaussianBlur(frames[7], (0, 0), 4)  # a blurry frame picked alone in its window -> dropped
    video = _write_video(tmp_path / "v.avi", frames)
    rep = extract_video_frames(video, tmp_path / "f", fps=None, num_frames=24, blur_ratio=0.5, max_size=0)
    idx = [int(n.split("_")[1].split(".")[0]) for n in rep.names]
    assert idx == sorted(idx) and 7 not in idx and rep.dropped_blurry >= 1
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == rep.names
    rep2 = extract_video_frames(video, tmp_path / "g", fps=None, num_frames=8, blur_ratio=0.0, max_size=48)
    assert len(rep2.names) == 8 and cv2.imread(str(tmp_path / "g" / rep2.names[0])).shape[1] == 48


def test_frames_that_repeat_the_one_kept_before_are_dropped(tmp_path):
    """A 10 fps drive written at 20 fps (every frame twice), then a stop (one view, six times): each window's frame
    that repeats the frame kept before it is dropped; the drive's frames stay."""
    drive = _textured(np.random.default_rng(1), 12)
    doubled = [f for f in drive for _ in (0, 1)]
    stop = [drive[-1].copy() for _ in range(6)]
    video = _write_video(tmp_path / "v.avi", doubled + stop)
    rep = extract_video_frames(video, tmp_path / "f", fps=None, num_frames=30, blur_ratio=0.0, max_size=0)
    assert len(rep.names) == 12 and rep.dropped_repeats == 30 - 12
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == rep.names


def test_unreadable_video_and_too_few_frames(tmp_path, capsys):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video at all")
    with pytest.raises(DataError, match="cannot read video"):
        extract_video_frames(bad, tmp_path / "f", None, 10, 0.5, 0)
    short = _write_video(tmp_path / "short.avi", _textured(np.random.default_rng(1), 3))
    with pytest.raises(DataError, match="too few frames"):
        extract_video_frames(short, tmp_path / "g", None, 10, 0.5, 0)
    from nerf2gs_plugin.cli.data import entrypoint
    import sys

    argv = sys.argv
    sys.argv = ["ns2gs-data", "process", "video", str(bad), "--out", str(tmp_path / "d"), "--no-progress"]
    try:
        with pytest.raises(SystemExit) as e:
            entrypoint()
    finally:
        sys.argv = argv
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "cannot read video" in err[0]


def test_images_too_few(tmp_path):
    (tmp_path / "photos").mkdir()
    for i, f in enumerate(_textured(np.random.default_rng(2), 2)):
        cv2.imwrite(str(tmp_path / "photos" / f"p{i}.png"), f)
    (tmp_path / "photos" / "notes.txt").write_text("x")
    with pytest.raises(DataError, match="too few images: 2"):
        main(["process", "images", str(tmp_path / "photos"), "--out", str(tmp_path / "d"), "--no-progress"])


@pytest.mark.slow
def test_process_video_end_to_end(tmp_path, make_config, monkeypatch):
    """A 30-frame 200x112 drive (1.6 m apart) (the street's forward pass) -> all registered, poses within 1% ATE
    of the truth, a scale from the 3 m camera height (loose: at 200x112 px SIFT finds ~15 points on the
    road, so the plane is weakly supported; the 5% check is on synthetic points), parsers
    read the result, and a re-run reuses the features and the model."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.data.synthetic_street import generate_street
    from nerf2gs_plugin.eval.pose_eval import pose_errors

    street = tmp_path / "street"
    generate_street(make_config(street, width=200, height=112, num_train=60, num_street=1, num_bev=1, num_cars=2, spp=5, num_points=100))
    meta = json.loads((street / "transforms.json").read_text())
    fwd = meta["frames"][:30]
    video = _write_video(tmp_path / "drive.avi", [cv2.imread(str(street / f["file_path"])) for f in fwd])
    out = tmp_path / "data"
    args = ["process", "video", str(video), "--out", str(out), "--num-frames", "30", "--camera-height", "3.0", "--fov-deg", "80", "--no-progress",
            "--num-threads", "1", "--no-refine-intrinsics"]  # one thread: repeatable; the camera's FOV is known
    main(args)
    est = json.loads((out / "transforms.json").read_text())
    assert est["process"]["registered"] == len(est["frames"]) >= 28
    check = est["process"]["capture_check"]  # one drive: one scale, no jump along its path
    assert check["consistent"] and check["measured"] >= 20 and check["path_jump"]["ratio"] < 2.0
    assert all(f["fl_x"] == f["fl_y"] and (f["cx"], f["cy"]) == (100, 56) for f in est["frames"])  # the FOV's focal, centred
    for d in (2, 4, 8):
        assert len(list((out / f"images_{d}").iterdir())) == len(est["frames"])
    idx = [int(f["file_path"].split("_")[-1].split(".")[0]) for f in est["frames"]]
    true = np.array([np.array(fwd[i]["transform_matrix"])[:3] for i in idx])
    pe = pose_errors(np.array([np.array(f["transform_matrix"])[:3] for f in est["frames"]]), true)
    assert pe.ate_percent < 1.0
    assert abs(est["metres_per_unit"] / pe.scale - 1) < 0.5
    train = parse_dataset(out, "train")
    assert len(train.image_filenames) > 10 and train.points3D_xyz is not None
    # sequential matching's pairs: the quadratic hops by default, the linear window and the hops without them
    assert _pair_offsets(out / "colmap" / "database.db") == {1, 2, 4, 8, 16}
    import pycolmap

    lin = tmp_path / "linear.db"
    shutil.copy(out / "colmap" / "database.db", lin)
    with pycolmap.Database.open(str(lin)) as d:
        d.clear_matches()
        d.clear_two_view_geometries()
    assert match(lin, "sequential", SfmOptions(overlap=5, quadratic_overlap=False, num_threads=1), tmp_path / "marker.json")
    assert _pair_offsets(lin) == {1, 2, 3, 4, 5, 8, 16}
    stamps = {p: (out / "colmap" / p).stat().st_mtime for p in ("matching.json", "distorted/done.json")}
    print_before = folder_fingerprint(out)
    first = Path(est["frames"][0]["file_path"]).name
    inodes = {d: (out / d / first).stat().st_ino for d in ("images", "images_4")}
    main(args)  # resumed: features, matches and model reused
    assert {p: (out / "colmap" / p).stat().st_mtime for p in stamps} == stamps
    # the images are the same bytes: left in place (a run reading them meanwhile never finds one missing)
    assert {d: (out / d / first).stat().st_ino for d in inodes} == inodes
    # the times of a re-run live beside transforms.json: the data a run reads (its fingerprint) is unchanged
    assert set(json.loads((out / "colmap" / "stage_seconds.json").read_text())) >= {"features", "matching", "mapping"}
    assert folder_fingerprint(out) == print_before
    # other attempts could keep another model: the mapping runs again (the matches are kept)
    main(args + ["--mapping-attempts", "2"])
    assert (out / "colmap" / "distorted/done.json").stat().st_mtime != stamps["distorted/done.json"]
    assert (out / "colmap" / "matching.json").stat().st_mtime == stamps["matching.json"]
    # a broken join (forced: every step of the path counts as a jump) keeps the longest consistent stretch, in every output
    import pycolmap

    from nerf2gs_plugin.data.process import capture_check, scale_check

    monkeypatch.setattr(scale_check, "MAX_STEP_JUMP", 1.0)
    monkeypatch.setattr(capture_check, "MAX_CUTS", 1)  # one cut: the longer side (at least half) is kept
    main(args + ["--min-registered-fraction", "0.3"])
    cut = json.loads((out / "transforms.json").read_text())
    kept = [Path(f["file_path"]).name for f in cut["frames"]]
    assert cut["process"]["kept"] == len(kept) < cut["process"]["registered"] and cut["process"]["capture_check"]["dropped"]
    assert sorted(p.name for p in (out / "images").iterdir()) == sorted(kept) == sorted(p.name for p in (out / "images_4").iterdir())
    assert sorted(im.name for im in pycolmap.Reconstruction(str(out / "sparse" / "0")).images.values() if im.has_pose) == sorted(kept)
    assert not set(cut["process"]["capture_check"]["dropped"]) & set(kept)
    main(args + ["--broken-join", "keep"])  # the warning only: every frame stays
    assert len(json.loads((out / "transforms.json").read_text())["frames"]) == cut["process"]["registered"]
    monkeypatch.undo()
    main(args[:6] + ["28"] + args[7:] + ["--metres-per-unit", "1.0"])  # other frames: stale features and matches are not mixed in
    est = json.loads((out / "transforms.json").read_text())
    assert est["process"]["frames"] == len(list((out / "colmap" / "frames").iterdir())) <= 28


@pytest.mark.parametrize("model,params", [("SIMPLE_PINHOLE", [119.0, 100.0, 56.0]), ("SIMPLE_RADIAL", [119.0, 100.0, 56.0, 0.0]),
                                          ("PINHOLE", [119.0, 119.0, 100.0, 56.0]), ("OPENCV", [119.0, 119.0, 100.0, 56.0, 0, 0, 0, 0])])
def test_export_intrinsics_of_every_undistorted_model(model, params):
    """The undistorter keeps a zero-distortion SIMPLE_RADIAL as it is ([f, cx, cy, k]); reading its
    params as PINHOLE wrote fy = cx, cx = cy, cy = 0 into transforms.json (the bench's capture)."""
    import pycolmap

    from nerf2gs_plugin.data.process.export import pinhole_params

    cam = pycolmap.Camera.create_from_model_name(1, model, 119.0, 200, 112)
    cam.params = params
    assert pinhole_params(cam) == (119.0, 119.0, 100.0, 56.0)
    if model == "OPENCV":
        cam.params = params[:4] + [0.1, 0, 0, 0]
        with pytest.raises(DataError, match="distortion"):
            pinhole_params(cam)


@pytest.mark.parametrize("known_focal", [False, True])
def test_mapping_retries_loosen_the_initialisation_before_moving_the_pair(tmp_path, monkeypatch, known_focal):
    """A forward drive of closely spaced frames never reaches COLMAP's 16 deg initial triangulation
    angle: the second run keeps COLMAP's own pair choice under looser thresholds, only later runs
    start from pairs at other points of the capture; when none registers, one clear error. Retries hold
    a known focal (EXIF / --fov-deg) fixed; a guessed one stays refined."""
    import pycolmap

    from nerf2gs_plugin.data.process.sfm import SfmOptions, reconstruct

    db = tmp_path / "database.db"
    with pycolmap.Database.open(str(db)) as d:
        camera = pycolmap.Camera.create_from_model_name(1, "SIMPLE_PINHOLE", 100.0, 64, 48)
        camera.has_prior_focal_length = known_focal
        cam = d.write_camera(camera)
        for i in range(12):
            d.write_image(pycolmap.Image(name=f"f{i:03d}.png", camera_id=cam))
    runs, refined = [], []

    def fake_mapping(database, image_dir, out, options=None, **kw):
        runs.append((options.init_image_id1, options.init_image_id2, options.mapper.init_min_tri_angle,
                     options.mapper.init_max_forward_motion, options.init_num_trials))
        refined.append((options.ba_refine_focal_length, options.mapper.abs_pose_refine_focal_length))
        return {}

    monkeypatch.setattr(pycolmap, "incremental_mapping", fake_mapping)
    with pytest.raises(DataError, match="0 of 12 images registered"):
        reconstruct(db, tmp_path, tmp_path / "sparse", 12, SfmOptions(), matches_changed=True)
    assert len(runs) == SfmOptions().mapping_attempts == 4
    default_pair = runs[0][:2]
    assert runs[0][2] == 16.0 and runs[1][2] == runs[2][2] == 8.0 and runs[1][3] == 0.99
    assert runs[1][:2] == default_pair  # COLMAP still chooses the pair
    assert runs[2][:2] != default_pair and runs[3][:2] not in (default_pair, runs[2][:2])  # then pairs at other points
    # a pair of ours is not retried 200 times (COLMAP's default: a minute on a 14-frame capture)
    assert runs[0][4] == runs[1][4] == 200 and runs[2][4] == runs[3][4] <= 5
    assert refined == [(True, True)] + [(not known_focal, not known_focal)] * 3


class _FakeModel:
    """What ``reconstruct`` reads of a pycolmap model: frames registered, points, and a write."""

    def __init__(self, registered: int, seed: int) -> None:
        self.registered, self.seed = registered, seed

    def num_reg_images(self) -> int:
        return self.registered

    def num_points3D(self) -> int:
        return 100

    def write(self, path: str) -> None:
        Path(path, "seed.txt").write_text(str(self.seed))


@pytest.mark.parametrize("registered", [12, 5])
def test_mapping_runs_are_ranked_by_the_frames_the_capture_check_keeps(tmp_path, monkeypatch, registered):
    """Every run registers all 12 frames but joins them in the wrong place, save the one under seed 5: with
    the capture check's score the retries go on past ``mapping_attempts`` (other seeds, COLMAP's own pair) and
    that run is kept; without a score the first run ends them. A capture that registers under half of its
    frames in every run gets no more runs than ``mapping_attempts``."""
    import pycolmap

    from nerf2gs_plugin.data.process.sfm import SfmOptions, reconstruct

    db = tmp_path / "database.db"
    with pycolmap.Database.open(str(db)) as d:
        cam = d.write_camera(pycolmap.Camera.create_from_model_name(1, "SIMPLE_PINHOLE", 100.0, 64, 48))
        for i in range(12):
            d.write_image(pycolmap.Image(name=f"f{i:03d}.png", camera_id=cam))
    runs: list[tuple[int, int]] = []

    def fake_mapping(database, image_dir, out, options=None, **kw):
        runs.append((options.random_seed, options.init_image_id1))
        return {0: _FakeModel(registered, options.random_seed)}

    def score(model) -> int:  # the frames of its longest consistent stretch
        return model.registered if model.seed == 5 else model.registered // 2

    monkeypatch.setattr(pycolmap, "incremental_mapping", fake_mapping)
    opt = SfmOptions()
    res = reconstruct(db, tmp_path, tmp_path / "sparse", 12, opt, matches_changed=True, score=score)
    if registered == 5:
        assert len(runs) == opt.mapping_attempts and res.registered == 5
        return
    assert [seed for seed, _ in runs] == list(range(6)) and res.registered == 12
    assert (tmp_path / "sparse" / "0" / "seed.txt").read_text() == "5"
    assert runs[4][1] == runs[5][1] == runs[0][1]  # COLMAP's own initial pair again
    runs.clear()
    reconstruct(db, tmp_path, tmp_path / "sparse2", 12, opt, matches_changed=True)
    assert len(runs) == 1
    runs.clear()
    res = reconstruct(db, tmp_path, tmp_path / "sparse3", 12, SfmOptions(join_attempts=0), matches_changed=True, score=score)
    assert len(runs) == opt.mapping_attempts and (tmp_path / "sparse3" / "0" / "seed.txt").read_text() == "0"


def test_focal_that_ran_away_from_the_known_one_is_caught():
    """A forward drive can register every frame with half the true focal: that model must not end the retries."""
    from types import SimpleNamespace

    import pycolmap

    from nerf2gs_plugin.data.process.sfm import focal_ran_away

    def rec(f: float):
        return SimpleNamespace(cameras={1: pycolmap.Camera.create_from_model_name(1, "SIMPLE_RADIAL", f, 800, 240)})

    assert focal_ran_away(rec(203.0), 468.0) and focal_ran_away(rec(1183.0), 468.0)
    assert not focal_ran_away(rec(468.0), 468.0) and not focal_ran_away(rec(715.0), 996.0)


def test_install_images_replaces_only_what_changed(tmp_path):
    """Unchanged images stay (same inode, copies kept); a changed one is replaced and loses its copies; a
    gone one is removed; write_downscaled then remakes the missing copies and drops the stale ones."""
    from nerf2gs_plugin.data.process.export import install_images, write_downscaled

    root, src = tmp_path / "data", tmp_path / "und"
    src.mkdir()
    imgs = {n: np.full((16, 16, 3), v, np.uint8) for n, v in (("a.png", 10), ("b.png", 20), ("c.png", 30))}
    for n, im in imgs.items():
        cv2.imwrite(str(src / n), im)
    install_images(src, root)
    write_downscaled(root, sorted(imgs))
    ino = {n: (root / "images" / n).stat().st_ino for n in imgs}
    for n, v in (("a.png", 10), ("b.png", 99)):  # a: same bytes, b: changed, c: gone
        cv2.imwrite(str(src / n), np.full((16, 16, 3), v, np.uint8))
    install_images(src, root)
    assert (root / "images" / "a.png").stat().st_ino == ino["a.png"] and (root / "images_4" / "a.png").is_file()
    assert cv2.imread(str(root / "images" / "b.png"))[0, 0, 0] == 99 and not (root / "images_4" / "b.png").exists()
    assert sorted(p.name for p in (root / "images").iterdir()) == ["a.png", "b.png"]
    write_downscaled(root, ["a.png", "b.png"])
    assert sorted(p.name for p in (root / "images_4").iterdir()) == ["a.png", "b.png"]
    assert cv2.imread(str(root / "images_2" / "b.png"))[0, 0, 0] == 99


@pytest.mark.parametrize("cut", ["in the last frame", "in the frame before"])
def test_truncated_video_drops_the_half_decoded_frame(tmp_path, cut):
    video = _write_video(tmp_path / "v.avi", _textured(np.random.default_rng(2), 8))
    data = video.read_bytes()
    soi = [m for m in range(len(data) - 1) if data[m:m + 2] == b"\xff\xd8"]  # where each JPEG frame starts
    k = -1 if cut == "in the last frame" else -2
    video.write_bytes(data[:(soi[k] + (soi[k + 1] if k == -2 else len(data))) // 2])  # mid-frame
    with pytest.warns(UserWarning, match=r"v\.avi is truncated .*last frame \(index \d\) is half-decoded and dropped"):
        rep = extract_video_frames(video, tmp_path / "f", fps=None, num_frames=8, blur_ratio=0.0, max_size=0)
    assert len(rep.names) == (7 if k == -1 else 6)
    whole = extract_video_frames(_write_video(tmp_path / "w.avi", _textured(np.random.default_rng(2), 8)), tmp_path / "g",
                                 fps=None, num_frames=8, blur_ratio=0.0, max_size=0)
    assert len(whole.names) == 8  # an intact video keeps its last frame


def test_crop_factor_cuts_the_frames_before_the_sfm(tmp_path):
    """--crop-factor (top bottom left right) as nerfstudio's: video frames and photos lose those shares of their
    sides (then --max-size); a photo is cropped again when the crop changes; bad shares are one error line."""
    from nerf2gs_plugin.data.process.frames import collect_images
    from nerf2gs_plugin.data.process.pipeline import ProcessOptions, check_options
    from nerf2gs_plugin.errors import ConfigError

    frames = _textured(np.random.default_rng(3), 8)  # 96x64
    video = _write_video(tmp_path / "v.avi", frames)
    rep = extract_video_frames(video, tmp_path / "f", fps=None, num_frames=8, blur_ratio=0.0, max_size=0, crop=(0.0, 0.25, 0.0, 0.0))
    got = cv2.imread(str(tmp_path / "f" / rep.names[0]))
    assert got.shape[:2] == (48, 96)  # the bottom quarter (a bonnet) cut off
    photos = tmp_path / "photos"
    photos.mkdir()
    for i, f in enumerate(frames[:6]):
        cv2.imwrite(str(photos / f"p{i}.png"), f)
    collect_images(photos, tmp_path / "c", 0, crop=(0.0, 0.0, 0.25, 0.25))
    crop = cv2.imread(str(tmp_path / "c" / "p0.png"))
    assert crop.shape[:2] == (64, 48) and np.abs(crop.astype(int) - frames[0][:, 24:72]).max() <= 2
    collect_images(photos, tmp_path / "c", 0)  # no crop now: copied again, whole
    assert cv2.imread(str(tmp_path / "c" / "p0.png")).shape[:2] == (64, 96)
    for bad in ((0.0, 1.0, 0.0, 0.0), (-0.1, 0.0, 0.0, 0.0), (0.5, 0.5, 0.0, 0.0)):
        with pytest.raises(ConfigError, match="crop-factor"):
            check_options(ProcessOptions(crop_factor=bad))
