"""stability: every method under stress, failures counted and shown, never hidden.

Cases per method: 3 seeds (mean and std), pose noise (0.5 deg / 5 cm on every training camera),
half the training views, twice the transients (synthetic street only: twice the cars), no masks,
no sparse points (random initialisation). Datasets for the stress cases are perturbed copies of
the bench's dataset (:mod:`nerf2gs_plugin.eval.perturb`).

Outcomes: ``ok``; ``diverged`` (training stopped on NaN/inf; the last good checkpoint is kept by
the trainer); ``nan`` (metrics not finite); ``collapse`` (a quality collapse: street or BEV PSNR
more than :data:`COLLAPSE_DB` = 3 dB below the mean of the same method's unstressed seed runs, or
a final PSNR below the untrained model's on the same eval images); ``error`` (any other error);
``unsupported`` (the data layer cannot make that stress, e.g. more transients in a user dataset).
"""

from __future__ import annotations

import dataclasses
import json
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.eval.bench_io import (BenchLog, BenchProgress, BenchRunner, fmt, mean_psnr, nonfinite_metrics, planned_steps,
                                         progress_log, write_bench_files)
from nerf2gs_plugin.eval.bench_runs import RunSpec
from nerf2gs_plugin.eval.perturb import Perturbation, perturbed_copy
from nerf2gs_plugin.utils.image_metrics import psnr
from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.errors import DataError, UserError
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.utils.plotting import pyplot, save_figure

METHODS = ("streetnerf", "splatfacto", "scaffold-gs", "2dgs")
SEEDS = 3  # runs per method with different seeds
STATUSES = ("ok", "diverged", "nan", "collapse", "error", "unsupported")
FAILURES = ("diverged", "nan", "collapse", "error")
COLLAPSE_DB = 3.0  # a case more than this far below the unstressed runs' mean PSNR (street or BEV) failed


@dataclass
class StressCase:
    """One training run of the stability bench."""

    method: str
    variant: str  # "seed 0", "pose noise", ...
    seed: int = 0
    perturbation: Optional[Perturbation] = None
    transients_factor: int = 1
    overrides: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return f"{self.method} / {self.variant}"


def stability_plan(scale: str, methods=METHODS, seeds: Optional[tuple[int, ...]] = None) -> list[StressCase]:
    """The cases, in the order they are trained and reported (seeds first, then stresses).

    Seeds default to the method's own seed and the next two; the run at the method's own seed on
    the unperturbed dataset is the paper-table baseline run (same key), so it is trained once."""
    from nerf2gs_plugin.eval.bench_paper import _overrides
    from nerf2gs_plugin.registry import get_method

    stresses = [
        ("pose noise 0.5deg/5cm", Perturbation(rotation_deg=0.5, translation_m=0.05, seed=7), 1),
        ("half views", Perturbation(keep_every=2), 1),
        ("2x transients", None, 2),
        ("no masks", Perturbation(drop_masks=True), 1),
        ("random init", Perturbation(drop_points=True), 1),
    ]
    plan = []
    for m in methods:
        base = _overrides(scale, m)
        own = get_method(m).config.seed
        method_seeds = seeds or tuple(own + i for i in range(SEEDS))
        with_seed = lambda s: base if s == own else {**base, "seed": s}  # noqa: E731
        for s in method_seeds:
            plan.append(StressCase(m, f"seed {s}", s, None, 1, with_seed(s)))
        for name, pert, factor in stresses:
            plan.append(StressCase(m, name, method_seeds[0], pert, factor, with_seed(method_seeds[0])))
    return plan


def classify(result: Optional[dict], error: Optional[str], initial_psnr: Optional[float], final_psnr: Optional[float]) -> str:
    """The outcome of one case (see the module docstring). An error or non-finite metrics fail a
    case exactly as they fail a paper-table run (:func:`~nerf2gs_plugin.eval.bench_io.failure_reason`);
    collapse is this bench's extra check."""
    if error is not None:
        if error.startswith("unsupported"):
            return "unsupported"
        if error.startswith("TrainingDiverged") or "non-finite" in error or "diverged" in error:
            return "diverged"
        return "error"
    if result is None:
        return "error"
    if final_psnr is None or nonfinite_metrics(result) or not math.isfinite(final_psnr):  # as the table benches
        return "nan"
    if initial_psnr is not None and math.isfinite(initial_psnr) and final_psnr < initial_psnr:
        return "collapse"
    return "ok"


