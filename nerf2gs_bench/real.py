"""``ns2gs-bench real``: the synthetic street as a real capture would arrive, through the whole path.

The street's forward drive (one direction: the two passes of the training set share no view, so
only one would register) is written as a video; its poses and masks are thrown away. Then:
``process video`` (pycolmap SfM, ground-plane metric scale from the camera height) -> ``masks``
(``--segmenter auto``) -> StreetNeRF -> Splatfacto with and without NeRF views. The same pipeline
runs on the same frames with the true poses, scale and masks beside it, twice: with the capture's own
sparse points carried into the true frame (so the columns differ only in poses, scale and masks: the
``gain_ratio``), and with the generator's sparse points (``gain_ratio_generator_points``).

Eval cameras live in the true frame. An estimated dataset's frame is the SfM's, related to the
true one by the Sim(3) that aligns its training cameras onto the true ones (``pose_eval``: the
capture figures ATE, rotation and scale error are taken after it). Each true eval camera is mapped
into the estimated frame by the training cameras around it (``pose_eval.LocalAlignment``: one
Sim(3) would leave it degrees off where the models expect it, which alone costs PSNR) and written
into the estimated ``transforms.json`` as an eval split; the parser then normalises it with the
estimated dataset's own normalisation, exactly as the training cameras. The ground-truth dataset
goes through the same mapping with its own (identity) alignment, so both columns are produced by
one code path, and a mapping that is the identity reproduces the original eval cameras
(``tests/bench/test_bench_real.py``).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Literal, Optional

import numpy as np

from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.eval.pose_eval import LocalAlignment, Sim3, capture_report
from nerf2gs_plugin.utils.io import atomic_write_text

SPLITS = ("street", "bev_1", "bev_2")
NERF_VIEWS = "splatfacto + NeRF views"
GT_CAPTURE_POINTS = "ground_truth_capture_points"
"""The column with the true poses, scale and masks and the estimated capture's sparse points (carried
into the true frame): what ``gain_ratio`` compares against. ``ground_truth`` has the generator's points
(``gain_ratio_generator_points``): 4,000 samples of every surface, the road included, which no SfM finds
- on the bench's drive they alone lift StreetNeRF from above."""


@dataclass
class RealBenchOptions:
    """Step counts and capture settings of ``ns2gs-bench real`` (short: CPU scale)."""

    frames: int = 30
    """Frames of the forward drive written to the video (the street's first pass has 30)."""
    video_scale: int = 4
    """The video's frames are the street rendered at this multiple of its 200x112 (1, 2, 4 or 8: a dashcam
    hands over large frames); the SfM runs on them and the estimated column trains on ``process``'s
    ``images_<video_scale>`` copies, the ground-truth column's size. SIFT places a keypoint to about a
    pixel, so larger frames give the eval cameras less local rotation noise."""
    reference_steps: int = 1000
    """Steps of the masks' first reference (StreetNeRF without masks)."""
    streetnerf_steps: int = 400
    splatfacto_steps: int = 800
    """The quick scale's Splatfacto steps."""
    num_street: int = 4
    """Street eval views of the generated street (fewer than the default street: CPU time)."""
    num_bev: int = 6
    """Bird's-eye eval views per height."""
    camera_optimizer: Literal["off", "SO3xR3"] = "off"
    """StreetNeRF's pose refinement on the ESTIMATED capture (--pipeline.model.camera-optimizer.mode);
    the ground-truth side keeps the true poses unrefined."""
    seed: Optional[int] = None
    """The training seed of every run, both columns (None: each method's own); the capture (SfM,
    masks) is the same: a second seed measures how much of a gain ratio is the training's noise."""
    street_seed: int = 0
    """The synthetic street's seed (its layout, colours, cars and exposures; 0: the embedded street): another
    street is another capture, made under ``RUNS/real-street<seed>``."""


# ----------------------------------------------------------------------------- pure parts
def read_frames(data: Path) -> dict[str, list]:
    """Every split's raw frames (original paths, OpenGL c2w in the file's frame, intrinsics, masks);
    without split keys every frame is "train" (no held-out frames: the drive is aligned whole)."""
    import dataclasses

    from nerf2gs_plugin.data import dataparser_config

    cfg = dataclasses.replace(dataparser_config(Path(data)), holdout_every=0)
    return cfg.raw_frames()


