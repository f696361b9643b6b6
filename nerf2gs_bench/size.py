"""model-size: quality against primitives for each splatting method, sweeping its densification
budget and threshold one field at a time from the method's default, and whether the default ends
within 0.5 dB of the best swept configuration at no more than 1.5x the primitives of the smallest
one within that band (the model-size target).

Splatfacto and 2DGS sweep ``strategy.max_gaussians`` (the fixed soft budget),
``strategy.pixel_steps_per_gaussian`` (a budget read from the views: training pixels x densification
steps over it), ``strategy.gaussians_per_sparse_point`` (the budget's floor read from the SfM points),
``strategy.densify_grad_thresh``, ``strategy.prune_weight_fraction`` (the blending-weight prune after
densification) and ``strategy.prune_margin_db`` (how far below the model's error the prune's change to
the training renders must stay); Scaffold-GS sweeps ``max_anchors``, ``anchor_growth`` (growth relative
to the initial anchors; 0 leaves the views term alone), ``pixel_steps_per_anchor`` (0 leaves the growth
term alone; 20,000 puts the views term above any growth, like a fixed ``max_anchors``) and
``grow_threshold``. The band and the picks are chosen on the validation
views (val_street, val_bev) where the dataset has them, the test views (street, bev_1, bev_2)
otherwise; both are reported. With ``augment`` every run trains on StreetNeRF's views (the StreetNeRF
run is shared with the paper table when the scale matches).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

from nerf2gs_bench.runner import (EVAL_SPLITS, VAL_SPLITS, BenchLog, BenchProgress, BenchRunner, fmt, mean_psnr,
                                         planned_steps, progress_log, write_bench_files)
from nerf2gs_bench.runs import RunSpec
from nerf2gs_plugin.utils.plotting import pyplot, save_figure
from nerf2gs_plugin.data import dataparser_config
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.errors import ConfigError

TOLERANCE_DB = 0.5
SIZE_TARGET = 1.5
"""The model-size target: the default at no more than this many times the primitives of the smallest run in the band."""
# method -> [(model config field (dotted into a nested config), values at quick scale, values at
# default scale)]; one field varies at a time, the others stay default; the default itself is one
# run of its own ("<method> default"), and a swept value equal to it is not run twice.
SWEEPS: dict[str, list[tuple[str, tuple, tuple]]] = {
    "splatfacto": [("strategy.max_gaussians", (2000, 8000), (5000, 15000, 30000, 120000)),
                   ("strategy.pixel_steps_per_gaussian", (0.0, 27000.0, 54000.0, 108000.0, 216000.0), (0.0, 54000.0, 108000.0, 216000.0)),
                   ("strategy.gaussians_per_sparse_point", (0.0, 3.0), (0.0, 3.0)),
                   ("strategy.densify_grad_thresh", (0.0016,), (0.0016,)),
                   ("strategy.prune_weight_fraction", (0.0, 0.2), (0.0, 0.05, 0.2)),
                   ("strategy.prune_margin_db", (0.0, 2.0, 6.0), (0.0, 2.0, 6.0))],
    "2dgs": [("strategy.max_gaussians", (2000, 8000), (5000, 15000, 30000)),
             ("strategy.pixel_steps_per_gaussian", (0.0, 18000.0, 36000.0, 72000.0, 144000.0), (0.0, 36000.0, 72000.0, 144000.0)),
             ("strategy.gaussians_per_sparse_point", (0.0, 3.0), (0.0, 3.0)),
             ("strategy.densify_grad_thresh", (0.0016,), (0.0016,)),
             ("strategy.prune_weight_fraction", (0.0, 0.2), (0.0, 0.05, 0.2)),
             ("strategy.prune_margin_db", (0.0, 2.0, 6.0), (0.0, 2.0, 6.0))],
    "scaffold-gs": [("max_anchors", (1000,), (2000,)),
                    ("anchor_growth", (0.0, 1.1, 1.5, 2.0), (0.0, 1.1, 1.5, 2.0)),
                    ("pixel_steps_per_anchor", (0.0, 20000.0), (0.0, 20000.0)),
                    ("grow_threshold", (0.0008,), (0.0001, 0.0008))],
}


def _label(method: str, fld: str, value: Any) -> str:
    """``splatfacto prune_weight_fraction=0.2``."""
    return f"{method} {fld.rsplit('.', 1)[-1]}={value:g}"


def _get(cfg: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        cfg = getattr(cfg, part)
    return cfg


def _nested(dotted: str, value: Any) -> dict:
    """``"a.b"``, 1 -> ``{"a": {"b": 1}}`` (an override of a nested config field)."""
    out: Any = value
    for part in reversed(dotted.split(".")):
        out = {part: out}
    return out


def model_overrides(items: list[str]) -> dict:
    """``["strategy.max_gaussians=8000", ...]`` (values as JSON) -> the plain overrides of the model config
    (``{"pipeline": {"model": {...}}}``), nested fields of one config merged."""
    import json

    model: dict = {}
    for item in items:
        field, value = item.split("=", 1)
        nested = _nested(field, json.loads(value))
        key = next(iter(nested))
        model[key] = {**model.get(key, {}), **nested[key]} if isinstance(nested[key], dict) else nested[key]
    return {"pipeline": {"model": model}} if model else {}


def size_plan(scale: str, methods=tuple(SWEEPS), augment: bool = False, fields: Optional[tuple[str, ...]] = None) -> list[RunSpec]:
    """The default run, then one run per swept value that differs from the default (of the swept
    ``fields`` only when given, by their last name: ``prune_margin_db``)."""
    from nerf2gs_bench.paper import _overrides

    from nerf2gs_plugin.registry import get_method

    plan: list[RunSpec] = []
    if fields is not None:
        known = {fld.rsplit(".", 1)[-1] for m in methods if m in SWEEPS for fld, _, _ in SWEEPS[m]}
        unknown = sorted(set(fields) - known)
        if unknown:
            raise ConfigError(f"model-size sweeps no field {', '.join(unknown)} for {', '.join(methods)} (has: {', '.join(sorted(known))})")
    if augment:
        plan.append(RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf")))
    for m in methods:
        if m not in SWEEPS:
            raise ConfigError(f"model-size has no sweep for method '{m}' (has: {', '.join(SWEEPS)})")
        ref = "StreetNeRF" if augment else None
        # no override: the paper table's run of the method (same key, trained once)
        plan.append(RunSpec(f"{m} default", m, _overrides(scale, m), augment_from=ref))
        model_defaults = get_method(m).config.pipeline.model
        for fld, quick, default in SWEEPS[m]:
            if fields is not None and fld.rsplit(".", 1)[-1] not in fields:
                continue
            for value in (quick if scale == "quick" else default):
                if _get(model_defaults, fld) == value:
                    continue
                ov = _overrides(scale, m, {"pipeline": {"model": _nested(fld, value)}})
                plan.append(RunSpec(_label(m, fld, value), m, ov, augment_from=ref))
    return plan


def choice_key(rows: list[dict]) -> str:
    """``val_quality`` when every finished run has it (choose on validation views), else ``quality``."""
    done = [r for r in rows if r.get("quality") is not None]
    return "val_quality" if done and all(r.get("val_quality") is not None for r in done) else "quality"


def smallest_within(rows: list[dict], tol: float = TOLERANCE_DB, key: Optional[str] = None) -> dict[str, dict]:
    """Per method: the best run by ``key`` (:func:`choice_key` by default), the run with the fewest
    primitives within ``tol`` dB of it, and where the method's default run (``default: True``) stands."""
    key = key or choice_key(rows)
    out: dict[str, dict] = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        ok = [r for r in rows if r["method"] == m and r.get(key) is not None and r.get("primitives") is not None]
        if not ok:
            continue
        best = max(ok, key=lambda r: r[key])
        near = [r for r in ok if r[key] >= best[key] - tol]
        small = min(near, key=lambda r: (r["primitives"], -r[key]))
        pick = {"chosen_on": "validation views" if key == "val_quality" else "test views",
                "best": best["label"], "best_quality": best[key], "best_primitives": best["primitives"],
                "smallest": small["label"], "smallest_quality": small[key], "smallest_primitives": small["primitives"],
                "reduction": best["primitives"] / small["primitives"] if small["primitives"] else None,
                "smallest_within_0_5dB": {"label": small["label"], "primitives": small["primitives"], "mean_psnr": small[key]}}
        default = next((r for r in ok if r.get("default")), None)
        if default is not None:
            ratio = default["primitives"] / small["primitives"] if small["primitives"] else None
            below = best[key] - default[key]
            pick.update(default={"label": default["label"], "primitives": default["primitives"], "mean_psnr": default[key]},
                        default_over_smallest=ratio, default_below_best_db=below,
                        target_met=bool(ratio is not None and ratio <= SIZE_TARGET and below <= tol))
        out[m] = pick
    return out


