"""The paper's tables on the synthetic street: Table 1/S1 (paper-table), Table 2 (ablation), the
speed-quality charts, and the 10-minute `quick` version the README demo runs."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Callable, Optional

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_bench.runner import BenchFailed, fmt  # noqa: F401
from nerf2gs_bench.runs import RunSpec
from nerf2gs_plugin.eval.extrapolated import EXTRAPOLATED, EXTRAPOLATED_SPLITS, extrapolated_mean
from nerf2gs_plugin.eval.figures import image_row
from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.utils.plotting import pyplot, save_figure

SPLITS = ("street", "bev_1", "bev_2", "lane_2", "lane_4", EXTRAPOLATED)
METRICS = (("psnr", "PSNR", True), ("ssim", "SSIM", True), ("lpips", "LPIPS", False), ("psnr_ground", "PSNR road", True))
TARGETS = ("splatfacto", "scaffold-gs", "2dgs")

# Step budgets per scale ("default" = the method's registered config). A shorter run rescales the
# method's schedules with it (see step_overrides), so it is a faithful short run, not a truncated one.
SCALE_STEPS: dict[str, dict[str, int]] = {
    "quick": {"streetnerf": 1500, "splatfacto": 800, "scaffold-gs": 800, "2dgs": 800},
    "default": {},
}


def _diff(before: Any, after: Any) -> Any:
    """The parts of plain config ``after`` that differ from ``before`` (nested dicts recursed)."""
    if isinstance(before, dict) and isinstance(after, dict):
        out = {k: _diff(before.get(k), v) for k, v in after.items() if before.get(k) != v}
        return out
    return after


def _merge(base: dict, extra: dict) -> dict:
    """Recursive dict merge (``extra`` wins); inputs are not modified."""
    out = json.loads(json.dumps(base))
    for k, v in extra.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def step_overrides(method: str, steps: int) -> dict:
    """Plain overrides for ``steps`` iterations with the method's schedules (densification,
    SH degree, learning-rate decay, ...) rescaled by ``MethodSpecification.with_steps``."""
    from nerf2gs_plugin.utils.config import to_plain
    from nerf2gs_plugin.registry import get_method

    spec = get_method(method)
    return json.loads(json.dumps(_diff(to_plain(spec.config), to_plain(spec.with_steps(steps))), default=str))


def _overrides(scale: str, method: str, extra: Optional[dict] = None) -> dict:
    """Overrides of ``method``'s registered config for a bench at ``scale`` (plus ``extra``)."""
    steps = SCALE_STEPS.get(scale, {}).get(method)
    base = step_overrides(method, steps) if steps else {}
    return _merge({**base, "steps_per_eval_image": 0}, extra or {})


def confidence_label(mode: str) -> str:
    """The row suffix of a run trained with ``--augment.confidence mode``."""
    return f" ({mode} confidence)"


def paper_table_pairs(targets, enhancer: bool, confidence: tuple[str, ...] = ()) -> list[tuple[str, str]]:
    """The paper table's "Differences" rows: each target with NeRF views (and with the enhancer) against the target
    alone, each confidence mode against NeRF views without it."""
    pairs = [(f"{t} + NeRF views", t) for t in targets] + [(f"{t} + NeRF views + enhancer", t) for t in targets if enhancer]
    return pairs + [(f"{t} + NeRF views{confidence_label(c)}", f"{t} + NeRF views") for t in targets for c in confidence]