def frame_index(image: Path) -> int:
    """``frame_000012.jpg`` -> 12: the video frame a processed image came from."""
    return int(Path(image).stem.rsplit("_", 1)[-1])


def mapped_eval_frames(true_groups: dict[str, list], true_to_est: Sim3 | LocalAlignment, splits=SPLITS) -> dict[str, list[dict]]:
    """The true eval cameras of ``splits`` as nerfstudio frame dicts in the estimated frame:
    poses mapped by ``true_to_est`` (its ``apply_poses``), the true intrinsics per frame (PINHOLE),
    absolute image paths."""
    out: dict[str, list[dict]] = {}
    for split in splits:
        frames = true_groups.get(split, [])
        if not frames:
            continue
        c2w = true_to_est.apply_poses(np.stack([f.c2w.double().numpy() for f in frames]))
        out[split] = []
        for f, m in zip(frames, c2w):
            i = f.intr
            out[split].append({"file_path": str(Path(f.image).resolve()), "camera_model": "PINHOLE",
                               "fl_x": i.fx, "fl_y": i.fy, "cx": i.cx, "cy": i.cy, "w": i.width, "h": i.height,
                               "transform_matrix": [[float(v) for v in row] for row in m] + [[0.0, 0.0, 0.0, 1.0]]})
    return out


def link_eval_masks(data: Path, true_groups: dict[str, list], splits=SPLITS) -> None:
    """The true eval views' masks as ``DATA/masks/<kind>/<stem>.png`` symlinks (road PSNR needs the
    ground masks; the parser finds a frame's masks there by the image's stem)."""
    for split in splits:
        for f in true_groups.get(split, []):
            for kind, src in f.masks.items():
                if src is None:
                    continue
                dst = Path(data) / "masks" / kind / f"{Path(f.image).stem}{Path(src).suffix}"
                if dst.exists() or dst.is_symlink():
                    continue
                dst.parent.mkdir(parents=True, exist_ok=True)
                dst.symlink_to(Path(src).resolve())


def street_camera(street: Path):
    """The synthetic street's config as generated (its camera's FOV and height: the ``--fov-deg`` and
    ``--camera-height`` a dashcam owner would pass)."""
    from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig

    stats = Path(street) / "synth_stats.json"
    cfg = json.loads(stats.read_text()).get("config", {}) if stats.is_file() else {}
    return SynthStreetConfig(**{k: cfg[k] for k in ("fov_deg", "cam_height") if k in cfg})


def write_eval_splits(data: Path, eval_frames: dict[str, list[dict]]) -> None:
    """``eval_splits`` of ``DATA/transforms.json`` replaced by ``eval_frames`` (atomic)."""
    meta_file = Path(data) / "transforms.json"
    meta = json.loads(meta_file.read_text())
    meta["eval_splits"] = eval_frames
    atomic_write_text(meta_file, json.dumps(meta, indent=1))


def c2w_array(frames: list) -> np.ndarray:
    return np.stack([f.c2w.double().numpy() for f in frames])


def gain_ratio(est: dict, gt: dict, split: str) -> Optional[float]:
    """(bird's-eye PSNR gain from NeRF views, everything estimated) / (the gain with ground truth)."""
    def gain(res: dict) -> Optional[float]:
        a, b = res.get(NERF_VIEWS, {}), res.get("splatfacto", {})
        if a.get("failed") or b.get("failed") or not a or not b:
            return None
        return a["results"][split]["psnr"] - b["results"][split]["psnr"]

    ge, gg = gain(est), gain(gt)
    return None if ge is None or gg is None or gg == 0 else ge / gg


# ----------------------------------------------------------------------------- stages
def write_video(path: Path, images: list[Path], fps: float = 10.0, transform=None) -> Path:
    """The frames (each through ``transform``, an image -> image function, when given) as an MJPG video
    (what a dashcam would hand over)."""
    import cv2

    transform = transform or (lambda img: img)
    first = transform(cv2.imread(str(images[0])))
    h, w = first.shape[:2]
    tmp = Path(path).with_name(Path(path).stem + ".tmp" + Path(path).suffix)
    wr = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    for p in images:
        wr.write(transform(cv2.imread(str(p))))
    wr.release()
    os.replace(tmp, path)
    return Path(path)