def row_from(label: str, method: str, result: Optional[dict], error: Optional[str],
             val_result: Optional[dict] = None) -> dict[str, Any]:
    """A run's size and quality: ``quality`` over the test views, ``val_quality`` over the validation
    views (None where the dataset has none)."""
    row: dict[str, Any] = {"label": label, "method": method, "error": error, "default": label.endswith(" default")}
    if result is not None:
        row.update(quality=mean_psnr(result, EVAL_SPLITS), street_psnr=mean_psnr(result, ("street",)),
                   bev_psnr=mean_psnr(result, ("bev_1", "bev_2")), primitives=result["size"]["primitives"],
                   megabytes=result["size"].get("checkpoint_megabytes", result["size"].get("megabytes")),
                   fps=result.get("fps"), train_seconds=result.get("train_seconds"))
        val = mean_psnr(val_result, VAL_SPLITS) if val_result is not None else None
        row.update(val_quality=val, val_street_psnr=mean_psnr(val_result or {}, ("val_street",)),
                   val_bev_psnr=mean_psnr(val_result or {}, ("val_bev",)))
    return row


def markdown(rows: list[dict], best: dict[str, dict], tol: float = TOLERANCE_DB) -> str:
    key = choice_key(rows)
    on = "validation" if key == "val_quality" else "test"
    lines = [f"Picks on the {on} views (mean PSNR over {', '.join(VAL_SPLITS if key == 'val_quality' else EVAL_SPLITS)}); "
             f"the test-view columns are reported, never chosen on.", "",
             "| run | primitives | MB | val PSNR | val street | val BEV | test PSNR | street PSNR | BEV PSNR | FPS | train s | note |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tags = []
        b = best.get(r["method"], {})
        if b.get("best") == r["label"]:
            tags.append("best")
        if b.get("smallest") == r["label"]:
            tags.append(f"smallest within {tol:g} dB")
        if r.get("error"):
            tags.append(f"**FAILED**: {r['error'][:100]}".replace("|", "/"))
        lines.append(f"| {r['label']} | {r.get('primitives', 'n/a')} | {fmt(r.get('megabytes'), 1)} | {fmt(r.get('val_quality'))} | "
                     f"{fmt(r.get('val_street_psnr'))} | {fmt(r.get('val_bev_psnr'))} | {fmt(r.get('quality'))} | "
                     f"{fmt(r.get('street_psnr'))} | {fmt(r.get('bev_psnr'))} | {fmt(r.get('fps'))} | {fmt(r.get('train_seconds'), 0)} | "
                     f"{'; '.join(tags)} |")
    lines += ["", f"| method | best ({on} PSNR, primitives) | smallest within {tol:g} dB | default | default below best | "
              f"default / smallest (target <= {SIZE_TARGET:g}) | target met |", "|---|---|---|---|---|---|---|"]
    for m, b in best.items():
        d = b.get("default")
        lines.append(f"| {m} | {b['best']} ({fmt(b['best_quality'])}, {b['best_primitives']}) | {b['smallest']} "
                     f"({fmt(b['smallest_quality'])}, {b['smallest_primitives']}) | "
                     + (f"{fmt(d['mean_psnr'])}, {d['primitives']} | {fmt(b['default_below_best_db'])} dB | "
                        f"{fmt(b['default_over_smallest'])}x | {'yes' if b['target_met'] else '**no**'} |" if d else "n/a | | | |"))
    return "\n".join(lines)


def draw(ax, rows: list[dict], best: dict[str, dict], title: str, legend: bool = True) -> None:
    """One sweep on ``ax``: mean PSNR against primitives (log x) per method, picks marked."""
    plt = pyplot()
    methods = list(dict.fromkeys(r["method"] for r in rows))
    key = choice_key(rows)
    for k, m in enumerate(methods):
        colour = plt.get_cmap("tab10")(k)
        ok = sorted((r for r in rows if r["method"] == m and r.get(key) is not None and r.get("primitives")),
                    key=lambda r: r["primitives"])
        ax.plot([r["primitives"] for r in ok], [r[key] for r in ok], "o", color=colour, label=m, alpha=0.85)
        b = best.get(m)
        if b:
            ax.scatter([b["smallest_primitives"]], [b["smallest_quality"]], s=170, facecolors="none", edgecolors=colour, linewidths=1.8, zorder=4)
            ax.axhline(b["best_quality"] - TOLERANCE_DB, color=colour, ls=":", lw=0.8)
            if b.get("default"):
                ax.scatter([b["default"]["primitives"]], [b["default"]["mean_psnr"]], marker="*", s=160, color=colour, zorder=5)
    ax.set_xscale("log")
    ax.set_xlabel("primitives (Gaussians / anchors / surfels, log)")
    ax.set_ylabel(f"mean PSNR over the {'validation' if key == 'val_quality' else 'test'} views (dB)")
    ax.grid(alpha=0.3, which="both")
    if legend:
        ax.legend(fontsize=8, title=f"star: default; ringed: smallest within {TOLERANCE_DB:g} dB of the best (dotted)", title_fontsize=7)
    ax.set_title(title, fontsize=10)


def chart(rows: list[dict], best: dict[str, dict], path: Path, title: str) -> None:
    """The sweep's picture (:func:`draw`) on its own."""
    fig, ax = pyplot().subplots(figsize=(7.5, 4.6))
    draw(ax, rows, best, title)
    fig.tight_layout()
    save_figure(fig, path)


def run(plan: list[RunSpec], data: Path, runs_root: Path, out_dir: Path, scale: str, rerun: bool = False) -> dict:
    """Train/evaluate the sweep (failures recorded, not fatal), write model_size.{json,md,png}."""
    rows, done = [], {}
    with make_progress() as progress:
        bar = BenchProgress(progress, "model-size", [planned_steps(s.method, s.overrides, s.augment if s.augment_from else None) for s in plan])
        log = progress_log(progress, BenchLog(runs_root, "model_size"))
        runner = BenchRunner(runs_root, log=log, rerun=rerun)
        # the same runs evaluated on the validation views, where the dataset has them (asked once, not per run)
        has_val = any(s in dataparser_config(data).splits() for s in VAL_SPLITS)
        val_runner = BenchRunner(runs_root, log=log, splits=VAL_SPLITS) if has_val else None
        for i, spec in enumerate(plan):
            bar.start(i, spec.label)
            ref = done.get(spec.augment_from) if spec.augment_from else None
            if spec.augment_from and ref is None:
                rows.append(row_from(spec.label, spec.method, None, f"reference '{spec.augment_from}' failed"))
            else:
                out = runner.run(spec, data, reference=ref, step_hook=bar.hook)
                if out.result is not None:
                    done[spec.label] = (Path(out.run_dir), Path(out.run_dir).name)
                if spec.method != "streetnerf":
                    val = val_runner.run(spec, data, reference=ref).result if val_runner and out.result is not None else None
                    rows.append(row_from(spec.label, spec.method, out.result, out.error, val))
            bar.finish(i)
    best = smallest_within(rows)
    title = f"Model size against quality, {Path(data).name} ({scale} scale)"
    payload = {"scale": scale, "data": str(data), "tolerance_db": TOLERANCE_DB, "rows": rows, "picks": best}
    md = write_bench_files(out_dir, "model_size", title, payload, markdown(rows, best) + "\n\n![model size](model_size.png)\n")
    chart(rows, best, Path(out_dir) / "model_size.png", title)
    print(md)
    return payload