def paper_table_plan(scale: str, targets=TARGETS, enhancer: Optional[str] = None, confidence: tuple[str, ...] = ()) -> list[RunSpec]:
    """StreetNeRF, then per target: alone, + NeRF views (+ the same with ``--augment.confidence`` per
    mode in ``confidence``), + NeRF views + enhancer."""
    plan = [RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf"))]
    for t in targets:
        plan.append(RunSpec(f"{t}", t, _overrides(scale, t)))
        plan.append(RunSpec(f"{t} + NeRF views", t, _overrides(scale, t), augment_from="StreetNeRF"))
        for mode in confidence:
            plan.append(RunSpec(f"{t} + NeRF views{confidence_label(mode)}", t, _overrides(scale, t), augment_from="StreetNeRF",
                                augment={"confidence": mode}))
        if enhancer:
            plan.append(RunSpec(f"{t} + NeRF views + enhancer", t, _overrides(scale, t), augment_from="StreetNeRF",
                                augment={"enhancer": enhancer}))
    return plan


ABLATION_FAMILIES = (("lane-shift",), ("raise",), ("birds-eye", "lane-shift"))
"""The ablation's view-family rows beside the bird's-eye views ("views from StreetNeRF"), each family's defaults;
the poses family needs the user's file of poses, so it has no row."""


def family_label(views: tuple[str, ...]) -> str:
    """The row suffix of a run trained with ``--augment.views views``."""
    return f" ({' '.join(views)})"


def ablation_plan(scale: str, enhancer: Optional[str] = None, confidence: tuple[str, ...] = (),
                  streetnerf_terms: bool = True) -> list[RunSpec]:
    """Views from Splatfacto itself vs from StreetNeRF (+ enhancer, + ``--augment.confidence`` per mode
    in ``confidence``), then StreetNeRF without each of its street-specific terms."""
    t = "splatfacto"
    plan = [
        RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf")),
        RunSpec(t, t, _overrides(scale, t)),
        RunSpec(f"{t} + views from {t}", t, _overrides(scale, t), augment_from=t),
        RunSpec(f"{t} + views from StreetNeRF", t, _overrides(scale, t), augment_from="StreetNeRF"),
    ]
    plan += [RunSpec(f"{t} + views from StreetNeRF{confidence_label(mode)}", t, _overrides(scale, t), augment_from="StreetNeRF",
                     augment={"confidence": mode}) for mode in confidence]
    plan += [RunSpec(f"{t} + views from StreetNeRF{family_label(views)}", t, _overrides(scale, t), augment_from="StreetNeRF",
                     augment={"views": list(views)}) for views in ABLATION_FAMILIES]
    if enhancer:
        plan.insert(3, RunSpec(f"{t} + views from {t} + enhancer", t, _overrides(scale, t), augment_from=t, augment={"enhancer": enhancer}))
        plan.append(RunSpec(f"{t} + views from StreetNeRF + enhancer", t, _overrides(scale, t), augment_from="StreetNeRF", augment={"enhancer": enhancer}))
    for flag in ("sky", "ground_reg", "transient_mask", "appearance", "point_depth") if streetnerf_terms else ():
        plan.append(RunSpec(f"StreetNeRF w/o {flag}", "streetnerf", _overrides(scale, "streetnerf", {"pipeline": {"model": {flag: False}}})))
    return plan


def run_plan(plan: list[RunSpec], data: Path, runs_root: Path, log: Optional[Callable[[str], None]] = None,
             name: str = "bench", rerun: bool = False) -> dict[str, dict]:
    """Train (or reuse) and evaluate every run of a plan, in order; returns label -> eval result.
    A run that fails (training diverged, an error in training or evaluation, non-finite metrics)
    is a row with ``failed: True`` and its ``error``, as in the stability bench, and the plan goes
    on; runs that augment from a failed run fail too. One progress bar over the whole plan (in
    training steps); log lines also go to ``<runs_root>/logs/<name>.log``."""
    from nerf2gs_bench.runner import BenchLog, BenchProgress, BenchRunner, failure_reason, planned_steps, progress_log

    done: dict[str, tuple[Path, str]] = {}
    results: dict[str, dict] = {}
    with make_progress() as progress:
        bar = BenchProgress(progress, name, [planned_steps(s.method, s.overrides, s.augment if s.augment_from else None) for s in plan])
        log = log or progress_log(progress, BenchLog(runs_root, name))
        runner = BenchRunner(runs_root, log=log, rerun=rerun)
        for i, spec in enumerate(plan):
            bar.start(i, spec.label)
            log(f"[bench] ({i + 1}/{len(plan)}) {spec.label}")
            if spec.augment_from and spec.augment_from not in {s.label for s in plan[:i]}:
                raise ConfigError(f"run '{spec.label}' augments from '{spec.augment_from}', which is not earlier in the plan")
            if spec.augment_from and spec.augment_from not in done:
                reason = f"reference run '{spec.augment_from}' failed"
                log(f"[bench] {spec.label} FAILED: {reason}")
                results[spec.label] = {"label": spec.label, "target": spec.method, "failed": True, "error": reason}
            else:
                out = runner.run(spec, data, reference=done.get(spec.augment_from) if spec.augment_from else None,
                                 step_hook=bar.hook)
                reason = failure_reason(out)
                if reason is None:
                    done[spec.label] = (Path(out.run_dir), out.key)
                    results[spec.label] = out.result
                else:
                    if out.error is None:
                        log(f"[bench] {spec.label} FAILED: {reason}")
                    results[spec.label] = {**(out.result or {}), "label": spec.label, "target": spec.method,
                                           "run_dir": out.run_dir, "failed": True, "error": reason}
            bar.finish(i)
    return results


def failures(results: dict[str, dict]) -> dict[str, str]:
    """label -> reason of every failed run."""
    return {label: r.get("error") or "failed" for label, r in results.items() if r.get("failed")}


def succeeded(results: dict[str, dict]) -> dict[str, dict]:
    return {label: r for label, r in results.items() if not r.get("failed")}


# ----------------------------------------------------------------------------- tables
def _value(res: dict, metric: str, split: str) -> Optional[float]:
    if split == EXTRAPOLATED:  # computed here, so results evaluated before the column existed have it too
        return extrapolated_mean(res.get("results", {}), metric)
    r = res.get("results", {}).get(split, {})
    return r.get(metric)


def table_splits(results: dict[str, dict]) -> tuple[str, ...]:
    """The columns of :data:`SPLITS` some run has a PSNR for: a street without lane views (an older
    dataset, the real-capture bench's) keeps its three columns instead of n/a ones."""
    return tuple(s for s in SPLITS if any(_value(r, "psnr", s) is not None for r in results.values() if not r.get("failed")))


def _group_ranks(rows: list[dict], groups: dict[str, list[str]], splits: tuple[str, ...] = SPLITS) -> dict[tuple[str, str, str], int]:
    """(label, metric, split) -> 1 (best) or 2 (second) within each target group."""
    ranks = {}
    for labels in groups.values():
        if len(labels) < 2:
            continue
        for metric, _, higher in METRICS:
            for split in splits:
                vals = [(r["label"], _value(r, metric, split)) for r in rows if r["label"] in labels]
                vals = [(lab, v) for lab, v in vals if v is not None]
                vals.sort(key=lambda x: -x[1] if higher else x[1])
                for rank, (lab, _) in enumerate(vals[:2], start=1):
                    ranks[(lab, metric, split)] = rank
    return ranks


def markdown_table(results: dict[str, dict], groups: dict[str, list[str]], title: str) -> str:
    rows = list(results.values())
    splits = table_splits(results)
    ranks = _group_ranks([r for r in rows if not r.get("failed")], groups, splits)
    head = ["method"] + [f"{name} {s}" for _, name, _ in METRICS for s in splits] + ["FPS", "primitives", "MB", "train s"]
    lines = [f"### {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["label"]]
        if r.get("failed"):  # the reason in the first metric cell; no number is made up
            reason = str(r.get("error") or "unknown error").replace("|", "/").replace("\n", " ")[:160]
            lines.append("| " + " | ".join(cells + [f"failed: {reason}"] + ["-"] * (len(head) - 2)) + " |")
            continue
        for metric, _, _ in METRICS:
            for s in splits:
                v = _value(r, metric, s)
                txt = "n/a" if v is None else (f"{v:.2f}" if metric.startswith("psnr") else f"{v:.3f}")
                rank = ranks.get((r["label"], metric, s))
                cells.append(f"**{txt}**" if rank == 1 else f"_{txt}_" if rank == 2 else txt)
        size = r["size"]
        cells += [fmt(r.get("fps")), primitives_cell(size), fmt(size.get("checkpoint_megabytes", size["megabytes"]), 1), fmt(r.get("train_seconds"), 0)]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Bold: best, italic: second best within each target method (rows sharing a target)."]
    if EXTRAPOLATED in splits:
        lines += [f"{EXTRAPOLATED}: the mean over {', '.join(EXTRAPOLATED_SPLITS)} (views no training camera took)."]
    return "\n".join(lines)


def primitives_cell(size: dict) -> str:
    """Primitives of a splatting run; for a model without primitives (a NeRF's hash grid) its
    parameters, so no table calls hash-table entries primitives."""
    if "primitive_kind" in size and size["primitive_kind"] is None:
        return f"({size['parameters'] / 1e6:.2f}M params)"
    return str(size["primitives"])


def rich_table(results: dict[str, dict], title: str):
    from rich.table import Table
    from rich.text import Text

    table = Table(title=title)
    splits = table_splits(results)
    table.add_column("method")
    for s in splits:
        table.add_column(f"PSNR {s}", justify="right")
    for s in splits:
        table.add_column(f"SSIM {s}", justify="right")
    table.add_column("FPS", justify="right")
    table.add_column("prims", justify="right")
    for r in results.values():
        if r.get("failed"):
            table.add_row(r["label"], Text(f"failed: {r.get('error')}", style="red"), *[""] * (2 * len(splits) + 1))
            continue
        ps = [_value(r, "psnr", s) for s in splits]
        ss = [_value(r, "ssim", s) for s in splits]
        table.add_row(r["label"], *[f"{v:.2f}" if v is not None else "n/a" for v in ps],
                      *[f"{v:.3f}" if v is not None else "n/a" for v in ss], fmt(r.get("fps")), primitives_cell(r["size"]))
    return table


def target_groups(results: dict[str, dict]) -> dict[str, list[str]]:
    groups: dict[str, list[str]] = {}
    for label, r in results.items():
        key = r["target"] if " w/o " not in label else "streetnerf-ablation"
        groups.setdefault(key, []).append(label)
    return groups


# ----------------------------------------------------------------------------- charts
def speed_quality_chart(results: dict[str, dict], path: Path, title: str) -> None:
    """FPS and training time against BEV PSNR for this bench's runs, Pareto fronts marked."""
    from nerf2gs_bench.speed_quality import chart, points_from_results

    if not results:
        return
    chart(points_from_results(results, Path(path).stem), path, title)


def psnr_bar_chart(results: dict[str, dict], path: Path, title: str) -> None:
    if not results:  # every run failed: nothing to draw
        return
    splits = table_splits(results)
    if not splits:
        return
    plt = pyplot()
    labels = list(results)
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(labels)), 4.2))
    width = 0.8 / len(splits)
    for k, s in enumerate(splits):
        vals = [_value(results[l], "psnr", s) or 0.0 for l in labels]
        ax.bar([i + (k - (len(splits) - 1) / 2) * width for i in range(len(labels))], vals, width, label=s)
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels, rotation=25, ha="right", fontsize=8)
    ax.set_ylabel("PSNR (dB)")
    lo = min((_value(r, "psnr", s) or 99) for r in results.values() for s in splits)
    ax.set_ylim(max(0, lo - 3), None)
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