def images_psnr(model, datamanager, split: str, count: int = 2) -> Optional[float]:
    """Mean PSNR of the first ``count`` images of ``split`` (the collapse check's fixed images)."""
    import torch


    vals = []
    with torch.no_grad():
        for i, (camera, batch) in enumerate(datamanager.eval_images(split)):
            if i >= count:
                break
            vals.append(float(psnr(model.render_camera(camera)["rgb"].clamp(0, 1), batch["image"])))
    return sum(vals) / len(vals) if vals else None


def initial_psnr(spec: RunSpec, data: Path, split: str, device) -> Optional[float]:
    """PSNR of the model as set up for training (step 0), on the collapse check's images."""
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = apply_plain(get_method(spec.method).config, spec.overrides, where=f"stability run {spec.label}")
    cfg = dataclasses.replace(cfg, data=Path(data), progress=False, device=str(device))
    trainer = Trainer(cfg)
    trainer.setup()
    trainer.pipeline.model.eval()
    return images_psnr(trainer.pipeline.model, trainer.pipeline.datamanager, split)


def case_dataset(case: StressCase, data: Path, runs_root: Path, synthetic: bool) -> Path:
    """The dataset a case trains on: the bench's, a perturbed copy, or a street with more cars."""
    if case.transients_factor > 1:
        if not synthetic:
            raise DataError("unsupported: more transients needs the embedded synthetic street (no --data)", data)
        from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

        cars = SynthStreetConfig().num_cars * case.transients_factor
        path = Path(runs_root) / "data" / f"{Path(data).name}-{cars}cars"
        if not (path / "transforms.json").is_file():
            generate_street(SynthStreetConfig(out=path, num_cars=cars, progress=False))
        return path
    if case.perturbation is None:
        return Path(data)
    if not (Path(data) / "transforms.json").is_file():
        raise DataError("unsupported: this stress writes a perturbed transforms.json; the dataset has none (COLMAP?)", data)
    return perturbed_copy(data, Path(runs_root) / "data", case.perturbation)


def run_case(case: StressCase, data: Path, runner: BenchRunner, synthetic: bool, step_hook=None) -> dict:
    """Train/evaluate one case (reusing earlier work) and classify it."""
    from nerf2gs_plugin.engine.reference import load_run

    spec = RunSpec(case.label, case.method, case.overrides)
    try:
        case_data = case_dataset(case, data, runner.runs_root, synthetic)
    except UserError as e:
        msg = str(e)
        return {"method": case.method, "variant": case.variant, "status": "unsupported" if "unsupported" in msg else "error", "error": msg}
    out = runner.run(spec, case_data, step_hook=step_hook)
    split = "street"
    row: dict[str, Any] = {"method": case.method, "variant": case.variant, "data": str(case_data), "error": out.error}
    first = final = None
    if out.result is not None:
        split = next(iter(out.result["results"]), split)
        check = Path(out.run_dir) / "stability_check.json"
        if check.is_file():
            first, final = json.loads(check.read_text())["psnr"]
        else:
            try:
                first = initial_psnr(spec, case_data, split, runner.device)
                run = load_run(Path(out.run_dir), device=runner.device)
                final = images_psnr(run.model, run.pipeline.datamanager, split)
                atomic_write_text(check, json.dumps({"split": split, "psnr": [first, final]}))
            except (UserError, RuntimeError, ValueError) as e:
                out.error = f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"
    row["status"] = classify(out.result, out.error, first, final)
    row.update(initial_psnr=first, final_psnr=final, run_dir=out.run_dir)
    if out.result is not None:
        r = out.result
        row.update(street_psnr=mean_psnr(r, ("street",)), bev_psnr=mean_psnr(r, ("bev_1", "bev_2")),
                   ssim=_mean([v.get("ssim") for v in r["results"].values()]), primitives=r["size"]["primitives"],
                   train_seconds=r.get("train_seconds"))
    return row


def _mean(vals) -> Optional[float]:
    vals = [v for v in vals if isinstance(v, (int, float)) and math.isfinite(v)]
    return sum(vals) / len(vals) if vals else None


