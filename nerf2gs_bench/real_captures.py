"""``ns2gs-bench real-captures``: public real captures through the whole path, measured from above too.

Per capture (a declarative list below: where its frames come from, their licence, the camera's height
and field of view): ``process images`` -> ``masks`` (auto) -> StreetNeRF -> Splatfacto alone and with
NeRF views (the same stages as ``real-photos``), then what a real capture allows without ground truth:
registered fraction, seconds per stage, the masks' coverage, held-out PSNR (every 8th frame; over
static pixels only where moving-object labels exist), and holes from above: the share of pixels with
accumulation < 0.5 rendered from the augmentation's own bird's-eye cameras. The bench never
downloads: it reads frames fetched beforehand under ``--data-root`` and names the missing ones.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

from nerf2gs_plugin.utils.io import atomic_write_text

STEM = "real_captures"
TARGET, AUGMENTED, REFERENCE = "splatfacto", "splatfacto + NeRF views", "StreetNeRF"
DATA_ROOT_ENV = "NERF2GS_REAL_DATA"
MIN_FRAMES = 3  # fewer cannot make a held-out split and a two-view SfM


@dataclass(frozen=True)
class Capture:
    """One public capture: where its frames are, what may be shown, how the camera sat."""

    name: str
    folder: str
    """Frames' folder under the data root."""
    fetch: str
    """Where the frames come from (repository and path): the bench never fetches them itself."""
    licence: str
    provenance: str
    camera_height: float
    """Metres above the ground (sets the metric scale)."""
    fov_deg: Optional[float] = None
    """Horizontal field of view when the frames carry no EXIF focal."""
    first: int = 0
    last: Optional[int] = None
    """Frames ``[first, last)`` in name order (one shot: scene cuts excluded)."""
    crop_bottom: float = 0.0
    """Share of the frame's height cut at the bottom (a car's bonnet)."""
    mount: str = "car"
    show_renders: bool = False
    """Whether the licence lets the bench's picture show renders of it."""
    labels: tuple[str, ...] = ()
    """Hand labels of moving objects (``benchmarks/validation/labels/<name>.json``, in the source frames' pixels; several
    sets of the same frames merge), when any exist: the masks' IoU on labelled training frames, static PSNR on labelled
    held-out frames."""
    truth: Optional[str] = None
    """Folder (under the data root) of ground-truth cameras ``<image name>.camera`` (Strecha's format), when surveyed."""


CAPTURES: tuple[Capture, ...] = (
    Capture("kitti", "kitti", "github:rahulagrawal048/kitti-odometry, kitti/0001-0133.png (commit 403ebe5)",
            "CC BY-NC-SA 3.0 (KITTI)", "KITTI raw excerpt (Geiger et al.), 133 frames 800x240 from a car-mounted camera",
            camera_height=1.65, fov_deg=81.0, labels=("kitti_moving", "kitti_moving_more")),
    Capture("lund", "lund/images", "github:mapillary/OpenSfM, data/lund/images (commit 238744c)",
            "BSD-2-Clause (OpenSfM)", "29 hand-held photos of a street in Lund, 1024x768, EXIF focal and GPS",
            camera_height=1.6, mount="walk", show_renders=True),
    Capture("nuscenes", "nuscenes/image_2", "github:youngibby/nuscene, image_2/ (nuScenes CAM_FRONT)",
            "CC BY-NC-SA 4.0 (nuScenes)", "nuScenes CAM_FRONT 1600x900, first shot (frames 1-52: every 8th, held out, is labelled), bonnet cropped",
            camera_height=1.5, fov_deg=64.0, first=1, last=53, crop_bottom=0.1, labels=("nuscenes_moving_heldout",)),
    Capture("herzjesu", "herzjesu/images", "github:openMVG/SfM_quality_evaluation, Benchmarking_Camera_Calibration_2008/"
            "Herz-Jesus-P25/ (images/ and gt_dense_cameras/, commit 348a981)",
            "no licence stated in the repository (Strecha et al. 2008, EPFL CVLab: research use)",
            "Strecha's Herz-Jesu-P25: 25 photos 3072x2048 of a church courtyard with surveyed metric cameras",
            camera_height=1.6, fov_deg=58.2, mount="hand-held", truth="herzjesu/gt_dense_cameras"),
)


@dataclass(frozen=True)
class BenchScale:
    """Frames, training width and steps of one bench scale."""

    frames: Optional[int]
    width: Optional[int]
    """Training width in pixels (the nearest downscale of the processed frames); None: full size."""
    reference_steps: int
    streetnerf_steps: int
    splatfacto_steps: int
    above_views: int = 12
    """Bird's-eye views rendered per run for the hole measure (evenly over the augmentation's views)."""


SCALES = {
    "quick": BenchScale(frames=40, width=400, reference_steps=300, streetnerf_steps=500, splatfacto_steps=700, above_views=8),
    "full": BenchScale(frames=None, width=None, reference_steps=500, streetnerf_steps=1000, splatfacto_steps=1500),
}