def renders_figure(results: dict[str, dict], labels: list[str], split: str, path: Path, image_index: int = 0) -> None:
    """Paper Fig. 4 analogue: GT and each run's render of one eval view."""
    from nerf2gs_plugin.runs.load import load_run

    images, names = [], []
    for label in labels:
        if label not in results:
            continue
        run = load_run(Path(results[label]["run_dir"]))
        cams = list(run.pipeline.datamanager.eval_images(split))
        camera, batch = cams[min(image_index, len(cams) - 1)]
        if not images:
            images.append(batch["image"].cpu())
            names.append(f"GT ({split})")
        images.append(run.model.render_camera(camera)["rgb"].clamp(0, 1).cpu())
        names.append(label)
    if images:
        image_row(images, names, path, title=f"{split} view {image_index}")


# ----------------------------------------------------------------------------- entry points
def write_results(out_dir: Path, name: str, results: dict[str, dict], title: str, extra_md: str = "") -> str:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    info = machine_info()
    md = markdown_table(results, target_groups(results), title)
    failed = failures(results)
    if failed:
        md += f"\n\n**{len(failed)} of {len(results)} runs failed** (reasons in the table and in {name}.json)."
    md = f"# {title}\n\nMachine: {machine_line(info)}\n\n{md}\n\n{extra_md}"
    atomic_write_text(out_dir / f"{name}.json", json.dumps({"machine": info, "results": results, "failed": failed}, indent=1))
    atomic_write_text(out_dir / f"{name}.md", md)
    psnr_bar_chart(succeeded(results), out_dir / f"{name}.png", title)
    return md