def make_street(root: Path, opts: RealBenchOptions, scale: int = 1) -> Path:
    """The synthetic street (made once; remade when its generator changed), at ``scale`` times its
    image size (the same cameras, cars and exposures: everything follows from the seed)."""
    from nerf2gs_plugin.data.synthetic_street import GENERATOR_VERSION, SynthStreetConfig, generate_street, read_generator_version

    path = Path(root) / ("street" if scale == 1 else f"street_x{scale}")
    base = SynthStreetConfig()
    cfg = SynthStreetConfig(out=path, seed=opts.street_seed, num_street=opts.num_street, num_bev=opts.num_bev, num_val_street=0, num_val_bev=0,
                            width=base.width * scale, height=base.height * scale, progress=False, overwrite=True)
    if not (path / "transforms.json").is_file() or read_generator_version(path) != GENERATOR_VERSION:
        generate_street(cfg)
    return path


def ground_truth_dataset(street: Path, out: Path, n: int, points: Optional[tuple[np.ndarray, np.ndarray]] = None) -> Path:
    """``out``: the street's first ``n`` training frames (the forward drive) with their true poses,
    scale and masks; every other item of the street linked. ``points`` (``[N, 3]`` xyz in the true
    frame, ``[N, 3]`` uint8 rgb) replace the street's sparse points (which the generator samples on every
    surface, the road included: no capture has those)."""
    from nerf2gs_plugin.data.ply import write_ply_points

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((Path(street) / "transforms.json").read_text())
    if points is not None:
        meta.setdefault("ply_file_path", "sparse_pc.ply")
    own = {"transforms.json"} | ({meta["ply_file_path"]} if points is not None else set())
    for item in Path(street).iterdir():
        link = out / item.name
        if item.name in own or link.exists() or link.is_symlink():
            continue
        link.symlink_to(item.resolve())
    if points is not None:
        write_ply_points(out / meta["ply_file_path"], *points)  # atomic
    meta["frames"] = meta["frames"][:n]
    meta.pop("eval_splits", None)
    atomic_write_text(out / "transforms.json", json.dumps(meta, indent=1))
    return out


def capture_points(est: Path, est_to_true: Sim3) -> tuple[np.ndarray, np.ndarray]:
    """The estimated capture's sparse points carried into the true frame (xyz float32, rgb uint8)."""
    from nerf2gs_plugin.data.ply import read_ply_points

    meta = json.loads((Path(est) / "transforms.json").read_text())
    xyz, rgb = read_ply_points(Path(est) / meta.get("ply_file_path", "sparse_pc.ply"))
    return est_to_true.apply(xyz.astype(np.float64)).astype(np.float32), rgb


def training_view(capture: Path, out: Path, factor: int) -> Path:
    """``out/transforms.json``: the processed ``capture`` at 1/``factor`` of its size - its
    ``images_<factor>`` copies (absolute paths) with the intrinsics scaled by the parser's rule - so the
    estimated column trains, makes its masks and is scored at the size of the ground-truth one."""
    from nerf2gs_plugin.data.undistort import Intrinsics, output_intrinsics

    meta = json.loads((Path(capture) / "transforms.json").read_text())
    for frame in [meta, *meta["frames"]]:
        if "w" in frame:  # process writes PINHOLE: no distortion to undo, only the downscale
            i = output_intrinsics(Intrinsics(frame["fl_x"], frame["fl_y"], frame["cx"], frame["cy"], int(frame["w"]), int(frame["h"])), factor)
            frame.update(w=i.width, h=i.height, fl_x=i.fx, fl_y=i.fy, cx=i.cx, cy=i.cy)
    for frame in meta["frames"]:
        frame["file_path"] = str((Path(capture) / f"images_{factor}" / Path(frame["file_path"]).name).resolve())
    if "ply_file_path" in meta:
        meta["ply_file_path"] = str((Path(capture) / meta["ply_file_path"]).resolve())
    Path(out).mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(out) / "transforms.json", json.dumps(meta, indent=1))
    return Path(out)


