"""stability: every method under stress, swept level by level to its breaking point.

Cases per method: 3 seeds (mean and std: the unstressed baseline), then each stress of
:mod:`nerf2gs_bench.stability_levels` walked mild -> harsh (pose noise, fraction of views
kept, transient share, mask errors (erosion, dilation, drop: one ladder each), per-frame exposure, random init; for "target + NeRF views"
also the reference's training length, the reference always trained on the stressed data). A
stress stops at its first failure, its breaking point (:mod:`nerf2gs_bench.breaking_point`).
Datasets for the stress cases are perturbed copies of the bench's dataset
(:mod:`nerf2gs_bench.perturb`); runs are reused from the bench's runs folder by key.

Outcomes: ``ok``; ``diverged`` (training stopped on NaN/inf; the last good checkpoint is kept by
the trainer); ``nan`` (metrics not finite); ``collapse`` (a quality collapse: street or BEV PSNR
more than :data:`COLLAPSE_DB` = 3 dB below the mean of the same method's unstressed seed runs, or
a final PSNR below the untrained model's on the same eval images); ``error`` (any other error,
its kind given); ``unsupported`` (the data layer cannot make that stress, e.g. more transients in
a user dataset).
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
from nerf2gs_bench.runner import (BenchLog, BenchProgress, BenchRunner, failure_reason, fmt, mean_psnr, nonfinite_metrics,
                                         planned_steps, progress_log, write_bench_files)
from nerf2gs_bench.runs import RunSpec
from nerf2gs_bench.breaking_point import (COLLAPSE_DB, FAILURES, breaking_markdown, breaking_points, level_chart,
                                               mark_collapses, sweep)
from nerf2gs_bench.perturb import Perturbation, perturbed_copy
from nerf2gs_bench.stability_levels import AUGMENTED_LABEL, REFERENCE_METHOD, STRESS_LEVELS, parse_method, stresses_for
from nerf2gs_plugin.utils.image_metrics import psnr
from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.errors import ConfigError, DataError, UserError
from nerf2gs_plugin.progress import make_progress

__all__ = ["COLLAPSE_DB", "FAILURES", "mark_collapses", "StressCase", "stability_plan", "run", "classify"]

METHODS = ("streetnerf", "splatfacto", "scaffold-gs", "2dgs", "splatfacto+nerf")
SEEDS = 3  # runs per method with different seeds
STATUSES = ("ok", "diverged", "nan", "collapse", "error", "unsupported")


@dataclass
class StressCase:
    """One training run of the stability bench."""

    method: str  # the registered method trained (the target, for an augmented case)
    variant: str  # "seed 0", "pose noise 1deg/10cm", ...
    seed: int = 0
    perturbation: Optional[Perturbation] = None
    transients_factor: int = 1
    overrides: dict[str, Any] = field(default_factory=dict)
    stress: str = ""  # "" for the seed runs (and hand-made single cases)
    level: int = 0  # 1-based rung of the stress; 0 unstressed
    level_label: str = ""
    reference_overrides: Optional[dict[str, Any]] = None
    """Set for "target + NeRF views": the reference (StreetNeRF) trained with these on the same data."""

    @property
    def label_method(self) -> str:
        """The method as the tables name it (``splatfacto + NeRF views`` for an augmented case)."""
        return self.method + (AUGMENTED_LABEL if self.reference_overrides is not None else "")

    @property
    def label(self) -> str:
        return f"{self.label_method} / {self.variant}"


def steps_overrides(scale: str, method: str, fraction: float = 1.0) -> dict:
    """The bench overrides of ``method`` at ``scale`` with its steps times ``fraction`` (schedules
    rescaled); fraction 1 is exactly the paper table's run (same key: trained once)."""
    from nerf2gs_bench.paper import SCALE_STEPS, _overrides, step_overrides
    from nerf2gs_plugin.registry import get_method

    if fraction == 1.0:
        return _overrides(scale, method)
    if not 0.0 < fraction <= 1.0:
        raise ConfigError(f"--steps-fraction {fraction}: must be in (0, 1]")
    steps = SCALE_STEPS.get(scale, {}).get(method) or get_method(method).config.max_num_iterations
    return {**step_overrides(method, max(1, round(steps * fraction))), "steps_per_eval_image": 0}


def stability_plan(scale: str, methods=METHODS, seeds: Optional[tuple[int, ...]] = None, stresses: Optional[tuple[str, ...]] = None,
                   steps_fraction: float = 1.0, n_seeds: int = SEEDS) -> list[StressCase]:
    """The cases, in the order they are trained and reported: per method its seed runs, then each
    stress's levels mild -> harsh (the sweep skips a stress's levels after its first failure).

    Seeds default to the method's own seed and the next ``n_seeds - 1``; the run at the method's
    own seed on the unperturbed dataset is the paper-table baseline run (same key), so it is
    trained once. Methods: registered names, or ``<target>+nerf`` for the augmented pipeline.
    Bad names fail here, before any work."""
    from nerf2gs_plugin.registry import get_method

    plan = []
    for name in methods:
        bm = parse_method(name)
        m = bm.method
        names = stresses_for(bm, stresses)
        base = steps_overrides(scale, m, steps_fraction)
        ref_full = steps_overrides(scale, REFERENCE_METHOD, steps_fraction) if bm.augmented else None
        own = get_method(m).config.seed
        method_seeds = seeds or tuple(own + i for i in range(max(1, n_seeds)))
        with_seed = lambda s: base if s == own else {**base, "seed": s}  # noqa: E731
        for s in method_seeds:
            plan.append(StressCase(m, f"seed {s}", s, None, 1, with_seed(s), reference_overrides=ref_full))
        for stress in names:
            for i, lv in enumerate(STRESS_LEVELS[stress], 1):
                ref = None
                if bm.augmented:
                    ref = ref_full if lv.reference_steps_fraction == 1.0 else \
                        steps_overrides(scale, REFERENCE_METHOD, steps_fraction * lv.reference_steps_fraction)
                plan.append(StressCase(m, lv.variant(stress), method_seeds[0], lv.perturbation, lv.transients_factor,
                                       with_seed(method_seeds[0]), stress, i, lv.label, ref))
    return plan