def mark_collapses(rows: list[dict], drop_db: float = COLLAPSE_DB) -> list[dict]:
    """Rows with every ``ok`` case whose street or BEV PSNR lies more than ``drop_db`` below its
    method's unstressed mean (the ``ok`` seed runs) turned into ``collapse``, the drop in ``error``.
    Pure: works on a fresh bench's rows and on the rows of a committed stability.json alike."""
    base: dict[str, dict[str, float]] = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        seeds = [r for r in rows if r["method"] == m and r["variant"].startswith("seed ") and r["status"] == "ok"]
        for name in ("street_psnr", "bev_psnr"):
            vals = [r[name] for r in seeds if isinstance(r.get(name), (int, float)) and math.isfinite(r[name])]
            if vals:
                base.setdefault(m, {})[name] = statistics.fmean(vals)
    out = []
    for r in rows:
        r = dict(r)
        if r["status"] == "ok":
            drops = {name: mean - r[name] for name, mean in base.get(r["method"], {}).items()
                     if isinstance(r.get(name), (int, float))}
            bad = {k: d for k, d in drops.items() if d > drop_db}
            if bad:
                r["status"] = "collapse"
                r["error"] = "; ".join(f"{k.split('_')[0]} PSNR {d:.2f} dB below the unstressed mean" for k, d in bad.items())
        out.append(r)
    return out


def summarize(rows: list[dict]) -> dict[str, dict]:
    """Per method: seed mean/std of street and BEV PSNR, and failures counted by kind."""
    out: dict[str, dict] = {}
    for row in rows:
        s = out.setdefault(row["method"], {"cases": 0, "failures": 0, **{k: 0 for k in STATUSES}, "seed_street": [], "seed_bev": []})
        s["cases"] += 1
        s[row["status"]] += 1
        s["failures"] += row["status"] in FAILURES
        if row["variant"].startswith("seed ") and row["status"] == "ok":
            for key, name in (("seed_street", "street_psnr"), ("seed_bev", "bev_psnr")):
                if row.get(name) is not None:
                    s[key].append(row[name])
    for s in out.values():
        for key in ("seed_street", "seed_bev"):
            vals = s.pop(key)
            s[f"{key}_mean"] = statistics.fmean(vals) if vals else None
            s[f"{key}_std"] = statistics.pstdev(vals) if len(vals) > 1 else (0.0 if vals else None)
            s[f"{key}_n"] = len(vals)
    return out