def ratios_md(results: dict[str, dict], pairs: list[tuple[str, str]]) -> str:
    """Augmented vs baseline, measured in the same run of the bench (absolute times drift)."""
    splits = table_splits(results)
    lines = ["| comparison | " + " | ".join(f"d PSNR {s}" for s in splits) + " | FPS ratio |", "|---|" + "---|" * (len(splits) + 1)]
    for a, b in pairs:
        if a in results and b in results and not results[a].get("failed") and not results[b].get("failed"):
            d = [(_value(results[a], "psnr", s), _value(results[b], "psnr", s)) for s in splits]
            cells = [f"{x - y:+.2f}" if x is not None and y is not None else "n/a" for x, y in d]
            fr = results[a]["fps"] / results[b]["fps"] if results[a].get("fps") and results[b].get("fps") else float("nan")
            lines.append(f"| {a} vs {b} | " + " | ".join(cells) + f" | {fr:.2f}x |")
    return "\n".join(lines)


def run_named_bench(name: str, plan: list[RunSpec], data: Path, runs_root: Path, out_dir: Path, title: str,
                    compare: list[tuple[str, str]], figure_labels: Optional[list[str]] = None, rerun: bool = False) -> dict[str, dict]:
    """Run the plan and write the table, charts and figures; failed runs are rows of the table,
    and then :class:`BenchFailed` (exit status 2 from ``ns2gs-bench``) names them."""

    t0 = time.time()
    results = run_plan(plan, data, runs_root, name=name, rerun=rerun)
    write_results(out_dir, name, results, title, extra_md="Differences, same bench run:\n\n" + ratios_md(results, compare)
                       + f"\n\nBench wall time: {time.time() - t0:.0f} s (training reused where cached).\n")
    ok = succeeded(results)
    speed_quality_chart(ok, Path(out_dir) / f"{name}_speed_quality.png", title)
    if figure_labels:
        renders_figure(ok, figure_labels, "bev_1", Path(out_dir) / f"{name}_renders_bev_1.png")
        renders_figure(ok, figure_labels, "street", Path(out_dir) / f"{name}_renders_street.png")
    from nerf2gs_plugin.eval.table_print import print_table

    print_table(rich_table(results, title))
    print(ratios_md(results, compare))
    print(f"all columns (LPIPS, road PSNR, size, train time) and charts: {out_dir}/{name}.md")
    failed = failures(results)
    if failed:
        listed = "; ".join(f"'{label}' ({reason})" for label, reason in failed.items())
        raise BenchFailed(f"{len(failed)} of {len(results)} runs failed: {listed}; results written to {out_dir}/{name}.md")
    return results
