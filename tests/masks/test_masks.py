"""ns2gs-data masks: the ONNX segmenter (layout, normalisation, class maps, bad files), the
mask-from-renders functions on constructed renders with known answers, and mask_iou."""

from __future__ import annotations

import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from nerf2gs_plugin.cli import data as data_cli
from nerf2gs_plugin.data.images import load_mask, write_image_atomic
from nerf2gs_plugin.masks import from_renders as fr
from nerf2gs_plugin.masks.class_maps import CITYSCAPES
from nerf2gs_plugin.masks.onnx_segmenter import OnnxSegmenter
from nerf2gs_plugin.masking.make_masks import MasksConfig, make_masks
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.masks.evaluate import dataset_mask_iou, hide_ground_truth, mask_iou

# ---------------------------------------------------------------- a tiny ONNX segmenter
MEAN, STD = (200.0, 190.0, 180.0), (20.0, 25.0, 30.0)  # in 0..255: a wrong normalisation picks other classes
COLOURS = {10: (0.3, 0.5, 0.95), 0: (0.45, 0.45, 0.45), 13: (0.9, 0.1, 0.1), 8: (0.1, 0.6, 0.1)}  # sky, road, car, vegetation


def _prototype_model(path: Path, layout: str = "NCHW", fixed: tuple[int, int] | None = None, meta: dict | None = None) -> Path:
    """A 1x1 conv whose 19 logits are -|x - p_k|^2 (+ const) in the normalised space: nearest colour wins."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    protos = np.full((19, 3), 5.0, dtype=np.float32)  # unused classes: far away in normalised space
    for k, c in COLOURS.items():
        protos[k] = (np.array(c) * 255 - np.array(MEAN)) / np.array(STD)
    W = (2 * protos)[:, :, None, None].astype(np.float32)
    b = (-(protos ** 2).sum(1)).astype(np.float32)
    H, Wd = fixed if fixed else ("H", "W")
    shape = [1, 3, H, Wd] if layout == "NCHW" else [1, H, Wd, 3]
    nodes, src = [], "image"
    if layout == "NHWC":
        nodes.append(helper.make_node("Transpose", ["image"], ["x"], perm=[0, 3, 1, 2]))
        src = "x"
    nodes.append(helper.make_node("Conv", [src, "W", "b"], ["logits"]))
    graph = helper.make_graph(nodes, "seg", [helper.make_tensor_value_info("image", TensorProto.FLOAT, shape)],
                              [helper.make_tensor_value_info("logits", TensorProto.FLOAT, [1, 19, H, Wd])],
                              [numpy_helper.from_array(W, "W"), numpy_helper.from_array(b, "b")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    for k, v in (meta or {}).items():
        model.metadata_props.add(key=k, value=v)
    onnx.save(model, str(path))
    return path


def _test_image(h: int = 24, w: int = 32) -> tuple[torch.Tensor, dict[str, np.ndarray]]:
    img = torch.empty(h, w, 3)
    img[:] = torch.tensor(COLOURS[8])
    img[: h // 3] = torch.tensor(COLOURS[10])
    img[2 * h // 3 :] = torch.tensor(COLOURS[0])
    car = (slice(h // 2, h // 2 + h // 4), slice(w // 8, w // 8 + w // 4))
    img[car] = torch.tensor(COLOURS[13])
    gt = {"sky": np.zeros((h, w), bool), "ground": np.zeros((h, w), bool), "transient": np.zeros((h, w), bool)}
    gt["sky"][: h // 3] = True
    gt["ground"][2 * h // 3 :] = True
    gt["transient"][car] = True
    gt["ground"][car] = False
    return img, gt


SIDECAR = {"range": "0,255", "mean": ",".join(map(str, MEAN)), "std": ",".join(map(str, STD))}


def test_onnx_segmenter_nchw_sidecar_and_cityscapes_map(tmp_path):
    model = _prototype_model(tmp_path / "seg.onnx")
    (tmp_path / "seg.onnx.json").write_text(json.dumps(SIDECAR))
    img, gt = _test_image()
    masks = OnnxSegmenter(model).masks(img)  # 19 classes -> the Cityscapes map by default
    for k in gt:
        assert np.array_equal(masks[k].numpy(), gt[k]), k
    # without the sidecar's normalisation the model sees other colours: the masks are wrong
    (tmp_path / "seg.onnx.json").unlink()
    wrong = OnnxSegmenter(model).masks(img)
    assert not all(np.array_equal(wrong[k].numpy(), gt[k]) for k in gt)


def test_onnx_segmenter_nhwc_fixed_size_metadata_and_user_map(tmp_path):
    meta = {"layout": "NHWC", "classes": "cityscapes", **SIDECAR}
    model = _prototype_model(tmp_path / "seg.onnx", layout="NHWC", fixed=(12, 16), meta=meta)
    img, gt = _test_image(48, 64)  # resized to 12x16 and back: compare away from the edges
    seg = OnnxSegmenter(model)
    assert seg.size == (12, 16) and seg.layout == "NHWC"
    masks = seg.masks(img)
    for k in gt:
        assert mask_iou(masks[k], gt[k]) > 0.7, k
    # a user map by class names: vegetation counts as ground, cars are not transient
    cmap = tmp_path / "map.json"
    cmap.write_text(json.dumps({"ground": ["vegetation", "road"], "sky": [10]}))
    masks = OnnxSegmenter(model, class_map=str(cmap)).masks(img)
    assert not masks["transient"].any()
    assert mask_iou(masks["ground"], ~gt["sky"] & ~gt["transient"]) > 0.8


def test_onnx_segmenter_tiles_agree_with_one_pass(tmp_path):
    model = _prototype_model(tmp_path / "seg.onnx")
    (tmp_path / "seg.onnx.json").write_text(json.dumps({**SIDECAR, "tile_size": "16", "overlap": 4}))
    img, gt = _test_image(40, 56)
    lab_tiled = OnnxSegmenter(model).labels(img)
    (tmp_path / "seg.onnx.json").write_text(json.dumps(SIDECAR))
    assert torch.equal(lab_tiled, OnnxSegmenter(model).labels(img))  # a 1x1 conv: tiling changes nothing


@pytest.mark.parametrize("case", ["bad_file", "missing_file", "bad_map_id", "bad_map_key", "bad_map_name", "bad_sidecar"])
def test_bad_segmenter_inputs_are_one_line_naming_the_file(tmp_path, case):
    model = _prototype_model(tmp_path / "seg.onnx")
    img, _ = _test_image()
    cmap = tmp_path / "map.json"
    named = model
    kw = {}
    if case == "bad_file":
        model.write_bytes(b"this is not an onnx model")
    elif case == "missing_file":
        model, named = tmp_path / "nope.onnx", tmp_path / "nope.onnx"
    elif case == "bad_sidecar":
        (tmp_path / "seg.onnx.json").write_text(json.dumps({"layuot": "NHWC"}))
        named = tmp_path / "seg.onnx.json"
    else:
        cmap.write_text(json.dumps({"bad_map_id": {"sky": [25]}, "bad_map_key": {"skyy": [10]},
                                    "bad_map_name": {"sky": ["heaven"]}}[case]))
        kw, named = {"class_map": str(cmap)}, cmap
    with pytest.raises(ConfigError) as e:
        OnnxSegmenter(model, **kw).masks(img)
    msg = str(e.value)
    assert "\n" not in msg and str(named) in msg


def _tiny_dataset(root: Path, n: int = 3) -> Path:
    img, _ = _test_image()
    frames = []
    for i in range(n):
        write_image_atomic(root / "images" / f"f{i}.png", img)
        frames.append({"file_path": f"images/f{i}.png", "transform_matrix": [[1, 0, 0, i], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})
    (root / "transforms.json").write_text(json.dumps({"fl_x": 30, "w": 32, "h": 24, "frames": frames}))
    return root


def test_make_masks_onnx_writes_the_layout_the_parsers_read(tmp_path):
    from nerf2gs_plugin.data import parse_dataset

    model = _prototype_model(tmp_path / "seg.onnx")
    (tmp_path / "seg.onnx.json").write_text(json.dumps(SIDECAR))
    data = _tiny_dataset(tmp_path / "d")
    make_masks(MasksConfig(data=data, segmenter=f"onnx:{model}", progress=False), log=lambda s: None)
    _, gt = _test_image()
    for k in ("sky", "ground", "transient"):
        assert np.array_equal(load_mask(data / "masks" / k / "f1.png").numpy(), gt[k])
    outs = parse_dataset(data, "train")
    assert set(outs.mask_filenames) == {"sky", "ground", "transient"}
    with pytest.raises(ConfigError, match="already has masks"):
        make_masks(MasksConfig(data=data, segmenter=f"onnx:{model}", progress=False), log=lambda s: None)


def test_staging_left_by_a_killed_run_is_removed_and_a_live_runs_kept(tmp_path):
    """kill -9 during masks left its hidden .masks-<pid>.tmp folder in the dataset for good: the next
    run removes those of processes that are gone, and only those (a run going on beside it keeps its own)."""
    import subprocess

    model = _prototype_model(tmp_path / "seg.onnx")
    (tmp_path / "seg.onnx.json").write_text(json.dumps(SIDECAR))
    data = _tiny_dataset(tmp_path / "d")
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        for pid in (gone.pid, live.pid):
            (data / f".masks-{pid}.tmp" / "masks" / "sky").mkdir(parents=True)
            (data / f".masks-{pid}.tmp" / "masks" / "sky" / "f0.png").write_bytes(b"half")
        (data / ".masks-notes.tmp").mkdir()  # not a pid: not ours to judge
        lines: list[str] = []
        make_masks(MasksConfig(data=data, segmenter=f"onnx:{model}", progress=False), log=lines.append)
        hidden = sorted(p.name for p in data.iterdir() if p.name.startswith("."))
        assert hidden == sorted([f".masks-{live.pid}.tmp", ".masks-notes.tmp"])
        assert any("removed 1 staging folder" in s for s in lines)
        assert (data / "masks" / "sky" / "f0.png").stat().st_size > len(b"half")
    finally:
        live.kill()
        live.wait()


def test_a_killed_process_not_yet_reaped_counts_as_gone():
    """A run killed under a parent that has not reaped it yet (a zombie) still answers signal 0."""
    import subprocess
    import time

    from nerf2gs_plugin.utils.io import pid_alive

    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    assert pid_alive(p.pid)
    p.kill()
    deadline = time.time() + 10
    while pid_alive(p.pid) and time.time() < deadline:
        time.sleep(0.05)
    assert not pid_alive(p.pid) and p.poll() is not None


def test_cli_bad_segmenter_is_one_error_line(tmp_path, monkeypatch, capsys):
    data = _tiny_dataset(tmp_path / "d")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"garbage")
    for args, named in ((["--segmenter", f"onnx:{bad}"], str(bad)), (["--segmenter", "sam"], "--segmenter")):
        monkeypatch.setattr(sys, "argv", ["ns2gs-data", "masks", str(data), *args])
        with pytest.raises(SystemExit) as e:
            data_cli.entrypoint()
        err = capsys.readouterr().err
        assert int(e.value.code) == 2 and len(err.strip().splitlines()) == 1 and err.startswith("error: ") and named in err


# ---------------------------------------------------------------- masks from renders
def _camera_rays(h: int = 40, w: int = 60, pitch_deg: float = 10.0, cam_h: float = 1.5):
    """A pinhole camera at height cam_h looking along +x, pitched down: unit ray directions [H, W, 3]."""
    f = 0.8 * w
    v, u = torch.meshgrid(torch.arange(h) + 0.5, torch.arange(w) + 0.5, indexing="ij")
    x, y = (u - w / 2) / f, -(v - h / 2) / f  # camera right, up
    p = math.radians(pitch_deg)
    fwd, up, right = torch.tensor([math.cos(p), 0, -math.sin(p)]), torch.tensor([math.sin(p), 0, math.cos(p)]), torch.tensor([0.0, -1, 0])
    d = fwd + x[..., None] * right + y[..., None] * up
    return torch.tensor([0.0, 0, cam_h]), torch.nn.functional.normalize(d, dim=-1)


def test_sky_and_ground_from_constructed_renders():
    up = torch.tensor([0.0, 0, 1])
    origin, dirs = _camera_rays()
    cos = dirs @ up
    t_plane = (0.0 - origin[2]) / cos.clamp(max=-1e-6)
    # the scene: the road (z = 0) up to x = 20 m, a wall at x = 20 m up to 6 m high, sky above
    t_wall = 20.0 / dirs[..., 0]
    wall_z = origin[2] + t_wall * dirs[..., 2]
    road = (cos < 0) & (t_plane * dirs[..., 0] < 20.0)
    wall = ~road & (wall_z < 6.0) & (wall_z > 0)
    depth = torch.where(road, t_plane, torch.where(wall, t_wall, torch.full_like(t_plane, 1e3)))
    acc = (road | wall).float()
    depth = depth * (1 + 0.01 * torch.randn(depth.shape, generator=torch.Generator().manual_seed(0)))  # a NeRF's depth noise
    sky = fr.sky_from_render(acc, dirs, up)
    ground = fr.ground_from_render(origin, dirs, depth, acc, up, 0.0, tol=0.3)
    assert mask_iou(sky, acc == 0) == 1.0
    assert mask_iou(ground, road) > 0.95
    assert not (ground & wall & (wall_z > 0.5)).any()  # only the wall's foot is within the tolerance
    normals = fr.normals_from_points(fr.surface_points(origin, dirs, depth))
    g2 = fr.ground_from_render(origin, dirs, depth, acc, up, 0.0, tol=0.3, normals=normals)
    assert mask_iou(g2, road) > 0.8 and not (g2 & wall & (wall_z > 0.5)).any()
    # a floater below the horizon is not sky even where accumulation is low
    acc2 = acc.clone()
    acc2[-5:, :5] = 0
    assert not fr.sky_from_render(acc2, dirs, up)[-5:, :5].any()


def test_transient_from_residual_finds_the_blob_not_the_noise():
    g = torch.Generator().manual_seed(1)
    h, w = 60, 80
    image = torch.rand(h, w, 3, generator=g) * 0.2 + 0.4
    render = image + 0.015 * torch.randn(h, w, 3, generator=g)  # reconstruction noise
    render[::7, ::5] += 0.5  # isolated bad pixels: not transients
    gt = torch.zeros(h, w, dtype=torch.bool)
    gt[20:35, 30:55] = True
    image[gt] = torch.tensor([0.9, 0.1, 0.1])
    image[26:29, 40:44] = render[26:29, 40:44]  # a window of the car that matches the background
    render = render * 0.9 + 0.05  # the reference's mean appearance differs from this image's
    fitted = fr.fit_colour(render.clamp(0, 1), image)
    res = fr.residual_map(image, fitted)
    thr = fr.robust_threshold(res)
    trans = fr.transient_from_residual(res, thr, min_area=20)
    assert mask_iou(trans, gt) > 0.85
    assert bool(trans[26:29, 40:44].all())  # the hole is filled
    assert not trans[:15].any() and not trans[40:].any()


def test_box_vote_and_clean_regions():
    m = torch.zeros(20, 20, dtype=torch.bool)
    m[5, 5] = True  # a lone pixel
    m[10:16, 10:16] = True
    v = fr.box_vote(m)
    assert not v[5, 5] and bool(v[11:15, 11:15].all())
    c = fr.clean_regions(m, min_area=4, close_px=0)
    assert not c[5, 5] and int(c.sum()) == 36


def test_mask_iou_and_hidden_ground_truth(small_street, tmp_path):
    a = torch.zeros(4, 4, dtype=torch.bool)
    b = a.clone()
    assert mask_iou(a, b) == 1.0
    a[:2] = True
    b[1:3] = True
    assert mask_iou(a, b) == pytest.approx(4 / 12)
    hidden = hide_ground_truth(small_street, tmp_path / "hidden")
    assert not (hidden / "masks").exists() and "mask_path" not in (hidden / "transforms.json").read_text()
    from nerf2gs_plugin.data import parse_dataset

    assert parse_dataset(hidden, "train").mask_filenames == {}
    shutil.copytree(small_street / "masks", hidden / "masks")
    ious = dataset_mask_iou(hidden, small_street)
    assert ious == {"sky": 1.0, "ground": 1.0, "transient": 1.0}


# ---------------------------------------------------------------- auto masks on the tiny scene
def _tiny(tmp_path: Path, name: str, transients: bool = True) -> Path:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tiny_scene import write_tiny_scene

    return write_tiny_scene(tmp_path / name, transients=transients)


def test_auto_masks_on_the_tiny_scene_with_stand_in_renders(tmp_path):
    """A perfect reference's renders (the analytic plane depth, the scene without its car) stand in
    for a trained one: each kind must match the scene's exact masks far better than chance."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.data.images import load_image
    from nerf2gs_plugin.masks.auto import AutoOptions, Renders, masks_from_renders

    real, clean = _tiny(tmp_path, "real"), _tiny(tmp_path, "clean", transients=False)
    outs, clean_outs = parse_dataset(real, "train"), parse_dataset(clean, "train")
    up = outs.up.float()
    height = float((outs.points3D_xyz @ up).median())
    views = []
    for i in range(len(outs)):
        cam = outs.cameras[i : i + 1]
        h, w = int(cam.height[0]), int(cam.width[0])
        rays = cam.generate_rays(0)
        d, o = rays.directions.reshape(h, w, 3), rays.origins[0]
        cos = d @ up
        t = (height - o @ up) / cos.clamp(max=-1e-6)
        hit = (cos < -1e-3) & (t < outs.metres_to_world(60.0))
        views.append({"rgb": load_image(clean_outs.image_filenames[i]), "image": load_image(outs.image_filenames[i]),
                      "depth": torch.where(hit, t, torch.full_like(t, 1e3)), "acc": hit.float(), "dirs": d, "origin": o})
    res = masks_from_renders(Renders({"train": views}, up, height, outs.metres_to_world(1.0), 0.0), AutoOptions(), log=lambda s: None)
    for kind, floor in (("sky", 0.95), ("ground", 0.9), ("transient", 0.6)):
        inter = union = 0
        for i, m in enumerate(res["train"]):
            a, b = __import__("nerf2gs_plugin.masks.evaluate", fromlist=["iou_counts"]).iou_counts(
                getattr(m, kind), load_mask(real / "masks" / kind / f"train_{i:03d}.png"))
            inter, union = inter + a, union + b
        assert inter / union > floor, (kind, inter / union)