def default_data_root() -> Path:
    return Path(os.environ.get(DATA_ROOT_ENV) or Path.home() / ".cache" / "nerf2gs" / "real")


def capture_frames(cap: Capture, data_root: Path) -> list[Path]:
    """The capture's frames in name order, ``[first, last)``; one clear line if they are not there."""
    from nerf2gs_plugin.data.process.frames import IMAGE_EXTS
    from nerf2gs_plugin.errors import DataError

    folder = Path(data_root) / cap.folder
    names = sorted(p for p in folder.glob("*") if p.suffix.lower() in IMAGE_EXTS) if folder.is_dir() else []
    names = names[cap.first:cap.last]
    if cap.truth and len(names) >= MIN_FRAMES and not (Path(data_root) / cap.truth).is_dir():
        raise DataError(f"capture '{cap.name}': ground-truth cameras missing; fetch {cap.fetch} (the bench does not download)",
                        Path(data_root) / cap.truth)
    if len(names) < MIN_FRAMES:
        raise DataError(f"capture '{cap.name}': frames missing ({len(names)} found); fetch {cap.fetch} into this folder (the bench does not download)",
                        folder)
    return names


def stage_frames(cap: Capture, frames: Sequence[Path], out: Path, count: Optional[int]) -> list[Path]:
    """The first ``count`` frames (consecutive: neighbours keep their overlap) copied into ``out``;
    cropped ones rewritten, the rest copied byte for byte (their EXIF focal stays). Frames another scale
    staged there before are removed: ``process`` takes the whole folder."""
    import cv2

    out.mkdir(parents=True, exist_ok=True)
    picked = list(frames)[:count] if count else list(frames)
    keep = {src.name for src in picked}
    for old in out.iterdir():
        if old.is_file() and old.name not in keep:
            old.unlink()
    staged = []
    for src in picked:
        dst = out / src.name
        if not dst.is_file():
            if cap.crop_bottom > 0:
                img = cv2.imread(str(src))
                keep = int(round(img.shape[0] * (1.0 - cap.crop_bottom)))
                tmp = dst.with_name(f".{dst.stem}.tmp{dst.suffix}")
                cv2.imwrite(str(tmp), img[:keep])
                tmp.replace(dst)
            else:
                shutil.copyfile(src, dst)
        staged.append(dst)
    return staged


def downscale_for(width_px: int, scale: BenchScale) -> float:
    """The integer downscale that brings ``width_px`` nearest the scale's training width (>= 1)."""
    if scale.width is None:
        return 1.0
    return float(max(1, round(width_px / scale.width)))


# ----------------------------------------------------------------------------- measures from above
# ----------------------------------------------------------------------------- holes on a few views from above
# (the street-level bench's quick measure; this bench measures through ns2gs-render compare below)
def hole_fraction(accumulations: Sequence) -> float:
    """Share of all pixels of the renders that are holes (``ns2gs-render``'s measure: accumulation below 0.5)."""
    from nerf2gs_plugin.render.measures import hole_mask

    holes = pixels = 0
    for acc in accumulations:
        h = hole_mask(acc if acc.dim() == 3 else acc[..., None])
        holes += int(h.sum())
        pixels += h.numel()
    return holes / max(pixels, 1)


def above_cameras(run, delta_h: float, theta_pitch: float, views: int):
    """``views`` of the augmentation's own bird's-eye cameras (over the training cameras), evenly spread."""
    import dataclasses

    import torch

    from nerf2gs_plugin.augment.config import AugmentConfig
    from nerf2gs_plugin.augment.geometry import ViewGeometry

    td = run.pipeline.datamanager.train_data
    geometry = ViewGeometry.of(dataclasses.replace(AugmentConfig(), delta_h=delta_h, theta_pitch=theta_pitch))
    cams = geometry.cameras(td.cameras, td)
    idx = torch.linspace(0, len(cams) - 1, min(views, len(cams))).round().long().unique()
    return cams[idx]


def holes_from_above(run_dir: Path, delta_h: float, theta_pitch: float, views: int) -> tuple[float, list]:
    """A run's hole fraction on the bird's-eye cameras, and its RGB renders (for the picture)."""
    import torch

    from nerf2gs_plugin.runs.load import load_run

    run = load_run(run_dir)
    run.model.eval()
    cams = above_cameras(run, delta_h, theta_pitch, views)
    accs, rgbs = [], []
    with torch.no_grad():
        for i in range(len(cams)):
            out = run.model.render_camera(cams[i:i + 1])
            accs.append(out["accumulation"].cpu())
            rgbs.append(out["rgb"].clamp(0, 1).cpu())
    return hole_fraction(accs), rgbs


COMPARE_LABELS = {TARGET: "splatfacto (target alone)", AUGMENTED: "splatfacto + NeRF views", REFERENCE: "StreetNeRF (reference)"}
"""How each run is labelled in its compare frames."""
COMPARE_RECORD = "bench_compare.json"


