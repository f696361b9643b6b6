"""``ns2gs-bench real-path-speed``: the real path of a dashcam capture timed stage by stage.

Stand-in for a 100-frame 480x360 dashcam clip: the synthetic street with movers (a car and a cyclist
riding ahead at the drive's speed, pedestrians, parked cars) rendered at 480x360, its forward drive
written as a video. The path is what a user runs with default configs: ``process video`` ->
``masks`` (auto: first reference, its renders, the mask maths) -> StreetNeRF (``--warm-start`` from
the masks' reference as their second pass left it, unless ``--no-warm-start``) -> Splatfacto
``--augment-from`` StreetNeRF (the reference's renders, then the training). Every stage gets wall seconds and CPU seconds (user + sys of
this process and its children: robust to other load on a shared machine, and with one thread the
time the stage takes alone on one core). Writes ``real_path_speed.{json,md}``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from nerf2gs_plugin.utils.extensions import build_seconds
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.utils.parallel import cpu_seconds

STEM = "real_path_speed"
TARGET_MINUTES = 12.0


@dataclass
class RealPathOptions:
    frames: int = 100
    """Frames of the forward drive in the video."""
    width: int = 480
    height: int = 360
    street_seed: int = 0
    movers: bool = True
    """Objects moving with the camera and across it (what a dashcam sees)."""
    reference_steps: int = 1000
    """The masks' first reference (the masks stage's default)."""
    streetnerf_steps: Optional[int] = None
    """None: StreetNeRF's default."""
    splatfacto_steps: Optional[int] = None
    """None: Splatfacto's default (its whole schedule rescaled otherwise, as ns2gs-train --steps)."""
    view_downscale: Optional[int] = None
    """The views from above rendered and trained at 1/N size (--augment.view-downscale; None: its default)."""
    warm_start: bool = True
    """StreetNeRF continues from the masks' reference, as continued by their second pass when it ran (its first
    steps are the reference's)."""
    render_downscale: Optional[int] = None
    """The masks' renders at every d-th pixel per side (ns2gs-data masks --render-downscale); None: its default."""
    capture: Optional[str] = None
    """A real capture of real-captures (kitti, nuscenes, ...) instead of the stand-in: its first --frames frames as
    a video, scaled to the pixel count of --width x --height (aspect kept), with its field of view and camera height."""
    data_root: Optional[Path] = None
    """Where the real captures' folders are (None: real-captures' default, $NERF2GS_REAL_DATA)."""
    crop_bottom: Optional[float] = None
    """--capture: the share of each frame's height cut off at the bottom (a bonnet); None: the capture's own."""


class Stages:
    """Wall and CPU seconds per named stage, in the order run; ``on_stage`` is called after each (a
    long bench writes what it has so far)."""

    def __init__(self, on_stage: Optional[Callable[[], None]] = None) -> None:
        self.rows: dict[str, dict[str, float]] = {}
        self.kernel_seconds: dict[str, float] = {}
        """Wall seconds a stage spent compiling or loading the C++ kernels (a build is an install's cost, not the path's)."""
        self.on_stage = on_stage

    def run(self, name: str, fn: Callable):
        w0, c0, k0 = time.perf_counter(), cpu_seconds(), build_seconds()
        out = fn()
        self.add(name, time.perf_counter() - w0, cpu_seconds() - c0)
        self.kernel_seconds[name] = round(build_seconds() - k0, 1)
        if self.on_stage:
            self.on_stage()
        return out

    def add(self, name: str, wall: float, cpu: float) -> None:
        self.rows[name] = {"wall_s": round(wall, 1), "cpu_s": round(cpu, 1)}

    def split(self, name: str, part: str, wall: float, cpu: float) -> None:
        """Take ``part``'s share (measured inside stage ``name``) out of it into its own row, just before it."""
        rows, self.rows = self.rows, {}
        for k, v in rows.items():
            if k == name:
                self.add(part, wall, cpu)
                v = {"wall_s": round(v["wall_s"] - wall, 1), "cpu_s": round(v["cpu_s"] - cpu, 1)}
            self.rows[k] = v

    def total(self, key: str) -> float:
        return round(sum(v[key] for v in self.rows.values()), 1)


def stem(opts: RealPathOptions) -> str:
    """The results' name: one per capture, the stand-in's the plain one."""
    name = f"{STEM}_{opts.capture}" if opts.capture else STEM
    if opts.capture and opts.crop_bottom is not None:
        name += f"_crop{round(100 * opts.crop_bottom)}"
    return f"{name}_view_downscale{opts.view_downscale}" if (opts.view_downscale or 1) > 1 else name