def classify(result: Optional[dict], error: Optional[str], initial_psnr: Optional[float], final_psnr: Optional[float]) -> str:
    """The outcome of one case (see the module docstring). An error or non-finite metrics fail a
    case exactly as they fail a paper-table run (:func:`~nerf2gs_bench.runner.failure_reason`);
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
    """Train/evaluate one case (reusing earlier work) and classify it. An augmented case first
    trains (or reuses) its reference on the same, stressed, dataset."""
    from nerf2gs_plugin.runs.load import load_run

    spec = RunSpec(case.label, case.method, case.overrides)
    tags = {"stress": case.stress or None, "level": case.level, "level_label": case.level_label or None}
    try:
        case_data = case_dataset(case, data, runner.runs_root, synthetic)
    except UserError as e:
        msg = str(e)
        return {"method": case.label_method, "variant": case.variant, **tags,
                "status": "unsupported" if "unsupported" in msg else "error", "error": msg}
    reference = None
    if case.reference_overrides is not None:
        ref_spec = RunSpec(f"{REFERENCE_METHOD} for {case.label}", REFERENCE_METHOD, case.reference_overrides)
        ref = runner.run(ref_spec, case_data)
        reason = failure_reason(ref)
        if reason is not None:
            error = f"reference failed: {reason}"
            return {"method": case.label_method, "variant": case.variant, **tags, "data": str(case_data),
                    "status": classify(None, error, None, None), "error": error}
        reference = (Path(ref.run_dir), ref.key)
        spec = RunSpec(case.label, case.method, case.overrides, augment_from=ref_spec.label)
    out = runner.run(spec, case_data, reference=reference, step_hook=step_hook)
    split = "street"
    row: dict[str, Any] = {"method": case.label_method, "variant": case.variant, **tags, "data": str(case_data), "error": out.error}
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
    if row["status"] == "collapse" and row["error"] is None:
        row["error"] = f"final PSNR {final:.2f} below the untrained model's {first:.2f} on the same images"
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
    """Sweep the plan (one progress bar over the bench, log in <runs>/logs/stability.log): each
    method x stress stops at its first failure; write stability.{json,md,png}; returns the payload."""
    log_file = BenchLog(runs_root, "stability")
    with make_progress() as progress:
        bar = BenchProgress(progress, "stability", [planned_steps(c.method, c.overrides, {} if c.reference_overrides is not None else None) for c in plan])
        logger = log or progress_log(progress, log_file)
        runner = BenchRunner(runs_root, log=logger, rerun=rerun)

        def run_one(i: int, case: StressCase) -> dict:
            bar.start(i, case.label)
            return run_case(case, data, runner, synthetic, step_hook=bar.hook)

        def on_row(case: StressCase, rows: list[dict]) -> None:
            logger(log_line(case.label, rows))
            bar.finish(plan.index(case))

        rows = sweep(plan, run_one, lambda c: (c.label_method, c.stress) if c.stress else None, on_row)
        skipped = len(plan) - len(rows)
        if skipped:
            logger(f"[stability] {skipped} harsher level(s) skipped after their stress's breaking point")
    return write_outputs(rows, out_dir, scale, str(data))


def write_outputs(rows: list[dict], out_dir: Path, scale: str, data: str, machine: Optional[dict] = None) -> dict:
    """Collapses marked, summary, breaking points, stability.{json,md,png} written; returns the JSON payload."""
    rows = mark_collapses(rows)
    summary = summarize(rows)
    points = breaking_points(rows)
    title = f"Stability under stress, {Path(data).name} ({scale} scale)"
    payload = {"scale": scale, "data": data, "collapse_db": COLLAPSE_DB, "breaking_point": points,
               "levels": {k: [lv.label for lv in v] for k, v in STRESS_LEVELS.items()}, "rows": rows, "summary": summary}
    body = breaking_markdown(points) + "\n\n" + markdown(rows, summary) + "\n\n![stability](stability.png)\n"
    md = write_bench_files(out_dir, "stability", title, payload, body, machine=machine)
    level_chart(rows, Path(out_dir) / "stability.png", title)
    print(md)
    return payload


def regenerate(results_json: Path, out_dir: Path) -> dict:
    """Rewrite stability.{json,md,png} from a committed stability.json's rows (no training): how the
    committed results got the current failure definition. The machine line stays the one it ran on."""
    d = json.loads(Path(results_json).read_text())
    rows = [{**r, "status": "ok", "error": None} if r["status"] == "collapse" and "unstressed mean" in (r.get("error") or "")
            else r for r in d["rows"]]
    return write_outputs(rows, out_dir, d["scale"], d["data"], machine=d["machine"])