def reference_dir(root: Path, est: Path, steps: int, options: str = "") -> Path:
    """The masks' first reference, keyed by the capture it trains on (its mask-less
    ``transforms.json``: poses, intrinsics, scale, up) and by ``options`` (anything else it is
    trained with, e.g. a downscale): a re-processed capture (other intrinsics or up, same images)
    must not reuse a reference trained on the old one."""
    import hashlib

    from nerf2gs_plugin.masking.mask_reference import REFERENCE_OVERRIDES
    from nerf2gs_plugin.masks.maskless import strip_frame_keys
    from nerf2gs_bench.code_version import model_code_hash

    meta = strip_frame_keys(json.loads((Path(est) / "transforms.json").read_text()))
    for k in ("eval_splits", "process"):  # the eval cameras and the stage times are no part of the capture
        meta.pop(k, None)
    # and by the model code that trains it: a changed default must not reuse a reference made before it
    recipe = json.dumps(REFERENCE_OVERRIDES, sort_keys=True)  # what it changes of StreetNeRF (masks/ keys no model)
    key = hashlib.sha1((json.dumps(meta, sort_keys=True) + options + model_code_hash() + recipe).encode()).hexdigest()[:10]
    return Path(root) / f"masks-reference-{steps}-{key}"


def attach_eval(data: Path, true_groups: dict[str, list], true_train: np.ndarray, est_train: np.ndarray) -> LocalAlignment:
    """Write the true eval cameras, mapped into the frame of ``est_train`` (the dataset's training
    cameras) by the training cameras around each, as the dataset's eval splits. Returns the mapping
    used (its ``global_sim``: the one estimated -> true Sim(3))."""
    local = LocalAlignment.fit(est_train, true_train)
    link_eval_masks(data, true_groups)
    write_eval_splits(data, mapped_eval_frames(true_groups, local))
    return local


def process_capture(video: Path, out: Path, n: int, fov_deg: float, camera_height: float, num_threads: int = 1):
    """``ns2gs-data process video`` with every frame kept (so frame names index the drive). ``num_threads``: COLMAP's
    (1, for the accuracy benches: repeatable mapping; a timing of the product passes its default, all cores)."""
    from nerf2gs_plugin.data.process.frames import extract_video_frames
    from nerf2gs_plugin.data.process.pipeline import ProcessOptions, run_process
    from nerf2gs_plugin.data.process.sfm import SfmOptions

    # the dashcam's FOV is known: keep it (no focal refinement); one thread makes the mapping repeatable
    # (COLMAP's multi-threaded mapper gave a wrong geometry on one of two runs of 30 frames)
    opts = ProcessOptions(out=Path(out), camera_height=camera_height, fov_deg=fov_deg, progress=False,
                          sfm=SfmOptions(refine_intrinsics=False, num_threads=num_threads))
    return run_process(lambda d, progress: extract_video_frames(video, d, None, n, 0.0, opts.max_size, progress=progress),
                       opts, is_video=True)


def real_plan(opts: RealBenchOptions, camera_optimizer: str = "off") -> list:
    """The bench's runs: StreetNeRF (with ``camera_optimizer`` refining its poses unless "off"), then
    Splatfacto without and with its NeRF views."""
    from nerf2gs_bench.paper import _merge, step_overrides
    from nerf2gs_bench.runs import RunSpec

    def ov(method: str, steps: int) -> dict:
        seed = {} if opts.seed is None else {"seed": opts.seed}  # absent by default: the run keys stay the plain bench's
        return {**step_overrides(method, steps), "steps_per_eval_image": 0, **seed}

    street = ov("streetnerf", opts.streetnerf_steps)
    if camera_optimizer != "off":  # absent when off: the run keys stay those of the plain bench
        street = _merge(street, {"pipeline": {"model": {"camera_optimizer": {"mode": camera_optimizer}}}})
    return [RunSpec("StreetNeRF", "streetnerf", street),
            RunSpec("splatfacto", "splatfacto", ov("splatfacto", opts.splatfacto_steps)),
            RunSpec(NERF_VIEWS, "splatfacto", ov("splatfacto", opts.splatfacto_steps), augment_from="StreetNeRF")]


def run_plan_for(data: Path, runs_root: Path, opts: RealBenchOptions, name: str, rerun: bool,
                 camera_optimizer: str = "off") -> dict[str, dict]:
    from nerf2gs_bench.paper import run_plan

    return run_plan(real_plan(opts, camera_optimizer), data, runs_root, name=name, rerun=rerun)


