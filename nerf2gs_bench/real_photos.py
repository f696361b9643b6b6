"""``ns2gs-bench real-photos --images DIR``: a real outdoor photo set through the whole path.

``process images`` (pycolmap SfM, ground-plane metric scale from the camera height) -> ``masks``
(``--segmenter auto``) -> StreetNeRF -> Splatfacto -> (the reference check:
the StreetNeRF's measured held-out PSNR against Splatfacto's, logged before the next run) ->
Splatfacto + NeRF views. Every ``holdout_every``-th photo (by name) is held out of every training
run, the masks' first reference included; the table is PSNR / SSIM / LPIPS on those held-out
photos (the "test" split). A real capture has no views from above to score against, so the
bird's-eye views are shown, not scored: each run rendered from cameras ``delta_h`` metres above
held-out photos' cameras, pitched ``theta_pitch`` below the ground plane's horizon (the same
cameras the augmentation uses).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Literal, Optional

from nerf2gs_plugin.utils.io import atomic_write_text

NERF_VIEWS = "splatfacto + NeRF views"
LABELS = ("StreetNeRF", "splatfacto", NERF_VIEWS)
STEM = "real_photos"


@dataclass
class RealPhotosOptions:
    """Capture and training settings of ``ns2gs-bench real-photos`` (short: CPU scale)."""

    images: Path
    """Folder of photos (natural name order = capture order)."""
    provenance: str = ""
    """Where the photos come from (repository, commit, path, licence): written into the results."""
    camera_height: float = 1.6
    """Hand-held: ~1.6 m above the ground (sets the metric scale)."""
    fov_deg: Optional[float] = None
    """Horizontal FOV when the photos carry no EXIF focal."""
    metres_per_unit: Optional[float] = None
    """Metres per SfM unit when the camera-height scale cannot be trusted (see the results' notes)."""
    matching: Literal["auto", "sequential", "exhaustive"] = "auto"
    """SfM matching (as process images --matching)."""
    overlap: int = 10
    """Sequential matching: frames matched with each frame."""
    num_threads: int = -1
    """SfM threads (-1: all cores)."""
    max_features: int = 4096
    """SIFT features per photo."""
    downscale: float = 4.0
    """Training and eval image downscale (images_4)."""
    holdout_every: int = 8
    """Every n-th photo (by name, from the first) is held out of every training run."""
    reference_steps: int = 500
    """Steps of the masks' first reference (StreetNeRF without masks)."""
    streetnerf_steps: int = 1000
    """StreetNeRF's steps (schedules rescaled)."""
    splatfacto_steps: int = 1500
    """Splatfacto's steps, with and without NeRF views."""
    delta_h: float = 3.0
    """Bird's-eye views: metres above the input cameras (the augmentation's and the figure's)."""
    theta_pitch: float = 30.0
    """Bird's-eye views: degrees below the horizon of the ground plane."""
    every_n: int = 1
    """Bird's-eye views from every n-th training pose (CPU time: each is a reference render)."""


def run_overrides(opts: RealPhotosOptions, method: str, steps: int) -> dict:
    from nerf2gs_bench.paper import step_overrides

    dm = {"downscale": opts.downscale, "holdout_every": opts.holdout_every}
    ov = step_overrides(method, steps)
    ov.setdefault("pipeline", {}).setdefault("datamanager", {}).setdefault("dataparser", {}).update(dm)
    return {**ov, "steps_per_eval_image": 0}


def augment_overrides(opts: RealPhotosOptions) -> dict:
    """The ``--augment.*`` of the bench's Splatfacto + NeRF views run."""
    return {"delta_h": opts.delta_h, "theta_pitch": opts.theta_pitch, "every_n": opts.every_n}


def run_specs(opts: RealPhotosOptions, seed: Optional[int] = None, augment: Optional[dict] = None) -> dict:
    """The bench's runs by label: StreetNeRF, Splatfacto alone and with NeRF views (from that StreetNeRF);
    ``seed``: the two Splatfacto runs' training seed (None: the method's default); ``augment``: more
    ``--augment.*`` of the run with NeRF views (a lever measured against the bench's own)."""
    from nerf2gs_bench.runs import RunSpec

    target = run_overrides(opts, "splatfacto", opts.splatfacto_steps)
    if seed is not None:
        target = {**target, "seed": seed}
    return {"StreetNeRF": RunSpec("StreetNeRF", "streetnerf", run_overrides(opts, "streetnerf", opts.streetnerf_steps)),
            "splatfacto": RunSpec("splatfacto", "splatfacto", target),
            NERF_VIEWS: RunSpec(NERF_VIEWS, "splatfacto", target, augment_from="StreetNeRF",
                                augment={**augment_overrides(opts), **(augment or {})})}


def process_photos(opts: RealPhotosOptions, out: Path):
    """``ns2gs-data process images`` (same code path as the CLI) into ``out``."""
    from nerf2gs_plugin.data.process.frames import collect_images, list_images
    from nerf2gs_plugin.data.process.pipeline import ProcessOptions, exif_focal_for, run_process
    from nerf2gs_plugin.data.process.sfm import SfmOptions

    po = ProcessOptions(out=Path(out), camera_height=opts.camera_height, fov_deg=opts.fov_deg, progress=False,
                        metres_per_unit=opts.metres_per_unit,
                        sfm=SfmOptions(matching=opts.matching, overlap=opts.overlap, num_threads=opts.num_threads,
                                       max_features=opts.max_features))
    sources = list_images(opts.images)
    return run_process(lambda d, progress: collect_images(opts.images, d, po.max_size, progress), po, is_video=False,
                       focal_px_fn=lambda d, names: exif_focal_for(sources, d, names))


def run_real_photos(opts: RealPhotosOptions, runs_root: Path, out_dir: Path, rerun: bool = False,
                    log: Callable[[str], None] = print, name: Optional[str] = None) -> dict:
    """The whole bench; writes ``real_photos.{json,md,png}`` into ``out_dir``; returns the JSON document."""
    from nerf2gs_plugin.masking.make_masks import MasksConfig, make_masks
    from nerf2gs_bench.runner import BenchRunner, failure_reason
    from nerf2gs_plugin.eval.reference_check import reference_report

    if not Path(opts.images).is_dir():
        from nerf2gs_plugin.errors import DataError

        raise DataError("photo folder does not exist", opts.images)
    name = name or Path(opts.images).resolve().parent.name
    root = Path(runs_root) / "real_photos" / name
    root.mkdir(parents=True, exist_ok=True)
    stages: dict[str, float] = {}
    t_all = time.perf_counter()

    def timed(stage: str, fn):
        t0 = time.perf_counter()
        out = fn()
        stages[stage] = round(time.perf_counter() - t0, 1)
        return out

    data = root / "data"
    reused: list[str] = []  # stages whose seconds are the saved ones of an earlier run
    report = process_or_reuse(opts, data, stages, reused, rerun, log)
    for line in report.lines():
        log(f"[bench] process: {line}")
    from nerf2gs_bench.real import reference_dir

    # keyed by the processed capture: a re-processed one (another up, other intrinsics) trains its own
    reference = reference_dir(root, data, opts.reference_steps, f"downscale {opts.downscale}")
    masks = masks_or_reuse(opts, data, reference, stages, reused, rerun, log)
    runner = BenchRunner(Path(runs_root), log=log, rerun=rerun)
    specs = run_specs(opts)
    results: dict[str, dict] = {}
    done_runs: dict[str, tuple[Path, str]] = {}
    check = None
    for label in LABELS:
        spec = specs[label]
        ref = done_runs.get(spec.augment_from) if spec.augment_from else None
        if spec.augment_from and ref is None:
            results[label] = {"label": label, "target": spec.method, "failed": True, "error": f"reference run '{spec.augment_from}' failed"}
            continue
        if spec.augment_from and "splatfacto" in done_runs:  # the reference check, said before training on it
            line, check = reference_report(ref[0], done_runs["splatfacto"][0])
            log(f"[bench] {line}")
        log(f"[bench] {label}")
        out = timed(f"train + eval: {label}", lambda: runner.run(spec, data, reference=ref))
        reason = failure_reason(out)
        if reason is None:
            done_runs[label] = (Path(out.run_dir), out.key)
            results[label] = out.result
            own = run_seconds(out.result)
            if own is not None and own > stages[f"train + eval: {label}"]:  # a reused run took ~0 s now: its saved seconds
                stages[f"train + eval: {label}"] = own
                reused.append(f"train + eval: {label}")
        else:
            results[label] = {**(out.result or {}), "label": label, "target": spec.method, "failed": True, "error": reason}
    if check is not None and NERF_VIEWS in done_runs:
        from nerf2gs_plugin.eval.reference_check import write_reference_report

        write_reference_report(done_runs[NERF_VIEWS][0], check)
    figure = None
    if all(lab in done_runs for lab in LABELS):
        figure = timed("figure", lambda: renders_from_above([done_runs[lab][0] for lab in LABELS], list(LABELS),
                                                            Path(out_dir) / f"{STEM}_renders.png", opts))
    doc = {
        "options": {k: str(v) if isinstance(v, Path) else v for k, v in asdict(opts).items()},
        "dataset": name,
        "data": str(data),
        "process": {"frames": report.frames, "registered": report.registered, "points": report.points, "matching": report.matching,
                    "metres_per_unit": report.metres_per_unit, "scale_source": report.scale_source,
                    "stage_seconds": {k: round(v, 1) for k, v in report.stage_seconds.items()}},
        "masks": {k: masks.get(k) for k in ("reference_seconds", "mask_seconds", "coverage", "images")},
        "results": results,
        "reference_check": check,
        "figure": figure,
        "stage_seconds": stages,
        "reused_stages": reused,
        "wall_seconds": round(time.perf_counter() - t_all, 1),
    }
    write_results(out_dir, doc)
    return doc


# ----------------------------------------------------------------------------- stages, reused when their code is unchanged
PROCESS_RECORD = "bench_process.json"
"""Beside the processed dataset: its stage seconds and report, keyed by the frames, options and SfM code."""
MASKS_RECORD = "bench_masks.json"
"""Beside the masks: their seconds, keyed by the reference, options and mask code."""


def process_key(opts: RealPhotosOptions) -> str:
    from nerf2gs_bench.code_version import source_hash
    from nerf2gs_bench.stage_record import stage_key
    from nerf2gs_plugin.data.fingerprint import files_fingerprint
    from nerf2gs_plugin.data.process.frames import list_images

    capture = {k: getattr(opts, k) for k in ("camera_height", "fov_deg", "metres_per_unit", "matching", "overlap", "max_features")}
    return stage_key("process", files_fingerprint(list_images(opts.images), Path(opts.images)), capture, source_hash(("data",)))


def process_or_reuse(opts: RealPhotosOptions, data: Path, stages: dict, reused: list, rerun: bool, log: Callable[[str], None]):
    """``process images`` into ``data``, or its earlier output when frames, options and the SfM code are
    the same (SfM is slow and not bit-repeatable: a rerun should not re-register the capture)."""
    from nerf2gs_bench.stage_record import read_stage, write_stage
    from nerf2gs_plugin.data.process.pipeline import ProcessReport

    key = process_key(opts)
    record = None if rerun or not (data / "transforms.json").is_file() else read_stage(data / PROCESS_RECORD, key)
    if record is not None:
        log(f"[bench] process: reusing {data} (made by the same frames, options and SfM code)")
        stages["process"] = record["seconds"]
        reused.append("process")
        return ProcessReport(out=data, **record["report"])
    t0 = time.perf_counter()
    report = process_photos(opts, data)
    stages["process"] = round(time.perf_counter() - t0, 1)
    fields = {k: getattr(report, k) for k in ("frames", "registered", "points", "matching", "metres_per_unit", "scale_source",
                                              "stage_seconds", "dropped_blurry", "check")}
    write_stage(data / PROCESS_RECORD, key, stages["process"], report=fields)
    return report


def masks_or_reuse(opts: RealPhotosOptions, data: Path, reference: Path, stages: dict, reused: list, rerun: bool,
                   log: Callable[[str], None]) -> dict:
    """The masks of ``data`` (reference first), or the earlier ones when made from the same reference
    by the same mask code."""
    from nerf2gs_bench.code_version import source_hash
    from nerf2gs_bench.stage_record import read_stage, stage_key, write_stage
    from nerf2gs_plugin.masking.make_masks import MasksConfig, make_masks

    from nerf2gs_plugin.masks.motion import is_sequence

    # a sequence gets the motion route too: the same reference makes other masks for it
    sequence = is_sequence(json.loads((data / "transforms.json").read_text()))
    key = stage_key("masks", str(reference), opts.reference_steps, opts.downscale, sequence, source_hash(("masks", "masking")))
    masks_json = data / "masks" / "masks.json"
    done = json.loads(masks_json.read_text()) if masks_json.is_file() else {}
    record = read_stage(data / "masks" / MASKS_RECORD, key)
    if not rerun and record is not None and done.get("reference") == str(reference):
        log(f"[bench] reusing the masks of {data / 'masks'} (reference {reference}, same mask code)")
        stages["masks"] = record["seconds"]
        reused.append("masks")
        return done
    t0 = time.perf_counter()
    masks = make_masks(MasksConfig(data=data, reference=reference, reference_steps=opts.reference_steps, downscale=opts.downscale,
                                   splits=("train",), overwrite=True, progress=False), log=log)
    stages["masks"] = round(time.perf_counter() - t0, 1)
    write_stage(data / "masks" / MASKS_RECORD, key, stages["masks"])
    return masks


def run_seconds(result: Optional[dict]) -> Optional[float]:
    """A run's own training + evaluation seconds (saved with it when they ran); None when not saved."""
    if not result:
        return None
    train = (result.get("trained") or {}).get("seconds")
    evaluate = (result.get("measured") or {}).get("seconds")
    return None if train is None or evaluate is None else round(train + evaluate, 1)


# ----------------------------------------------------------------------------- renders from above
def _above_cameras(run, opts: RealPhotosOptions, views: int, split: str = "test"):
    """Held-out photos' cameras (and photos) and the bird's-eye cameras above them, in ``run``'s frame."""
    from nerf2gs_plugin.augment.geometry import ViewGeometry

    dm = run.pipeline.datamanager
    td = dm.train_data
    pairs = list(dm.eval_images(split))
    step = max(1, len(pairs) // max(views, 1))
    picked = pairs[::step][:views]
    geometry = ViewGeometry(opts.delta_h, opts.theta_pitch, pitch_mode="absolute")
    above = [geometry.cameras(cam, td) for cam, _ in picked]
    return picked, above


def renders_from_above(run_dirs: list[Path], labels: list[str], path: Path, opts: RealPhotosOptions, views: int = 2,
                       split: str = "test") -> str:
    """Rows per held-out photo: the photo and each run's render of it, then each run's render from
    ``delta_h`` m above it (no photo exists there)."""
    import torch

    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.utils.plotting import pyplot, save_figure

    plt = pyplot()
    cols = ["held-out photo"] + list(labels)
    grid: list[list] = []
    names: list[str] = []
    with torch.no_grad():
        for k, rd in enumerate(run_dirs):
            run = load_run(rd)
            run.model.eval()
            picked, above = _above_cameras(run, opts, views, split)
            for v, ((cam, batch), up_cam) in enumerate(zip(picked, above)):
                if k == 0:
                    grid += [[batch["image"].cpu()] + [None] * len(labels), [None] * (len(labels) + 1)]
                    names += [f"held-out view {v + 1}: street", f"{opts.delta_h:g} m above, {opts.theta_pitch:g} deg down"]
                grid[2 * v][k + 1] = run.model.render_camera(cam)["rgb"].clamp(0, 1).cpu()
                grid[2 * v + 1][k + 1] = run.model.render_camera(up_cam)["rgb"].clamp(0, 1).cpu()
    fig, axes = plt.subplots(len(grid), len(cols), figsize=(3.0 * len(cols), 2.2 * len(grid) + 0.4), squeeze=False)
    for r, row in enumerate(grid):
        for c, img in enumerate(row):
            ax = axes[r][c]
            ax.set_xticks([])
            ax.set_yticks([])
            if img is None:
                ax.axis("off")
            else:
                ax.imshow(img.numpy())
            if r == 0:
                ax.set_title(cols[c], fontsize=9)
            if c == 1:
                ax.set_ylabel(names[r], fontsize=7)
    fig.suptitle("Held-out photos and the same places seen from above (no photo exists there)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    return str(path)


# ----------------------------------------------------------------------------- output
def _fmt(v: Optional[float], f: str) -> str:
    return "n/a" if v is None else f.format(v)


def held_out_table(results: dict[str, dict]) -> str:
    """``| method |`` table of the held-out photos: PSNR / SSIM / LPIPS (mean over the views)."""
    lines = ["| method | held-out photos | PSNR held-out | SSIM held-out | LPIPS held-out | train s |", "|---|---|---|---|---|---|"]
    for label, r in results.items():
        if r.get("failed"):
            lines.append(f"| {label} | failed: {str(r.get('error')).replace('|', '/')[:120]} | - | - | - | - |")
            continue
        t = r["results"].get("test", {})
        lines.append(f"| {label} | {t.get('num_images', 0)} | {_fmt(t.get('psnr'), '{:.2f}')} | {_fmt(t.get('ssim'), '{:.3f}')} | "
                     f"{_fmt(t.get('lpips'), '{:.3f}')} | {_fmt(r.get('train_seconds'), '{:.0f}')} |")
    return "\n".join(lines)


def _test_psnr(r: Optional[dict], key: str = "psnr"):
    """A run's held-out-photo PSNR (``key``: "psnr" the mean, "psnr_per_image" the list); None if it failed or has none."""
    return None if not r or r.get("failed") else r["results"].get("test", {}).get(key)


def target_lines(results: dict[str, dict]) -> list[str]:
    """The reference check's two targets on the held-out photos, measured."""
    nerf, base, aug = (_test_psnr(results.get(k)) for k in LABELS)
    out = []
    if nerf is not None and base is not None:
        d = nerf - base
        out.append(f"- StreetNeRF within 0.5 dB of Splatfacto: {d:+.2f} dB ({'met' if d >= -0.5 else 'not met'}).")
    if aug is not None and base is not None:
        d = aug - base
        out.append(f"- Splatfacto + NeRF views not below Splatfacto: {d:+.2f} dB ({'met' if d >= 0 else 'not met'}).")
    return ["Targets of issue 18 point 5 on the held-out photos:", ""] + out if out else []


def per_photo_lines(results: dict[str, dict]) -> list[str]:
    """Each method's PSNR per held-out photo: with four photos one lost view moves the mean by dBs."""
    out = []
    for label in LABELS:
        per = _test_psnr(results.get(label), "psnr_per_image")
        if per:
            out.append(f"- {label}: " + " / ".join(f"{v:.2f}" for v in per))
    return ["PSNR per held-out photo (in name order):", ""] + out if out else []


def results_md(doc: dict) -> str:
    from nerf2gs_bench.machine import machine_line

    o, p = doc["options"], doc["process"]
    lines = [
        f"# A real outdoor photo set through the whole path (`ns2gs-bench real-photos`): {doc['dataset']}", "",
        f"Machine: {machine_line(doc.get('machine'))}", "",
        f"Photos: `{o['images']}`. {o['provenance']}", "",
        f"process images (`--camera-height {o['camera_height']}" + (f" --fov-deg {o['fov_deg']}" if o.get("fov_deg") else "")
        + (f" --metres-per-unit {o['metres_per_unit']}" if o.get("metres_per_unit") else "")
        + f" --matching {o['matching']}`) -> masks (auto, reference {o['reference_steps']} steps at downscale {o['downscale']:g}) -> "
        f"StreetNeRF ({o['streetnerf_steps']} steps) -> Splatfacto ({o['splatfacto_steps']} steps) with and without NeRF views "
        f"(`--augment.delta-h {o['delta_h']:g} --augment.theta-pitch {o['theta_pitch']:g} --augment.every-n {o.get('every_n', 1)}`); downscale {o['downscale']:g}; every "
        f"{o['holdout_every']}th photo held out of every run (the masks' reference included).", "",
        f"SfM: {p['registered']} of {p['frames']} photos registered, {p['points']} sparse points, matching {p['matching']}; "
        f"{p['metres_per_unit']:.4g} metres per SfM unit ({p['scale_source']}).", "",
        "Held-out photos (PSNR / SSIM / LPIPS, mean over the held-out views):", "",
        held_out_table(doc["results"]), "",
    ]
    per_photo = per_photo_lines(doc["results"])
    lines += per_photo + [""] if per_photo else []
    lines += target_lines(doc["results"]) + [""]
    if doc.get("reference_check"):
        lines += [f"Reference check, logged before Splatfacto + NeRF views trained: {doc['reference_check']['line']}", ""]
    if doc.get("figure"):
        lines += [f"Renders from above: `{Path(doc['figure']).name}`.", ""]
    lines += ["Time per stage (s): " + ", ".join(f"{k} {v}" for k, v in doc["stage_seconds"].items()),
              "", "SfM stages (s): " + ", ".join(f"{k} {v}" for k, v in p["stage_seconds"].items())
              + (" (stages near 0 s were reused from an earlier run in the same folder: the COLMAP database is resumable)"
                 if min(p["stage_seconds"].get(k, 1.0) for k in ("features", "matching")) < 1.0 else ""),
              "", f"Masks: reference {doc['masks'].get('reference_seconds')} s, masks {doc['masks'].get('mask_seconds')} s; coverage "
              + ", ".join(f"{k} {100 * v:.1f}%" for k, v in (doc["masks"].get("coverage") or {}).items()),
              "", f"Bench wall time: {doc['wall_seconds']:.0f} s (runs reused where cached)."]
    return "\n".join(lines) + "\n"


def write_results(out_dir: Path, doc: dict) -> None:
    from nerf2gs_bench.machine import machine_info

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    doc["machine"] = machine_info()
    atomic_write_text(out_dir / f"{STEM}.json", json.dumps(doc, indent=1, default=str))
    atomic_write_text(out_dir / f"{STEM}.md", results_md(doc))


def rewrite_markdown(out_dir: Path) -> Path:
    """``real_photos.md`` again from ``real_photos.json`` (after a change to the Markdown only)."""
    doc = json.loads((Path(out_dir) / f"{STEM}.json").read_text())
    atomic_write_text(Path(out_dir) / f"{STEM}.md", results_md(doc))
    return Path(out_dir) / f"{STEM}.md"