def compare_or_reuse(cap: Capture, doc: dict, output: Path, rerun: bool,
                     log: Callable[[str], None]) -> tuple[dict[str, Optional[float]], list[Path], float, bool]:
    """Holes from above per run, the compare frames, the stage's seconds and whether they are the saved
    ones: ``ns2gs-render compare`` of the capture's runs on the augmentation's bird's-eye views (reused
    when the same runs were compared by the same code)."""
    from nerf2gs_bench.capture_compare import compare_frames, compare_from_above
    from nerf2gs_bench.code_version import source_hash
    from nerf2gs_bench.stage_record import read_stage, stage_key, write_stage

    done = {label: r["run_dir"] for label, r in doc["results"].items() if not r.get("failed") and r.get("run_dir")}
    holes: dict[str, Optional[float]] = {label: None for label in (TARGET, AUGMENTED, REFERENCE)}
    if TARGET not in done or AUGMENTED not in done:  # the views from above are the augmented run's
        log(f"[bench] {cap.name}: no holes from above (the target or its augmented twin failed)")
        return holes, [], 0.0, False
    labels = [label for label in (TARGET, AUGMENTED, REFERENCE) if label in done]
    key = stage_key("compare", [done[label] for label in labels], source_hash(("render", "cli/render.py")))
    record = None if rerun else read_stage(output.parent / COMPARE_RECORD, key)
    if record is not None and output.is_dir():
        measures, seconds, reused = record["measures"], record["seconds"], True
        log(f"[bench] {cap.name}: reusing the compare from above in {output}")
    else:
        t0 = time.perf_counter()
        measures = compare_from_above([done[label] for label in labels], [COMPARE_LABELS[label] for label in labels], output)
        seconds, reused = write_stage(output.parent / COMPARE_RECORD, key, time.perf_counter() - t0, measures=measures)["seconds"], False
    for label in labels:
        holes[label] = measures[COMPARE_LABELS[label]]["bev_hole_fraction"]
        log(f"[bench] {cap.name}: {label} holes from above {100 * holes[label]:.1f}%")
    return holes, compare_frames(output), seconds, reused


# ----------------------------------------------------------------------------- one capture
def hand_labels(hand: dict) -> dict:
    """The record's keys from :func:`hand_label_scores`: the moving IoU and, where held-out frames are
    labelled, the static PSNR by the labels (in place of the masks stage's estimate)."""
    static = hand["static"]
    out = {"moving_iou": None if hand["moving"] is None else hand["moving"]["iou"], "hand_labels": hand}
    if hand["static_frames"]:
        out["static_psnr"] = static
        out["static_psnr_delta"] = (None if static[TARGET] is None or static[AUGMENTED] is None
                                    else static[AUGMENTED] - static[TARGET])
    return out


def capture_summary(cap: Capture, doc: dict, holes: dict[str, Optional[float]]) -> dict:
    """The per-capture record of the bench from ``run_real_photos``' document and the holes from above."""
    p, res = doc["process"], doc["results"]

    def psnr(label: str, key: str = "psnr") -> Optional[float]:
        r = res.get(label) or {}
        return None if r.get("failed") else (r.get("results") or {}).get("test", {}).get(key)

    target, augmented = psnr(TARGET), psnr(AUGMENTED)
    # ns2gs-eval's PSNR outside the moving-object masks: null unless the held-out frames have masks
    # (the bench's masks stage makes them for the training frames only)
    static = {label: psnr(label, "static_psnr") for label in (REFERENCE, TARGET, AUGMENTED)}
    stages = {"process": doc["stage_seconds"].get("process"), "masks": doc["stage_seconds"].get("masks"),
              **{label: doc["stage_seconds"].get(f"train + eval: {label}") for label in (REFERENCE, TARGET, AUGMENTED)}}
    return {
        "capture": cap.name, "mount": cap.mount, "licence": cap.licence, "provenance": cap.provenance, "fetch": cap.fetch,
        "frames": p["frames"], "registered_fraction": p["registered"] / max(p["frames"], 1),
        "metres_per_unit": p["metres_per_unit"], "scale_source": p["scale_source"],
        "stage_seconds": stages, "sfm_stage_seconds": p["stage_seconds"],
        "masks_coverage": (doc.get("masks") or {}).get("coverage"),
        "psnr": {REFERENCE: psnr(REFERENCE), TARGET: target, AUGMENTED: augmented},
        "psnr_delta": None if target is None or augmented is None else augmented - target,
        "static_psnr": static,
        "static_psnr_delta": None if static[TARGET] is None or static[AUGMENTED] is None else static[AUGMENTED] - static[TARGET],
        "moving_iou": None,
        "bev_hole_fraction": {"target": holes.get(TARGET), "augmented": holes.get(AUGMENTED), "reference": holes.get(REFERENCE)},
        "wall_seconds": doc["wall_seconds"],
    }