def make_capture(root: Path, opts: RealPathOptions) -> tuple[Path, float, float]:
    """The stand-in street (or the real capture) and its forward drive as a video; ``(video, fov_deg, camera_height)``."""
    from nerf2gs_bench.real import write_video

    if opts.capture:
        return real_capture_video(root, opts)
    from nerf2gs_plugin.data.synthetic_street import GENERATOR_VERSION, SynthStreetConfig, generate_street, read_generator_version

    street = root / "street"
    cfg = SynthStreetConfig(out=street, seed=opts.street_seed, width=opts.width, height=opts.height, num_train=2 * opts.frames,
                            num_street=4, num_bev=4, num_val_street=0, num_val_bev=0, num_lane=0, num_val_lane=0,
                            movers=opts.movers, progress=False, overwrite=True)
    if not (street / "transforms.json").is_file() or read_generator_version(street) != GENERATOR_VERSION:
        generate_street(cfg)
    frames = json.loads((street / "transforms.json").read_text())["frames"][: opts.frames]  # the forward drive
    video = write_video(root / "drive.avi", [street / f["file_path"] for f in frames])
    return video, cfg.fov_deg, cfg.cam_height


def real_capture_video(root: Path, opts: RealPathOptions) -> tuple[Path, float, float]:
    """The first ``opts.frames`` frames of a real capture (bonnet cropped) at the stand-in's pixel count, as a video."""
    import cv2

    from nerf2gs_bench.real import write_video
    from nerf2gs_bench.real_captures import CAPTURES, capture_frames, default_data_root
    from nerf2gs_plugin.errors import ConfigError

    caps = {c.name: c for c in CAPTURES}
    if opts.capture not in caps:
        raise ConfigError(f"unknown capture '{opts.capture}' (known: {', '.join(sorted(caps))})")
    cap = caps[opts.capture]
    if cap.fov_deg is None:
        raise ConfigError(f"capture '{cap.name}' has no fixed field of view (EXIF photos): not a video")
    frames = capture_frames(cap, Path(opts.data_root or default_data_root()))[: opts.frames]
    Path(root).mkdir(parents=True, exist_ok=True)
    h0, w0 = cv2.imread(str(frames[0])).shape[:2]
    h0 = int(round(h0 * (1 - (cap.crop_bottom if opts.crop_bottom is None else opts.crop_bottom))))
    f = (opts.width * opts.height / (w0 * h0)) ** 0.5
    size = (2 * round(w0 * f / 2), 2 * round(h0 * f / 2))

    def shaped(img):
        return cv2.resize(img[: h0], size, interpolation=cv2.INTER_AREA)

    return write_video(Path(root) / f"{cap.name}.avi", frames, transform=shaped), cap.fov_deg, cap.camera_height


def _trainer_config(method: str, data: Path, run_dir: Path, steps: Optional[int], augment_changes: Optional[dict] = None, **kw):
    from nerf2gs_plugin.registry import get_method

    spec = get_method(method)
    cfg = spec.with_steps(steps) if steps else spec.config
    if augment_changes:
        kw["augment"] = dataclasses.replace(cfg.augment, **augment_changes)
    return dataclasses.replace(cfg, data=data, run_dir=run_dir, steps_per_eval_image=0, progress=False, **kw)


def _train(stages: Stages, name: str, cfg, setup_part: Optional[str] = None) -> Path:
    """Set up and train one run; ``setup_part`` names the setup's own row (the augmentation's renders)."""
    from nerf2gs_plugin.engine.trainer import Trainer

    trainer = Trainer(cfg)
    if setup_part:
        stages.run(setup_part, trainer.setup)
    else:
        trainer.setup()
    return stages.run(name, trainer.train)


