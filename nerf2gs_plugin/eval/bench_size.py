"""model-size: quality against primitives for each splatting method, sweeping its densification
budget and threshold, and the smallest model within 0.5 dB of the best one.

Splatfacto and 2DGS sweep ``strategy.max_gaussians`` (the soft budget of the densify/prune
strategy) and ``strategy.densify_grad_thresh``; Scaffold-GS sweeps ``max_anchors`` and ``grow_threshold``. Quality is the
mean PSNR over the eval splits the dataset has (street, bev_1, bev_2). With ``augment`` every run
trains on StreetNeRF's views (the StreetNeRF run is shared with the paper table when the scale
matches).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

from nerf2gs_plugin.eval.bench_io import (EVAL_SPLITS, BenchLog, BenchProgress, BenchRunner, fmt, mean_psnr, planned_steps,
                                         progress_log, write_bench_files)
from nerf2gs_plugin.eval.bench_runs import RunSpec
from nerf2gs_plugin.utils.plotting import pyplot, save_figure
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.errors import ConfigError

TOLERANCE_DB = 0.5
# method -> [(model config field (dotted into a nested config), values at quick scale, values at
# default scale)]; the default value of each field is part of every sweep, the others stay default
SWEEPS: dict[str, list[tuple[str, tuple, tuple]]] = {
    "splatfacto": [("strategy.max_gaussians", (2000, 8000, 30000), (5000, 15000, 30000, 60000, 120000)),
                   ("strategy.densify_grad_thresh", (0.0016,), (0.0004, 0.0016))],
    "2dgs": [("strategy.max_gaussians", (2000, 8000, 30000), (5000, 15000, 30000, 60000)),
             ("strategy.densify_grad_thresh", (0.0016,), (0.0004, 0.0016))],
    "scaffold-gs": [("max_anchors", (1000, 5000, 20000), (2000, 5000, 10000, 20000)),
                    ("grow_threshold", (0.0008,), (0.0001, 0.0008))],
}


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


def size_plan(scale: str, methods=tuple(SWEEPS), augment: bool = False) -> list[RunSpec]:
    """One run per swept value (duplicates of the default config run once)."""
    from nerf2gs_plugin.eval.bench_paper import _overrides

    from nerf2gs_plugin.registry import get_method

    plan: list[RunSpec] = []
    if augment:
        plan.append(RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf")))
    for m in methods:
        if m not in SWEEPS:
            raise ConfigError(f"model-size has no sweep for method '{m}' (has: {', '.join(SWEEPS)})")
        seen: set[tuple] = set()
        model_defaults = get_method(m).config.pipeline.model
        for fld, quick, default in SWEEPS[m]:
            for value in quick if scale == "quick" else default:
                if (fld, value) in seen:
                    continue
                seen.add((fld, value))
                # the method's own value adds no override: that run is the paper-table baseline (same key)
                extra = {} if _get(model_defaults, fld) == value else {"pipeline": {"model": _nested(fld, value)}}
                ov = _overrides(scale, m, extra)
                name = fld.rsplit(".", 1)[-1]
                plan.append(RunSpec(f"{m} {name}={value:g}", m, ov, augment_from="StreetNeRF" if augment else None))
    return plan


def smallest_within(rows: list[dict], tol: float = TOLERANCE_DB) -> dict[str, dict]:
    """Per method: the best quality, and the run with the fewest primitives within ``tol`` dB of it."""
    out: dict[str, dict] = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        ok = [r for r in rows if r["method"] == m and r.get("quality") is not None and r.get("primitives") is not None]
        if not ok:
            continue
        best = max(ok, key=lambda r: r["quality"])
        near = [r for r in ok if r["quality"] >= best["quality"] - tol]
        small = min(near, key=lambda r: (r["primitives"], -r["quality"]))
        out[m] = {"best": best["label"], "best_quality": best["quality"], "best_primitives": best["primitives"],
                  "smallest": small["label"], "smallest_quality": small["quality"], "smallest_primitives": small["primitives"],
                  "reduction": best["primitives"] / small["primitives"] if small["primitives"] else None}
    return out


def row_from(label: str, method: str, result: Optional[dict], error: Optional[str]) -> dict[str, Any]:
    row: dict[str, Any] = {"label": label, "method": method, "error": error}
    if result is not None:
        row.update(quality=mean_psnr(result, EVAL_SPLITS), street_psnr=mean_psnr(result, ("street",)),
                   bev_psnr=mean_psnr(result, ("bev_1", "bev_2")), primitives=result["size"]["primitives"],
                   megabytes=result["size"].get("checkpoint_megabytes", result["size"].get("megabytes")),
                   fps=result.get("fps"), train_seconds=result.get("train_seconds"))
    return row


def markdown(rows: list[dict], best: dict[str, dict], tol: float = TOLERANCE_DB) -> str:
    lines = ["| run | primitives | MB | mean PSNR | street PSNR | BEV PSNR | FPS | train s | note |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tags = []
        b = best.get(r["method"], {})
        if b.get("best") == r["label"]:
            tags.append("best")
        if b.get("smallest") == r["label"]:
            tags.append(f"smallest within {tol:g} dB")
        if r.get("error"):
            tags.append(f"**FAILED**: {r['error'][:100]}".replace("|", "/"))
        lines.append(f"| {r['label']} | {r.get('primitives', 'n/a')} | {fmt(r.get('megabytes'), 1)} | {fmt(r.get('quality'))} | "
                     f"{fmt(r.get('street_psnr'))} | {fmt(r.get('bev_psnr'))} | {fmt(r.get('fps'))} | {fmt(r.get('train_seconds'), 0)} | "
                     f"{'; '.join(tags)} |")
    lines += ["", "| method | best (mean PSNR, primitives) | smallest within "
              f"{tol:g} dB (mean PSNR, primitives) | fewer primitives |", "|---|---|---|---|"]
    for m, b in best.items():
        lines.append(f"| {m} | {b['best']} ({fmt(b['best_quality'])}, {b['best_primitives']}) | {b['smallest']} "
                     f"({fmt(b['smallest_quality'])}, {b['smallest_primitives']}) | {fmt(b['reduction'], 1)}x |")
    return "\n".join(lines)


def chart(rows: list[dict], best: dict[str, dict], path: Path, title: str) -> None:
    """Mean PSNR against primitives (log x), one curve per method and swept field; picks marked."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    for k, m in enumerate(methods):
        colour = plt.get_cmap("tab10")(k)
        ok = sorted((r for r in rows if r["method"] == m and r.get("quality") is not None and r.get("primitives")),
                    key=lambda r: r["primitives"])
        ax.plot([r["primitives"] for r in ok], [r["quality"] for r in ok], "o-", color=colour, label=m, alpha=0.85)
        b = best.get(m)
        if b:
            ax.scatter([b["smallest_primitives"]], [b["smallest_quality"]], s=170, facecolors="none", edgecolors=colour, linewidths=1.8, zorder=4)
            ax.axhline(b["best_quality"] - TOLERANCE_DB, color=colour, ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("primitives (Gaussians / anchors / surfels, log)")
    ax.set_ylabel("mean PSNR over eval splits (dB)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, title=f"ringed: smallest within {TOLERANCE_DB:g} dB of the best (dotted)", title_fontsize=7)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


def run(plan: list[RunSpec], data: Path, runs_root: Path, out_dir: Path, scale: str, rerun: bool = False) -> dict:
    """Train/evaluate the sweep (failures recorded, not fatal), write model_size.{json,md,png}."""
    rows, done = [], {}
    with make_progress() as progress:
        bar = BenchProgress(progress, "model-size", [planned_steps(s.method, s.overrides) for s in plan])
        runner = BenchRunner(runs_root, log=progress_log(progress, BenchLog(runs_root, "model_size")), rerun=rerun)
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
                    rows.append(row_from(spec.label, spec.method, out.result, out.error))
            bar.finish(i)
    best = smallest_within(rows)
    title = f"Model size against quality, {Path(data).name} ({scale} scale)"
    payload = {"scale": scale, "data": str(data), "tolerance_db": TOLERANCE_DB, "rows": rows, "picks": best}
    md = write_bench_files(out_dir, "model_size", title, payload, markdown(rows, best) + "\n\n![model size](model_size.png)\n")
    chart(rows, best, Path(out_dir) / "model_size.png", title)
    print(md)
    return payload