def hand_label_scores(cap: Capture, data: Path, run_dirs: dict[str, str]) -> dict:
    """Where the capture has hand labels: the masks stage's moving-object IoU on its labelled training frames
    (``moving``, None when none is in the run), and each run's held-out PSNR over the static pixels of the
    labelled held-out frames (``static``, by ``ns2gs-eval`` on the capture with those frames' labels as masks)."""
    import tempfile

    from nerf2gs_bench.hand_labels import labelled_view, merged_labels, moving_scores
    from nerf2gs_plugin.eval.evaluate import evaluate_run
    from nerf2gs_plugin.runs.load import load_run

    labels = merged_labels(cap.labels)
    src_h = labels.get("source_size", labels["size"])[1]
    crop_rows = int(round(src_h * (1.0 - cap.crop_bottom)))  # as stage_frames cuts the bonnet
    static: dict[str, Optional[float]] = {label: None for label in (REFERENCE, TARGET, AUGMENTED)}
    per_image: dict[str, Optional[list]] = {label: None for label in (REFERENCE, TARGET, AUGMENTED)}
    with tempfile.TemporaryDirectory() as tmp:
        view = Path(tmp) / "data"
        frames = labelled_view(data, labels, view, crop_rows)
        for label, run in run_dirs.items() if frames else ():
            test = evaluate_run(load_run(Path(run), device="cpu", data=view), ["test"])["results"]["test"]
            static[label], per_image[label] = test["static_psnr"], test.get("static_psnr_per_image")
    return {"labels": list(cap.labels), "moving": moving_scores(data, labels, crop_rows), "static": static, "static_frames": frames,
            "static_per_image": per_image}


def failed_record(cap: Capture, why: str) -> dict:
    """The record of a capture whose path stopped (e.g. too few frames registered): every figure null."""
    return {"capture": cap.name, "mount": cap.mount, "licence": cap.licence, "provenance": cap.provenance, "fetch": cap.fetch,
            "failed": why, "registered_fraction": None, "stage_seconds": {}, "masks_coverage": None,
            "psnr": {REFERENCE: None, TARGET: None, AUGMENTED: None}, "psnr_delta": None,
            "static_psnr": {REFERENCE: None, TARGET: None, AUGMENTED: None}, "static_psnr_delta": None, "moving_iou": None,
            "bev_hole_fraction": {"target": None, "augmented": None, "reference": None}}


def pool_seeds(per_seed: Sequence[dict]) -> dict:
    """The record's deltas over several seeds' target pairs (``per_seed``: ``{"seed", "psnr", "static_psnr"}``, each
    PSNR by label or None): ``psnr_delta`` and ``static_psnr_delta`` the means over the seeds that have both runs
    (None where none has), with the per-seed deltas beside them. One seed moves a few held-out frames' PSNR by
    tenths of a dB: a target read off one run says little."""
    def deltas(key: str) -> list[Optional[float]]:
        out = []
        for r in per_seed:
            p = r.get(key) or {}
            out.append(None if p.get(TARGET) is None or p.get(AUGMENTED) is None else p[AUGMENTED] - p[TARGET])
        return out

    pooled: dict = {"seeds": [r["seed"] for r in per_seed], "per_seed": list(per_seed)}
    for key in ("psnr", "static_psnr"):
        ds = deltas(key)
        known = [d for d in ds if d is not None]
        pooled[f"{key}_delta"] = sum(known) / len(known) if known else None
        pooled[f"{key}_delta_per_seed"] = ds
        halves = [split_delta((r.get(f"{key}_per_image") or {}).get(TARGET), (r.get(f"{key}_per_image") or {}).get(AUGMENTED))
                  for r in per_seed]
        pooled[f"{key}_delta_halves_per_seed"] = halves
        for i, half in enumerate(("validation", "test")):
            known = [h[i] for h in halves if h is not None]
            pooled[f"{key}_delta_{half}"] = sum(known) / len(known) if known else None
    return pooled


def split_delta(target: Optional[Sequence[Optional[float]]], augmented: Optional[Sequence[Optional[float]]]
                ) -> Optional[tuple[float, float]]:
    """(validation, test): the mean per-frame PSNR with NeRF views minus without over the 1st, 3rd, ... held-out frame
    (choose a lever on these) and over the 2nd, 4th, ... (report it), as ``ns2gs-bench street-level`` splits them;
    frames without a value (no labels) are left out. None without per-frame values or with a half empty."""
    if not target or not augmented or len(target) != len(augmented):
        return None
    out = []
    for start in (0, 1):
        pairs = [(a, b) for a, b in zip(target[start::2], augmented[start::2]) if a is not None and b is not None]
        if not pairs:
            return None
        out.append(sum(b - a for a, b in pairs) / len(pairs))
    return out[0], out[1]