def run_real_bench(runs_root: Path, out_dir: Path, opts: RealBenchOptions = RealBenchOptions(), rerun: bool = False,
                   log: Callable[[str], None] = print, train: bool = True, street: Optional[Path] = None) -> dict:
    """The whole bench; writes ``real.{json,md,png}`` into ``out_dir`` and returns the JSON document.
    ``train=False`` stops after the capture figures, ``street`` replaces the generated street (the
    test's plumbing run on a smaller one)."""
    from nerf2gs_plugin.masking.make_masks import MasksConfig, make_masks
    from nerf2gs_plugin.data.process.export import DOWNSCALES
    from nerf2gs_plugin.masks.evaluate import paired_mask_iou

    if opts.video_scale != 1 and opts.video_scale not in DOWNSCALES:
        raise ConfigError(f"--video-scale must be 1 or one of process's downscales {DOWNSCALES}, got {opts.video_scale}")
    root = Path(runs_root) / ("real" if opts.street_seed == 0 else f"real-street{opts.street_seed}")
    root.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    stages: dict[str, float] = {}

    def timed(name: str, fn):
        t0 = time.perf_counter()
        out = fn()
        stages[name] = round(time.perf_counter() - t0, 1)
        return out

    street = street or timed("synthetic street", lambda: make_street(root, opts))
    true_meta = json.loads((street / "transforms.json").read_text())
    street_cfg = street_camera(street)
    gt = ground_truth_dataset(street, root / "gt", opts.frames)
    true_groups = read_frames(gt)
    true_train = c2w_array(true_groups["train"])
    gt_local = attach_eval(gt, read_frames(street), true_train, true_train)  # identity: the same mapping code path

    scale = opts.video_scale
    if scale == 1:
        video_frames = true_groups["train"]
    else:  # the same drive at the dashcam's size: the same cameras, or the columns would not compare
        video_frames = read_frames(timed("video street", lambda: make_street(root, opts, scale)))["train"][:opts.frames]
        if not np.allclose(c2w_array(video_frames), true_train, atol=1e-9):
            raise RuntimeError(f"the street at {scale}x its size has other training cameras than the ground-truth one")
    video = timed("video", lambda: write_video(root / ("drive.avi" if scale == 1 else f"drive_x{scale}.avi"),
                                               [f.image for f in video_frames]))
    capture_dir = root / ("estimated" if scale == 1 else f"capture_x{scale}")
    report = timed("process", lambda: process_capture(video, capture_dir, opts.frames, street_cfg.fov_deg, street_cfg.cam_height))
    est = capture_dir if scale == 1 else training_view(capture_dir, root / f"estimated_x{scale}", scale)
    est_groups = read_frames(est)
    idx = [frame_index(f.image) for f in est_groups["train"]]
    est_train = c2w_array(est_groups["train"])
    est_meta = json.loads((est / "transforms.json").read_text())
    capture = capture_report(est_train, true_train[idx], float(est_meta["metres_per_unit"]), np.asarray(est_meta.get("up", [0, 0, 1])),
                             np.asarray(true_meta.get("up", [0, 0, 1])), report.registered, opts.frames)
    local = attach_eval(est, read_frames(street), true_train[idx], est_train)
    reference = reference_dir(root, est, opts.reference_steps)
    # the masks are always derived again (a minute of renders): the rules change more often than the capture
    summary = timed("masks", lambda: make_masks(MasksConfig(data=est, reference=reference, reference_steps=opts.reference_steps,
                                                            splits=("train",), overwrite=True, progress=False), log=log))
    def pinhole(intr) -> tuple[float, float, float, float]:
        return (intr.fx, intr.fy, intr.cx, intr.cy)

    iou = {k: paired_mask_iou([(est / "masks" / k / f"{Path(f.image).stem}.png", true_groups["train"][i].masks[k],
                                (pinhole(f.intr), pinhole(true_groups["train"][i].intr)))
                               for f, i in zip(est_groups["train"], idx) if true_groups["train"][i].masks.get(k)]) for k in MASK_KINDS}
    doc: dict = {
        "options": vars(opts).copy(),
        "registered_fraction": capture["registered_fraction"],
        "ate_percent": capture["ate_percent"],
        "scale_error_percent": capture["scale_error_percent"],
        "rotation_error_deg": capture["rotation_error_deg"],
        "up_error_deg": capture["up_error_deg"],
        "eval_mapping_rotation_deg": local.leave_one_out_rotation_deg(),
        "scale_check_ratio": est_meta.get("process", {}).get("capture_check", {}).get("ratio"),
        "path_jump_ratio": (est_meta.get("process", {}).get("capture_check", {}).get("path_jump") or {}).get("ratio"),
        "mask_iou": iou,
        "alignment": {"scale": local.global_sim.s, "gt_identity_scale": gt_local.global_sim.s},
        "process": {"registered": report.registered, "frames": report.frames, "points": report.points,
                    "metres_per_unit": report.metres_per_unit, "stage_seconds": report.stage_seconds},
        "masks": {"reference_seconds": summary.get("reference_seconds"), "mask_seconds": summary.get("mask_seconds"),
                  "coverage": summary.get("coverage")},
    }
    # the true poses, scale and masks with the capture's own sparse points: the columns differ in nothing else
    gt_sfm = ground_truth_dataset(street, root / "gt_capture_points", opts.frames, capture_points(est, local.global_sim))
    attach_eval(gt_sfm, read_frames(street), true_train, true_train)
    if train:
        res_gt = timed("ground truth: train + eval", lambda: run_plan_for(gt, Path(runs_root), opts, "real_gt", rerun))
        res_sfm = timed("ground truth, capture's points: train + eval",
                        lambda: run_plan_for(gt_sfm, Path(runs_root), opts, "real_gt_capture_points", rerun))
        res_est = timed("estimated: train + eval", lambda: run_plan_for(est, Path(runs_root), opts, "real_est", rerun,
                                                                        opts.camera_optimizer))
        doc["results"] = {"estimated": res_est, GT_CAPTURE_POINTS: res_sfm, "ground_truth": res_gt}
        doc["gain_ratio"] = {s: gain_ratio(res_est, res_sfm, s) for s in ("bev_1", "bev_2")}
        doc["gain_ratio_generator_points"] = {s: gain_ratio(res_est, res_gt, s) for s in ("bev_1", "bev_2")}
        doc["train_seconds"] = {f"{name}: {label}": r.get("train_seconds") for name, res in
                                (("estimated", res_est), ("ground truth, capture's points", res_sfm), ("ground truth", res_gt))
                                for label, r in res.items()}
    doc["stage_seconds"] = stages
    doc["wall_seconds"] = round(time.perf_counter() - t_all, 1)
    write_results(out_dir, doc)
    return doc