def test_make_masks_auto_with_a_very_short_reference(tmp_path):
    """The whole ``--segmenter auto`` path: a 5-step reference trained on the mask-less view, masks
    written for every split in the parsers' layout, the reference reused on a second run."""
    from nerf2gs_plugin.data import parse_dataset

    data = _tiny(tmp_path, "scene")
    shutil.rmtree(data / "masks")
    ref = tmp_path / "ref"
    logs: list[str] = []
    summary = make_masks(MasksConfig(data=data, reference=ref, reference_steps=5, progress=False, render_downscale=1), log=logs.append)
    assert (ref / "config.yml").is_file() and summary["reference"] == str(ref)
    # the closing line gives the StreetNeRF command that goes on from this reference
    assert f"ns2gs-train streetnerf --data {data} --warm-start {ref} " in logs[-1]
    from nerf2gs_plugin.engine.config import read_config_doc

    assert Path(read_config_doc(ref / "config.yml")["config"]["run_dir"]) == ref.absolute()  # the trainer's --run-dir
    outs = parse_dataset(data, "train")
    assert set(outs.mask_filenames) == {"sky", "ground", "transient"}
    assert all(p is not None for p in outs.mask_filenames["sky"])
    assert (data / "masks" / "sky" / "bev_1_000.png").is_file()  # every split
    assert summary["render_seconds"] >= 0 and summary["render_cpu_seconds"] > 0
    # again from every other pixel per side (the default): the masks are still written at the images' size
    again = make_masks(MasksConfig(data=data, reference=ref, overwrite=True, progress=False), log=logs.append)
    assert any("reusing reference" in line for line in logs)
    assert (summary["render_downscale"], again["render_downscale"]) == (1, 2)
    assert again["render_cpu_seconds"] < summary["render_cpu_seconds"]
    img = load_mask(outs.image_filenames[0].parent.parent / "masks" / "sky" / f"{outs.image_filenames[0].stem}.png")
    assert tuple(img.shape[:2]) == (int(outs.cameras.height[0]), int(outs.cameras.width[0]))
    with pytest.raises(ConfigError, match="render-downscale"):
        make_masks(MasksConfig(data=data, reference=ref, overwrite=True, render_downscale=0.5, progress=False), log=logs.append)
    from nerf2gs_plugin.masks.motion import MotionOptions

    for bad, flag in ((MotionOptions(persist=1.5), "motion.persist"), (MotionOptions(persist_ring=0.0), "motion.persist-ring"),
                      (MotionOptions(second_pass_steps=-1), "motion.second-pass-steps")):
        with pytest.raises(ConfigError, match=flag):
            make_masks(MasksConfig(data=data, reference=ref, overwrite=True, motion=bad, progress=False), log=logs.append)