def other_seeds(cap: Capture, opts, data: Path, runs_root: Path, seeds: Sequence[int], log: Callable[[str], None],
                augment: Optional[dict] = None) -> list[dict]:
    """Splatfacto alone and with NeRF views (from the bench's StreetNeRF, reused; ``augment``: more ``--augment.*``
    of the latter) trained with each of ``seeds``: per seed the held-out PSNR of both, where the capture's held-out
    frames are labelled their static PSNR, and their run folders."""
    from nerf2gs_bench.real_photos import NERF_VIEWS, run_specs
    from nerf2gs_bench.runner import BenchRunner, failure_reason

    runner = BenchRunner(Path(runs_root) / STEM, log=log)
    ref = runner.run(run_specs(opts)[REFERENCE], data)  # the bench's own run: reused
    if failure_reason(ref) is not None:
        return []
    out = []
    for seed in seeds:
        specs = run_specs(opts, seed, augment)
        done = {TARGET: runner.run(specs[TARGET], data), AUGMENTED: runner.run(specs[NERF_VIEWS], data, reference=(Path(ref.run_dir), ref.key))}
        ok = {label: o for label, o in done.items() if failure_reason(o) is None}
        tests = {label: ((ok[label].result.get("results") or {}).get("test") or {}) if label in ok else {} for label in (TARGET, AUGMENTED)}
        psnr = {label: t.get("psnr") for label, t in tests.items()}
        per_image = {label: t.get("psnr_per_image") for label, t in tests.items()}
        static, static_per_image = None, None
        if cap.labels and ok:
            hand = hand_label_scores(cap, data, {label: o.run_dir for label, o in ok.items()})
            static, static_per_image = hand["static"], hand["static_per_image"]
        out.append({"seed": seed, "psnr": psnr, "static_psnr": static, "psnr_per_image": per_image,
                    "static_psnr_per_image": static_per_image, "run_dirs": {label: str(o.run_dir) for label, o in ok.items()}})
        log(f"[bench] {cap.name}: seed {seed}: PSNR {psnr[TARGET]} / {psnr[AUGMENTED]} (alone / + NeRF views)")
    return out


def _default_seed() -> int:
    """The seed the bench's own runs train with (the method's default)."""
    from nerf2gs_plugin.registry import get_method

    return int(get_method("splatfacto").config.seed)


def run_capture(cap: Capture, data_root: Path, runs_root: Path, scale: BenchScale, rerun: bool = False,
                log: Callable[[str], None] = print, seeds: Sequence[int] = ()) -> tuple[dict, list[Path]]:
    """One capture through the whole path; its record and its compare frames from above (PNG, labelled)."""
    import cv2

    from nerf2gs_bench.real_photos import RealPhotosOptions, run_real_photos
    from nerf2gs_plugin.augment.config import AugmentConfig

    frames = capture_frames(cap, data_root)
    root = Path(runs_root) / STEM / cap.name
    staged = stage_frames(cap, frames, root / "frames", scale.frames)
    width = cv2.imread(str(staged[0])).shape[1]
    aug = AugmentConfig()
    opts = RealPhotosOptions(images=root / "frames", provenance=f"{cap.provenance}; {cap.fetch}; {cap.licence}",
                             camera_height=cap.camera_height, fov_deg=cap.fov_deg, downscale=downscale_for(min(width, 1600), scale),
                             reference_steps=scale.reference_steps, streetnerf_steps=scale.streetnerf_steps,
                             splatfacto_steps=scale.splatfacto_steps, delta_h=aug.delta_h, theta_pitch=aug.theta_pitch,
                             # a drive's frames in order, as `process video` matches them: the masks' motion route runs on a sequence
                             matching="sequential" if cap.mount == "car" else "auto")
    doc = run_real_photos(opts, runs_root / STEM, root / "results", rerun=rerun, log=log, name=cap.name)
    holes, views, seconds, reused = compare_or_reuse(cap, doc, root / "compare-birds-eye", rerun, log)
    doc["stage_seconds"]["holes from above"] = seconds
    summary = capture_summary(cap, doc, holes)
    if cap.labels:
        done = {label: r["run_dir"] for label, r in doc["results"].items() if not r.get("failed") and r.get("run_dir")}
        hand = hand_label_scores(cap, Path(doc["data"]), done)
        summary.update(hand_labels(hand))
        moving = hand["moving"]
        log(f"[bench] {cap.name}: hand labels: moving-object IoU "
            f"{'n/a (no labelled training frame)' if moving is None else '%.3f on %d frames' % (moving['iou'], len(moving['frames']))}, "
            f"static PSNR on {len(hand['static_frames'])} labelled held-out frames")
    default_seed = _default_seed()
    extra = [seed for seed in seeds if seed != default_seed]
    if extra:
        tests = {label: ((doc["results"].get(label) or {}).get("results") or {}).get("test") or {} for label in (TARGET, AUGMENTED)}
        first = {"seed": default_seed, "psnr": {label: summary["psnr"][label] for label in (TARGET, AUGMENTED)},
                 "static_psnr": summary["static_psnr"], "psnr_per_image": {label: t.get("psnr_per_image") for label, t in tests.items()},
                 "static_psnr_per_image": hand["static_per_image"] if cap.labels else None}
        summary.update(pool_seeds([first, *other_seeds(cap, opts, Path(doc["data"]), runs_root, extra, log)]))
    summary["stage_seconds"]["holes from above"] = doc["stage_seconds"]["holes from above"]
    # named as in the record's stage_seconds (runs by their label)
    summary["reused_stages"] = [k.removeprefix("train + eval: ") for k in doc.get("reused_stages", [])] + (
        ["holes from above"] if reused else [])
    summary["options"] = {"frames_used": len(staged), "downscale": opts.downscale, "delta_h": opts.delta_h,
                          "theta_pitch": opts.theta_pitch, "steps": {"reference": scale.reference_steps,
                                                                     REFERENCE: scale.streetnerf_steps, TARGET: scale.splatfacto_steps}}
    if cap.truth:
        from nerf2gs_bench.capture_truth import truth_report
        from nerf2gs_plugin.errors import DataError

        try:
            summary["pose_truth"] = truth_report(Path(doc["data"]), Path(data_root) / cap.truth)
        except DataError as e:  # the runs' figures stand without it
            summary["pose_truth"] = {"error": str(e)}
            log(f"[bench] {cap.name}: no comparison with the surveyed cameras: {e}")
        else:
            log(f"[bench] {cap.name}: against the surveyed cameras ATE {summary['pose_truth']['ate_m']:.3f} m, "
                f"scale error {summary['pose_truth']['scale_error_percent']:+.1f}%")
    return summary, views