def run(root: Path, out_dir: Path, opts: RealPathOptions = RealPathOptions(), log: Callable[[str], None] = print) -> dict:
    """The whole path in ``root`` (made afresh: nothing is reused); writes the results and returns them."""
    import shutil

    from nerf2gs_bench.machine import machine_info
    from nerf2gs_bench.real import process_capture
    from nerf2gs_plugin.data.process.sfm import SfmOptions
    from nerf2gs_plugin.masking.make_masks import MasksConfig, make_masks
    from nerf2gs_plugin.masking.mask_reference import ensure_reference

    root = Path(root)
    video, fov, cam_height = make_capture(root, opts)
    for stale in ("capture", "masks-reference", "masks-reference-second-pass", "streetnerf", "splatfacto-nerf-views"):
        shutil.rmtree(root / stale, ignore_errors=True)
    data, ref = root / "capture", root / "masks-reference"
    sfm_threads = SfmOptions().num_threads  # what a user's SfM runs on (the accuracy benches take one thread: repeatable)
    doc: dict = {"options": dict(dataclasses.asdict(opts)), "machine": machine_info(), "complete": False, "sfm_threads": sfm_threads,
                 "streetnerf_render_nerf_samples": _render_nerf_samples(), "video_size": _video_size(video)}

    def record(final: bool = False) -> None:
        doc.update({"stage_seconds": stages.rows, "kernel_build_seconds": stages.kernel_seconds, "total_wall_s": stages.total("wall_s"), "total_cpu_s": stages.total("cpu_s"),
                    "target_minutes": TARGET_MINUTES, "load_average": _load_average(), "complete": final})
        write_results(out_dir, doc)

    stages = Stages(on_stage=record)
    report = stages.run("process (frames, SfM)", lambda: process_capture(video, data, opts.frames, fov, cam_height, sfm_threads))
    log(f"[bench] process: {report.registered}/{report.frames} registered")
    doc["registered"], doc["frames_used"] = report.registered, report.frames  # a capture may hold fewer than --frames
    doc["kept"] = json.loads((data / "transforms.json").read_text()).get("process", {}).get("kept")  # after the capture check
    stages.run("masks: first reference", lambda: ensure_reference(data, ref, opts.reference_steps, progress=False, log=log))
    down = {} if opts.render_downscale is None else {"render_downscale": opts.render_downscale}
    summary = stages.run("masks: mask maths", lambda: make_masks(MasksConfig(
        data=data, reference=ref, splits=("train",), overwrite=True, progress=False, **down), log=log))
    doc["masks_render_downscale"] = summary.get("render_downscale")
    stages.split("masks: mask maths", "masks: renders", summary["render_seconds"], summary["render_cpu_seconds"])
    if "second_pass_seconds" in summary:
        stages.split("masks: mask maths", "masks: second pass", summary["second_pass_seconds"], summary["second_pass_cpu_seconds"])
    warm = Path(summary.get("second_pass_run") or ref)  # what `ns2gs-data masks` tells StreetNeRF to go on from
    doc["warm_start_from"] = warm.name if opts.warm_start else None
    sn = _train(stages, "StreetNeRF", _trainer_config("streetnerf", data, root / "streetnerf", opts.streetnerf_steps,
                                                      warm_start=warm if opts.warm_start else None))
    target = _trainer_config("splatfacto", data, root / "splatfacto-nerf-views", opts.splatfacto_steps, augment_from=sn,
                             augment_changes={} if opts.view_downscale is None else {"view_downscale": opts.view_downscale})
    dm = target.pipeline.datamanager
    doc["splatfacto_coarse_to_fine"] = {"num_downscales": dm.num_downscales, "resolution_schedule": dm.resolution_schedule}
    _train(stages, "Splatfacto + NeRF views: training", target, setup_part="Splatfacto + NeRF views: reference renders")
    doc["masks_coverage"] = summary.get("coverage")
    record(final=True)
    return doc


def _video_size(video: Path) -> str:
    import cv2

    cap = cv2.VideoCapture(str(video))
    try:
        return f"{int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))}x{int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))}"
    finally:
        cap.release()


def _render_nerf_samples() -> Optional[int]:
    """StreetNeRF's fine samples per ray in a render (the masks' and the augmentation's renders)."""
    from nerf2gs_plugin.methods.streetnerf.model import StreetNeRFModelConfig

    return StreetNeRFModelConfig().render_nerf_samples