@pytest.mark.parametrize("d", [2, 3])
def test_decimated_camera_has_exactly_the_chosen_pixels_rays(d):
    """--render-downscale renders every d-th pixel of the full-size camera (its footprint kept); the
    mask maths see them as a camera of their own, whose rays must be those very pixels' rays."""
    from nerf2gs_plugin.cameras import Cameras
    from nerf2gs_plugin.masking.auto_masks import decimated

    c2w = torch.tensor([[[0.96, 0.0, 0.28, 1.0], [0.0, 1.0, 0.0, 2.0], [-0.28, 0.0, 0.96, 3.0]]])
    cam = Cameras(c2w, torch.tensor([70.0]), torch.tensor([66.0]), torch.tensor([31.3]), torch.tensor([23.9]),
                  torch.tensor([61]), torch.tensor([47]))
    small, pixels = decimated(cam, d)
    assert (int(small.height[0]), int(small.width[0])) == (47 // d, 61 // d) and int(pixels.sum()) == (47 // d) * (61 // d)
    full = cam.generate_rays(0)
    torch.testing.assert_close(small.generate_rays(0).directions, full.directions[pixels.reshape(-1)], atol=1e-6, rtol=0)


def _street_scene(wall_h: float = 6.0, pitch_deg: float = 10.0):
    """The constructed street of the test above: road up to x = 20 m, a wall there ``wall_h`` high, sky."""
    up = torch.tensor([0.0, 0, 1])
    origin, dirs = _camera_rays(pitch_deg=pitch_deg)
    cos = dirs @ up
    t_plane = (0.0 - origin[2]) / cos.clamp(max=-1e-6)
    t_wall = 20.0 / dirs[..., 0]
    wall_z = origin[2] + t_wall * dirs[..., 2]
    road = (cos < 0) & (t_plane * dirs[..., 0] < 20.0)
    wall = ~road & (wall_z < wall_h) & (wall_z > 0)
    depth = torch.where(road, t_plane, torch.where(wall, t_wall, torch.full_like(t_plane, 1e3)))
    return up, origin, dirs, road, wall, depth


def test_sky_rules_drop_speckle_and_see_through_patches():
    """A short reference leaves low-accumulation speckle and see-through patches (far depth) inside
    facades: the box vote drops the speckle, and only regions reaching the image's top are sky."""
    up, origin, dirs, road, wall, depth = _street_scene(wall_h=4.0, pitch_deg=-5.0)
    sky_true = ~road & ~wall
    assert bool(sky_true[0].any())
    acc = (road | wall).float()
    hole = torch.zeros_like(wall)
    rows = wall.any(1).nonzero()[:, 0]
    hole[int(rows[len(rows) // 2]) - 2: int(rows[len(rows) // 2]) + 2, 10:16] = True  # a see-through patch in the wall
    hole &= wall
    speckle = torch.zeros_like(wall)
    speckle[::6, 3:-3:7] = True  # away from the border (the vote replicates it)
    speckle &= wall & ~hole
    d2 = torch.where(hole, torch.full_like(depth, 1e3), depth)
    a2 = torch.where(hole | speckle, torch.zeros_like(acc), acc)
    plain = fr.sky_from_render(a2, dirs, up, depth=d2, far=100.0)
    assert (plain & (hole | speckle)).any()  # the old rule takes both
    sky = fr.sky_from_render(a2, dirs, up, depth=d2, far=100.0, vote=3, from_top=True)
    assert not (sky & (hole | speckle)).any()
    assert mask_iou(sky, sky_true) > 0.95


def test_sky_holes_are_filled_but_not_what_reaches_a_side_or_the_bottom():
    """A cloud the reference gave density (a hole in the sky, here touching the top row too) is filled;
    a facade reaching the image's side and a tree standing on the bottom row stay out of the sky."""
    sky = torch.zeros(20, 30, dtype=torch.bool)
    sky[:8, 5:25] = True
    cloud = torch.zeros_like(sky)
    cloud[0:3, 10:14] = True  # touches the top row: the sky goes on above the frame
    inner = torch.zeros_like(sky)
    inner[4:6, 16:19] = True
    sky &= ~(cloud | inner)
    filled = fr.enclosed_holes(sky)
    assert filled[cloud].all() and filled[inner].all()
    assert not filled[:, :5].any() and not filled[:, 25:].any() and not filled[8:].any()  # facades, street
    tree = sky.clone()
    tree[3:, 20:22] = False  # a trunk from the bottom row up into the sky
    assert not fr.enclosed_holes(tree)[3:8, 20:22].any()
    up, origin, dirs, road, wall, depth = _street_scene(wall_h=4.0, pitch_deg=-5.0)
    acc = (road | wall).float()
    plain = fr.sky_from_render(acc, dirs, up, from_top=True)
    assert torch.equal(fr.sky_from_render(acc, dirs, up, from_top=True, fill_holes=True), fr.enclosed_holes(plain))


def test_ground_median_ignores_floater_speckle():
    """Floaters in front of the road (a tenth of the pixels at half the distance) flip single pixels;
    the height median over a window keeps the road whole and still stops at the wall."""
    up, origin, dirs, road, wall, depth = _street_scene()
    acc = (road | wall).float()
    g = torch.Generator().manual_seed(0)
    floaters = (torch.rand(depth.shape, generator=g) < 0.1) & road
    d2 = torch.where(floaters, depth * 0.5, depth)
    wall_z = origin[2] + depth * dirs[..., 2]
    plain = fr.ground_from_render(origin, dirs, d2, acc, up, 0.0, tol=0.3)
    smooth = fr.ground_from_render(origin, dirs, d2, acc, up, 0.0, tol=0.3, smooth_px=5)
    assert mask_iou(plain, road) < 0.9
    assert mask_iou(smooth, road) > 0.95
    assert not (smooth & wall & (wall_z > 1.0)).any()


def test_ground_where_the_reference_left_the_road_see_through():
    """A short reference leaves the grey road near the camera empty (accumulation 0): with
    ``empty_is_ground`` those downward rays are ground; the sky above the horizon, also empty, is not."""
    up, origin, dirs, road, wall, depth = _street_scene()
    acc = (road | wall).float()
    g = torch.Generator().manual_seed(1)
    holes = (torch.rand(depth.shape, generator=g) < 0.5) & road & (torch.arange(depth.shape[0])[:, None] > depth.shape[0] * 0.7)
    blobs = fr.box_vote(holes, 5, 0.3) & road  # see-through patches, wider than the median window
    acc2 = torch.where(blobs, torch.zeros_like(acc), acc)
    d2 = torch.where(blobs, torch.full_like(depth, 0.5), depth)  # what an empty ray's depth says: nothing
    off = fr.ground_from_render(origin, dirs, d2, acc2, up, 0.0, tol=0.3, smooth_px=3)
    on = fr.ground_from_render(origin, dirs, d2, acc2, up, 0.0, tol=0.3, smooth_px=3, empty_is_ground=True)
    assert blobs.sum() > 50 and not (off & blobs).all()
    assert mask_iou(on, road) > 0.95 > mask_iou(off, road)
    sky = acc == 0
    assert not (on & sky).any()  # empty, but above the horizon
    assert not (on & wall & ((origin[2] + depth * dirs[..., 2]) > 1.0)).any()


def test_transient_opening_drops_thin_strokes_keeps_blobs():
    res = torch.zeros(60, 80)
    res[:, 10:12] = 1.0  # a pole the reference blurs: a 2-px stroke of high residual
    res[20:35, 30:55] = 1.0  # a car
    t = fr.transient_from_residual(res, 0.5, min_area=20, open_px=2)
    assert not t[:, 8:14].any() and bool(t[22:33, 32:53].all())
    assert fr.transient_from_residual(res, 0.5, min_area=20)[:, 10:12].all()  # without the opening the pole stays


@pytest.mark.parametrize("size", [0, 3, 4, 9])
def test_median_compare_is_the_sorted_median_compared(size):
    """The ground mask's window medians are counted, not sorted: the same answer as sorting each
    window, ties at the threshold, the border and a NaN (its windows are False) included."""
    g = torch.Generator().manual_seed(size)
    x = torch.round(torch.rand(37, 53, generator=g) * 8) / 8
    x[4, 50] = float("nan")
    for t in (0.5, 0.125):
        med = fr.median_filter(x, size)
        assert torch.equal(fr.median_compare(x, t, size), med < t)
        assert torch.equal(fr.median_compare(x, t, size, below=False), med >= t)


@pytest.mark.parametrize("sequence, motion_on, splits, expected", [
    (True, True, ("test",), ["train", "test"]),  # held-out frames alone are seconds apart: train as neighbours
    (True, True, ("train",), ["train"]),  # the training masks never see the held-out frames
    (False, True, ("test",), ["test"]),  # photos: the motion route does not run
    (True, False, ("test",), ["test"]),
])
def test_masks_of_held_out_frames_take_the_training_frames_as_neighbours(tmp_path, monkeypatch, sequence, motion_on, splits, expected):
    """``--splits test`` on a video: the auto route computes the training frames too (the motion route's
    neighbours), and writes the held-out frames' masks only."""
    from nerf2gs_plugin.masking import auto_masks, mask_reference
    from nerf2gs_plugin.masks.motion import MotionOptions

    data = _tiny(tmp_path, "scene")
    shutil.rmtree(data / "masks")
    meta = json.loads((data / "transforms.json").read_text())
    meta["eval_splits"] = {"test": [meta["frames"][-1]["file_path"]]}
    if sequence:
        meta["process"] = {"source": "video"}
    (data / "transforms.json").write_text(json.dumps(meta))
    seen: list = []

    class Stop(Exception):
        pass

    def fake_auto(view, reference, names, *a, **k):
        seen.extend(names)
        raise Stop

    monkeypatch.setattr(mask_reference, "ensure_reference", lambda *a, **k: tmp_path / "ref")
    monkeypatch.setattr(auto_masks, "auto_masks", fake_auto)
    logs: list[str] = []
    with pytest.raises(Stop):
        make_masks(MasksConfig(data=data, reference=tmp_path / "ref", splits=splits, progress=False,
                               motion=MotionOptions(enabled=motion_on)), log=logs.append)
    assert seen == expected
    assert any("neighbours" in line for line in logs) == (expected != list(splits))
    assert not (data / "masks" / "transient").is_dir()  # nothing written before all of them are made