# ----------------------------------------------------------------------------- the bench
def run(names: Sequence[str], data_root: Path, runs_root: Path, out_dir: Path, scale_name: str = "quick",
        rerun: bool = False, log: Callable[[str], None] = print, docs_picture: Optional[Path] = None,
        seeds: Sequence[int] = ()) -> dict:
    """Every named capture; writes ``real_captures.{json,md,png}`` into ``out_dir`` (and, with ``docs_picture``,
    one compare frame of the first capture whose licence allows renders there); returns the document. ``seeds``: the
    targets' pair trained with each (the default seed's is the bench's own run), the deltas their means."""
    from nerf2gs_plugin.errors import ConfigError, UserError

    by_name = {c.name: c for c in CAPTURES}
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise ConfigError(f"--captures: unknown capture '{unknown[0]}' (known: {', '.join(by_name)})")
    caps = [by_name[n] for n in names]
    for cap in caps:  # all missing frames named before hours of training
        capture_frames(cap, data_root)
    scale = SCALES[scale_name]
    load_start = os.getloadavg()[0]  # the seconds mean little on a shared machine without it
    records, pictures = [], {}
    doc = {"scale": scale_name, "scale_settings": scale.__dict__, "captures": records,
           "load_average": {"start": load_start, "end": load_start}}
    for cap in caps:
        try:
            record, renders = run_capture(cap, data_root, runs_root, scale, rerun=rerun, log=log, seeds=seeds)
        except UserError as e:  # a capture SfM cannot register is a result of the bench, not its end
            log(f"[bench] {cap.name}: failed: {e}")
            records.append(failed_record(cap, str(e)))
        else:
            records.append(record)
            if cap.show_renders and renders:
                pictures[cap.name] = renders
        doc["load_average"]["end"] = os.getloadavg()[0]
        write_results(Path(out_dir), doc, pictures)  # after each capture: hours of work are never all lost
        if docs_picture is not None and cap.name in pictures and next(iter(pictures)) == cap.name:
            from nerf2gs_bench.capture_compare import save_small_png

            # the docs' side by side: the first capture whose licence allows renders
            log(f"[bench] {cap.name}'s side by side from above -> {save_small_png(pictures[cap.name][:1], docs_picture)}")
    return doc


def write_results(out_dir: Path, doc: dict, pictures: dict[str, list[Path]]) -> None:
    from nerf2gs_bench.machine import machine_info

    out_dir.mkdir(parents=True, exist_ok=True)
    doc["machine"] = machine_info()
    doc["figure"] = figure(doc, pictures, out_dir / f"{STEM}.png")
    atomic_write_text(out_dir / f"{STEM}.json", json.dumps(doc, indent=1, default=str))
    atomic_write_text(out_dir / f"{STEM}.md", results_md(doc))