def markdown(rows: list[dict], summary: dict[str, dict]) -> str:
    lines = ["## Outcomes", "", "| method | case | outcome | street PSNR | BEV PSNR | SSIM | PSNR step 0 -> end | primitives | train s | note |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        status = r["status"] if r["status"] in ("ok", "unsupported") else f"**{r['status'].upper()}**"
        prog = f"{fmt(r.get('initial_psnr'))} -> {fmt(r.get('final_psnr'))}" if r.get("final_psnr") is not None else "n/a"
        note = (r.get("error") or "").replace("|", "/")[:120]
        lines.append(f"| {r['method']} | {r['variant']} | {status} | {fmt(r.get('street_psnr'))} | {fmt(r.get('bev_psnr'))} | "
                     f"{fmt(r.get('ssim'), 3)} | {prog} | {r.get('primitives', 'n/a')} | {fmt(r.get('train_seconds'), 0)} | {note} |")
    lines += ["", "## Per method", "", "| method | seeds: street PSNR mean +- std | seeds: BEV PSNR mean +- std | failures | "
              + " | ".join(FAILURES) + " | unsupported |", "|---|---|---|---|" + "---|" * (len(FAILURES) + 1)]
    for m, s in summary.items():
        st = f"{fmt(s['seed_street_mean'])} +- {fmt(s['seed_street_std'])} (n={s['seed_street_n']})"
        bev = f"{fmt(s['seed_bev_mean'])} +- {fmt(s['seed_bev_std'])} (n={s['seed_bev_n']})"
        counts = " | ".join(str(s[k]) for k in FAILURES)
        lines.append(f"| {m} | {st} | {bev} | {s['failures']}/{s['cases'] - s['unsupported']} | {counts} | {s['unsupported']} |")
    lines += ["", "Failures: diverged = training stopped on NaN/inf (last good checkpoint kept); nan = non-finite metrics; "
              f"collapse = street or BEV PSNR more than {COLLAPSE_DB:g} dB below the mean of the method's unstressed seed runs, "
              "or final PSNR below the untrained model's on the same eval images; error = any other error."]
    return "\n".join(lines)


def log_line(label: str, rows: list[dict]) -> str:
    """The log line of the last row, with collapses already marked against the seed runs so far
    (the plan trains seeds first), so the log says what the table will say."""
    row = mark_collapses(rows)[-1]
    return f"[stability] {label}: {row['status']}" + (f" ({row['error']})" if row.get("error") else "")


def run(plan: list[StressCase], data: Path, runs_root: Path, out_dir: Path, scale: str, synthetic: bool,
        log: Optional[Callable[[str], None]] = None, rerun: bool = False) -> dict:
    """Run every case (one progress bar over the bench, log in <runs>/logs/stability.log), write
    stability.{json,md,png}; returns the JSON payload."""
    log_file = BenchLog(runs_root, "stability")
    rows = []
    with make_progress() as progress:
        bar = BenchProgress(progress, "stability", [planned_steps(c.method, c.overrides) for c in plan])
        logger = log or progress_log(progress, log_file)
        runner = BenchRunner(runs_root, log=logger, rerun=rerun)
        for i, case in enumerate(plan):
            bar.start(i, case.label)
            rows.append(run_case(case, data, runner, synthetic, step_hook=bar.hook))
            logger(log_line(case.label, rows))
            bar.finish(i)
    payload = write_outputs(rows, out_dir, scale, str(data))
    return payload


def write_outputs(rows: list[dict], out_dir: Path, scale: str, data: str, machine: Optional[dict] = None) -> dict:
    """Collapses marked, summary, stability.{json,md,png} written; returns the JSON payload."""
    rows = mark_collapses(rows)
    summary = summarize(rows)
    title = f"Stability under stress, {Path(data).name} ({scale} scale)"
    payload = {"scale": scale, "data": data, "collapse_db": COLLAPSE_DB, "rows": rows, "summary": summary}
    md = write_bench_files(out_dir, "stability", title, payload, markdown(rows, summary) + "\n\n![stability](stability.png)\n",
                           machine=machine)
    chart(rows, Path(out_dir) / "stability.png", title)
    print(md)
    return payload


def regenerate(results_json: Path, out_dir: Path) -> dict:
    """Rewrite stability.{json,md,png} from a committed stability.json's rows (no training): how the
    committed results got the current failure definition. The machine line stays the one it ran on."""
    d = json.loads(Path(results_json).read_text())
    rows = [{**r, "status": "ok", "error": None} if r["status"] == "collapse" and "unstressed mean" in (r.get("error") or "")
            else r for r in d["rows"]]
    return write_outputs(rows, out_dir, d["scale"], d["data"], machine=d["machine"])


def chart(rows: list[dict], path: Path, title: str) -> None:
    """BEV PSNR per case and method (failed cases drawn as red crosses at the axis floor)."""
    plt = pyplot()
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, ax = plt.subplots(figsize=(max(7, 0.9 * len(variants) * max(1, len(methods)) / 2), 4.4))
    vals = [r["bev_psnr"] for r in rows if r.get("bev_psnr") is not None and math.isfinite(r["bev_psnr"])]
    floor = (min(vals) - 2) if vals else 0.0
    width = 0.8 / max(1, len(methods))
    for k, m in enumerate(methods):
        for i, v in enumerate(variants):
            r = next((x for x in rows if x["method"] == m and x["variant"] == v), None)
            if r is None or r["status"] == "unsupported":
                continue
            x = i + (k - (len(methods) - 1) / 2) * width
            if r["status"] == "ok":
                if r.get("bev_psnr") is None:
                    continue
                ax.bar([x], [r["bev_psnr"] - floor], width, bottom=floor, color=plt.get_cmap("tab10")(k), label=m if i == 0 else None)
            else:
                ax.scatter([x], [floor + 0.3], marker="x", color="red", s=60, zorder=3, label="failed" if k == 0 and i == 0 else None)
    ax.set_xticks(range(len(variants)))
    ax.set_xticklabels(variants, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("bird's-eye PSNR (dB)")
    ax.legend(fontsize=7)
    ax.grid(axis="y", alpha=0.3)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