# ----------------------------------------------------------------------------- output
def _f(v: Optional[float], fmt: str = "{:.2f}") -> str:
    return "n/a" if v is None else fmt.format(v)


def results_md(doc: dict) -> str:
    from nerf2gs_plugin.data.process.scale_check import MAX_HEIGHT_JUMP, MAX_STEP_JUMP
    from nerf2gs_bench.paper import markdown_table, target_groups
    from nerf2gs_bench.machine import machine_line

    o = doc["options"]
    lines = [
        "# Real-capture path on the synthetic street (`ns2gs-bench real`)", "",
        f"Machine: {machine_line(doc.get('machine'))}", "",
        f"The street's (seed {o.get('street_seed', 0)}) forward drive ({o['frames']} frames, rendered at {200 * o.get('video_scale', 1)}x{112 * o.get('video_scale', 1)}) "
        "as an MJPG video, poses and masks thrown away: "
        "process video (`--fov-deg 80 --camera-height 3 --no-refine-intrinsics --num-threads 1`) -> "
        + (f"the capture's `images_{o['video_scale']}` (200x112, the ground-truth column's size: the masks and every model are made from them) -> "
           if o.get("video_scale", 1) != 1 else "")
        + f"masks (auto, reference {o['reference_steps']} steps) -> StreetNeRF ({o['streetnerf_steps']} steps) -> Splatfacto ({o['splatfacto_steps']} steps) with and without NeRF views; "
        + (f"StreetNeRF on the estimated poses refines them (camera optimizer {o['camera_optimizer']}); "
           if o.get("camera_optimizer", "off") != "off" else "")
        + "beside it the same frames with their true poses, scale and masks, once with the capture's own sparse points "
        "carried into the true frame (the columns differ in nothing else: `gain_ratio`) and once with the generator's "
        "(4,000 samples of every surface, the road included: `gain_ratio_generator_points`). The capture figures are taken after the "
        "Sim(3) aligning the estimated training cameras to the true ones; each eval camera is mapped into the estimated "
        "frame by the training cameras around it (`pose_eval.LocalAlignment`; `eval_mapping_rotation_deg`: what a held-out "
        "training camera mapped that way misses its estimated pose by).", "",
        "| capture figure | measured | target |", "|---|---|---|",
        f"| registered_fraction | {_f(doc['registered_fraction'], '{:.3f}')} | >= 0.95 |",
        f"| ate_percent | {_f(doc['ate_percent'], '{:.3f}')} | <= 1 |",
        f"| scale_error_percent | {_f(doc['scale_error_percent'], '{:+.2f}')} | within 5 |",
        f"| rotation_error_deg | {_f(doc['rotation_error_deg'], '{:.3f}')} | |",
        f"| up_error_deg | {_f(doc['up_error_deg'], '{:.3f}')} | |",
        f"| eval_mapping_rotation_deg | {_f(doc.get('eval_mapping_rotation_deg'), '{:.3f}')} | |",
    ]
    if doc.get("scale_check_ratio") is not None:  # process's scale check: the largest jump of the camera's height above its road
        lines.append(f"| scale_check_ratio | {_f(doc['scale_check_ratio'], '{:.2f}')} | <= {MAX_HEIGHT_JUMP:g} |")
    if doc.get("path_jump_ratio") is not None:  # and the largest step of the ordered path against the steps around it
        lines.append(f"| path_jump_ratio | {_f(doc['path_jump_ratio'], '{:.2f}')} | <= {MAX_STEP_JUMP:g} |")  # a video: the ordered bound
    for k in MASK_KINDS:
        lines.append(f"| mask_iou.{k} | {_f(doc['mask_iou'].get(k), '{:.3f}')} | {'>= 0.8' if k != 'transient' else ''} |")
    for s in ("bev_1", "bev_2"):
        if "gain_ratio" in doc:
            lines.append(f"| gain_ratio.{s} | {_f(doc['gain_ratio'].get(s), '{:.3f}')} | >= 0.8 |")
    for s in ("bev_1", "bev_2"):
        if "gain_ratio_generator_points" in doc:
            lines.append(f"| gain_ratio_generator_points.{s} | {_f(doc['gain_ratio_generator_points'].get(s), '{:.3f}')} | |")
    for name, key in (("Everything estimated", "estimated"),
                      ("Ground-truth poses, scale and masks, the capture's sparse points (`gain_ratio`)", GT_CAPTURE_POINTS),
                      ("Ground-truth poses, scale and masks, the generator's sparse points (`gain_ratio_generator_points`)", "ground_truth")):
        res = doc.get("results", {}).get(key)
        if res:
            lines += ["", markdown_table(res, target_groups(res), name)]
    lines += ["", "Time per stage (s): " + ", ".join(f"{k} {v}" for k, v in doc["stage_seconds"].items())
              + "; SfM: " + ", ".join(f"{k} {v:.1f}" for k, v in doc["process"]["stage_seconds"].items())
              + f"; masks: reference {doc['masks']['reference_seconds']}, masks {doc['masks']['mask_seconds']}"]
    if "train_seconds" in doc:
        lines += ["", "Training (s): " + ", ".join(f"{k} {_f(v, '{:.0f}')}" for k, v in doc["train_seconds"].items())]
    lines += ["", f"Bench wall time: {doc['wall_seconds']:.0f} s (training reused where cached)."]
    return "\n".join(lines) + "\n"


def write_results(out_dir: Path, doc: dict) -> None:
    from nerf2gs_bench.paper import psnr_bar_chart, succeeded
    from nerf2gs_bench.machine import machine_info

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    doc["machine"] = machine_info()
    atomic_write_text(out_dir / "real.json", json.dumps(doc, indent=1, default=str))
    atomic_write_text(out_dir / "real.md", results_md(doc))
    tag = {"estimated": "est", GT_CAPTURE_POINTS: "GT, SfM points", "ground_truth": "GT"}
    merged = {f"{label} ({tag.get(key, key)})": r for key, res in doc.get("results", {}).items() for label, r in succeeded(res).items()}
    psnr_bar_chart(merged, out_dir / "real.png", "Real-capture path: estimated vs ground-truth poses, scale, masks")