def figure(doc: dict, pictures: dict[str, list[Path]], path: Path) -> str:
    """Holes from above per capture (bars), then, for captures whose licence allows it, frames of
    ``ns2gs-render compare``: the target alone and with NeRF views (and StreetNeRF) from the same
    bird's-eye cameras, each under its label."""
    import cv2

    from nerf2gs_plugin.utils.plotting import pyplot, save_figure

    plt = pyplot()
    rows = [(name, f) for name, frames in pictures.items() for f in frames]
    fig = plt.figure(figsize=(11, 2.6 + 2.4 * len(rows)))
    grid = fig.add_gridspec(1 + len(rows), 1, height_ratios=[1.3] + [1.0] * len(rows))
    ax = fig.add_subplot(grid[0, 0])
    caps = doc["captures"]
    xs = range(len(caps))
    for off, key, label, colour in ((-0.25, "target", TARGET, "tab:red"), (0.0, "augmented", AUGMENTED, "tab:blue"),
                                    (0.25, "reference", REFERENCE, "tab:gray")):
        vals = [100 * (c["bev_hole_fraction"][key] or 0.0) for c in caps]
        ax.bar([x + off for x in xs], vals, width=0.25, color=colour, label=label)
    ax.set_xticks(list(xs), [c["capture"] for c in caps])
    ax.set_xlim(-0.6, len(caps) - 0.4 + 1.0)  # room on the right for the legend
    ax.set_ylabel("holes from above (%)", fontsize=8)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title("share of pixels with accumulation < 0.5 from the augmentation's bird's-eye cameras", fontsize=8)
    for r, (name, frame) in enumerate(rows, start=1):
        a = fig.add_subplot(grid[r, 0])
        a.imshow(cv2.imread(str(frame))[..., ::-1])
        a.set_xticks([])
        a.set_yticks([])
        a.set_title(f"{name} from above (ns2gs-render compare, view {frame.stem})", fontsize=8)
    fig.suptitle(f"Real captures from above ({doc['scale']} scale); renders shown only where the licence allows", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    return str(path)


def _f(v: Optional[float], fmt: str = "{:.2f}") -> str:
    return "n/a" if v is None else fmt.format(v)


def label_lines(captures: Sequence[dict]) -> list[str]:
    """What the hand labels measured per capture: which frames, the masks' IoU with precision and recall."""
    out = []
    for c in captures:
        hand = c.get("hand_labels")
        if not hand:
            continue
        m, parts = hand["moving"], []
        if m is None:
            parts.append("no labelled training frame in this run (no moving-object IoU)")
        else:
            parts.append(f"moving-object IoU {m['iou']:.3f} (precision {m['precision']:.2f}, recall {m['recall']:.2f}) "
                         f"on {', '.join(m['frames'])}")
        if hand["static_frames"]:
            st = hand["static"]
            parts.append(f"static PSNR {_f(st[TARGET])} / {_f(st[AUGMENTED])} / {_f(st[REFERENCE])} (target alone / + NeRF "
                         f"views / StreetNeRF) on {', '.join(hand['static_frames'])}")
        else:
            parts.append("no labelled held-out frame in this run (no static PSNR)")
        names = [hand["labels"]] if isinstance(hand["labels"], str) else hand["labels"]  # one name in records before label sets merged
        out.append(f"- {c['capture']} (labels {', '.join(f'`{n}`' for n in names)}): " + "; ".join(parts) + ".")
    return ["", "Hand labels (moving objects drawn by eye; 'ignore' regions and the bonnet count neither way):", ""] + out if out else []


def target_lines(captures: Sequence[dict]) -> list[str]:
    """The street-level and from-above targets per capture, measured (all pixels where no labels exist)."""
    out = []
    for c in captures:
        d = c["static_psnr_delta"] if c["static_psnr_delta"] is not None else c["psnr_delta"]
        h = c["bev_hole_fraction"]
        parts = []
        if d is not None:
            over = "static pixels" if c["static_psnr_delta"] is not None else "all pixels, no labels"
            if c.get("seeds"):
                per = c["static_psnr_delta_per_seed" if c["static_psnr_delta"] is not None else "psnr_delta_per_seed"]
                over += f"; mean of seeds {', '.join(map(str, c['seeds']))}: " + " / ".join(_f(x, "{:+.2f}") for x in per)
            parts.append(f"PSNR with NeRF views {d:+.2f} dB against without ({over}; target >= -0.3: {'met' if d >= -0.3 else 'not met'})")
        if h["target"] is not None and h["augmented"] is not None:
            ratio = h["augmented"] / h["target"] if h["target"] > 0 else 0.0
            parts.append(f"holes from above {ratio:.2f}x the target alone's (target <= 0.2x: {'met' if ratio <= 0.2 else 'not met'})")
        if parts:
            out.append(f"- {c['capture']}: " + "; ".join(parts) + ".")
    return ["Targets (street level keeps its quality; holes from above at most a fifth):", ""] + out if out else []


def truth_lines(captures: Sequence[dict]) -> list[str]:
    """Captures with surveyed cameras: our SfM against them (ATE after Sim(3), the metric scale's error)."""
    out = []
    for c in captures:
        t = c.get("pose_truth")
        if not t:
            continue
        if "error" in t:
            out.append(f"- {c['capture']}: not compared ({t['error']}).")
            continue
        out.append(f"- {c['capture']}: {t['frames_compared']} registered photos against their surveyed cameras: ATE "
                   f"{100 * t['ate_m']:.1f} cm ({t['ate_percent']:.2f}% of the path), rotation {t['rotation_error_deg']:.2f} deg, "
                   f"up {t['up_error_deg']:.1f} deg (against the surveyed vertical); metric scale from the camera height "
                   f"{t['scale_error_percent']:+.1f}% off.")
    return ["", "SfM against ground truth (metres; Sim(3)-aligned):", ""] + out if out else []


def _load_note(load: Optional[dict]) -> str:
    if not load:
        return ""
    return f" (1-minute load average {load['start']:.1f} at the start, {load['end']:.1f} at the end: the seconds are on a shared machine)"


def results_md(doc: dict) -> str:
    from nerf2gs_bench.machine import machine_line

    s = doc["scale_settings"]
    lines = [f"# Real captures through the whole path (`ns2gs-bench real-captures --scale {doc['scale']}`)", "",
             f"Machine: {machine_line(doc.get('machine'))}" + _load_note(doc.get("load_average")), ""]
    if doc["scale"] == "quick":
        lines += [f"**Quick scale**: the first {s['frames']} frames of each capture at about {s['width']} px wide, reference "
                  f"{s['reference_steps']} / StreetNeRF {s['streetnerf_steps']} / Splatfacto {s['splatfacto_steps']} steps: "
                  "a check of the path and of the direction of each measure, not the method's quality at full scale.", ""]
    lines += ["Every 8th frame is held out of every run. Holes from above: share of pixels with accumulation < 0.5 "
              "rendered from the augmentation's own bird's-eye cameras (same height and pitch as the training views).", "",
              "| capture | registered | PSNR StreetNeRF | PSNR splatfacto | PSNR + NeRF views | delta | static delta | "
              "holes target | holes + NeRF views | holes StreetNeRF | moving IoU |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in doc["captures"]:
        p, h = c["psnr"], c["bev_hole_fraction"]
        if c.get("failed"):
            lines.append(f"| {c['capture']} | failed: {c['failed']} |" + " |" * 9)
            continue
        lines.append(f"| {c['capture']} | {100 * c['registered_fraction']:.0f}% | {_f(p[REFERENCE])} | {_f(p[TARGET])} | "
                     f"{_f(p[AUGMENTED])} | {_f(c['psnr_delta'], '{:+.2f}')} | {_f(c['static_psnr_delta'], '{:+.2f}')} | "
                     f"{_f(h['target'] and 100 * h['target'], '{:.1f}%')} | {_f(h['augmented'] and 100 * h['augmented'], '{:.1f}%')} | "
                     f"{_f(h['reference'] and 100 * h['reference'], '{:.1f}%')} | {_f(c['moving_iou'], '{:.2f}')} |")
    seeded = sorted({tuple(c["seeds"]) for c in doc["captures"] if c.get("seeds")})
    if seeded:
        lines += ["", f"The deltas are the means over seeds {', '.join(map(str, seeded[0]))} of the two Splatfacto runs "
                  "(`--seeds`; the StreetNeRF is one); the PSNR and holes columns and the picture are the first seed's."]
    lines += [""] + target_lines(doc["captures"])
    lines += truth_lines(doc["captures"])
    lines += ["", "Static delta: PSNR outside the moving-object masks of the held-out frames, by hand labels (the masks "
              "stage makes masks for the training frames only, so it is n/a unless the held-out frames are labelled). "
              "Moving-object IoU: the masks stage's transient masks against the hand labels of the training frames "
              "(n/a without)."]
    lines += label_lines(doc["captures"])
    lines += ["", "## Captures, provenance and licence", ""]
    for c in doc["captures"]:
        if c.get("failed"):
            lines += [f"- **{c['capture']}** ({c['mount']}): {c['provenance']}. Source: {c['fetch']}. Licence: {c['licence']}. "
                      f"Stopped: {c['failed']}"]
            continue
        saved = set(c.get("reused_stages", []))
        st = ", ".join(f"{k} {_f(v, '{:.0f}')}" + (" (saved)" if k in saved else "") for k, v in c["stage_seconds"].items())
        cov = ", ".join(f"{k} {100 * v:.1f}%" for k, v in (c.get("masks_coverage") or {}).items())
        lines += [f"- **{c['capture']}** ({c['mount']}): {c['provenance']}. Source: {c['fetch']}. Licence: {c['licence']}. "
                  f"{c['options']['frames_used']} frames used, downscale {c['options']['downscale']:g}; "
                  f"{c['metres_per_unit']:.4g} m per SfM unit ({c['scale_source']}). Seconds: {st}. Masks' coverage: {cov or 'n/a'}."]
    lines += [f"- {n}" for n in doc.get("notes", [])]
    lines += ["", "Seconds marked (saved) are those of the stage when it ran: this run reused its output (made by the "
              "same code from the same inputs), so it took ~0 s here.", "",
              f"Picture: `{STEM}.png`: holes from above per capture, then frames of `ns2gs-render compare` (the runs side by "
              "side on the augmentation's bird's-eye views, labelled) of captures whose licence allows renders (Lund, BSD-2; "
              "KITTI and nuScenes are non-commercial share-alike, Herz-Jesu states no licence: measured, not shown)."]
    return "\n".join(lines) + "\n"