def _load_average() -> Optional[list[float]]:
    try:
        return [float(x) for x in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return None


def results_md(doc: dict) -> str:
    from nerf2gs_bench.machine import machine_line

    o = doc["options"]
    second = str(doc.get("warm_start_from") or "").endswith("-second-pass")
    warm = ("warm-started from the masks' " + ("second-pass reference" if second else "reference")) if o["warm_start"] else "from scratch"
    lines = [f"# The real path, stage by stage ({o['frames']} frames, {o['width']}x{o['height']})", "",
             f"Machine: {machine_line(doc['machine'])}; torch threads {doc['machine'].get('torch_threads')}; "
             f"SfM threads {_sfm_threads(doc)}; "
             f"load average at the end {doc.get('load_average')}.",
             f"{_source(doc)}; masks' reference {o['reference_steps']} steps, StreetNeRF "
             f"{o['streetnerf_steps'] or 'default'} steps ({warm}), "
             f"Splatfacto {o['splatfacto_steps'] or 'default'} steps with NeRF views{_coarse_to_fine(doc)}"
             f"{'' if o.get('view_downscale') in (None, 1) else ' (the views from above at 1/%d size)' % o['view_downscale']}; masks' renders at 1/{_downscale(doc):g}; "
             f"StreetNeRF renders with {doc.get('streetnerf_render_nerf_samples') or 'all'} fine samples per ray. "
             f"Registered {doc.get('registered', '?')}/{doc.get('frames_used', o['frames'])}"
             f"{'' if doc.get('kept') in (None, doc.get('registered')) else ', %s kept by the capture check' % doc['kept']}.", "",
             "CPU seconds are user + system of the bench's process (one thread: the time the stage takes alone on one "
             "core); wall seconds depend on the machine's other load.", "",
             "| stage | CPU s | wall s |", "|---|---|---|"]
    for name, v in doc["stage_seconds"].items():
        lines.append(f"| {name} | {v['cpu_s']:.1f} | {v['wall_s']:.1f} |")
    lines.append(f"| **total** | **{doc['total_cpu_s']:.0f} ({doc['total_cpu_s'] / 60:.1f} min)** | "
                 f"**{doc['total_wall_s']:.0f} ({doc['total_wall_s'] / 60:.1f} min)** |")
    built = {k: v for k, v in doc.get("kernel_build_seconds", {}).items() if v >= 5}
    if built:
        lines += ["", "Kernels compiled during the run (wall s, inside the stages above): "
                  + ", ".join(f"{k} {v:.0f}" for k, v in built.items()) + "."]
    elif "kernel_build_seconds" in doc:
        lines += ["", f"No kernel was compiled during the run (loads {sum(doc['kernel_build_seconds'].values()):.1f} s in all)."]
    if not doc.get("complete", True):
        lines += ["", "**Incomplete: the bench stopped (or is still running) after the stages above.**"]
    lines += ["", f"Target: <= {doc['target_minutes']:g} min for the whole path on 2 cores."]
    return "\n".join(lines) + "\n"


def _coarse_to_fine(doc: dict) -> str:
    """Whether Splatfacto trained coarse to fine (results written before it was recorded say nothing)."""
    c = doc.get("splatfacto_coarse_to_fine")
    if c is None:
        return ""
    if c["num_downscales"] <= 0:
        return " (full size throughout)"
    return f" (coarse to fine: 1/{2 ** c['num_downscales']} size first, doubled every {c['resolution_schedule']} steps)"


def _sfm_threads(doc: dict) -> str:
    """COLMAP's threads in the process stage (results written before it was recorded ran on one)."""
    n = doc.get("sfm_threads", 1)
    return "all cores (the product's default)" if n < 1 else str(n)


def _source(doc: dict) -> str:
    o = doc["options"]
    if o.get("capture"):
        crop = "" if o.get("crop_bottom") is None else f", the bottom {100 * o['crop_bottom']:g}% of each frame cut off"
        return (f"Real capture: {o['capture']}'s first {doc.get('frames_used', o['frames'])} frames as a video at {doc.get('video_size', '?')} "
                f"(the pixel count of {o['width']}x{o['height']}{crop})")
    return (f"Stand-in: the synthetic street (seed {o['street_seed']}{', movers' if o['movers'] else ''}) at {o['width']}x{o['height']}, "
            "its forward drive as a video")


def _downscale(doc: dict) -> float:
    """The masks' render downscale of a run (older results: only the option, 1 when unset)."""
    return doc.get("masks_render_downscale") or doc["options"].get("render_downscale") or 1.0


def write_results(out_dir: Path, doc: dict) -> None:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    o = doc["options"]
    name = stem(RealPathOptions(capture=o.get("capture"), view_downscale=o.get("view_downscale", 1), crop_bottom=o.get("crop_bottom")))
    atomic_write_text(out_dir / f"{name}.json", json.dumps(doc, indent=1, default=str))
    atomic_write_text(out_dir / f"{name}.md", results_md(doc))
