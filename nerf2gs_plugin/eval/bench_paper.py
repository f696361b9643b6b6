"""The paper's tables on the synthetic street: Table 1/S1 (paper-table), Table 2 (ablation), the
speed-quality charts, and the 10-minute `quick` version the README demo runs."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, Callable, Optional

from nerf2gs_plugin.engine.config import atomic_write_text
from nerf2gs_plugin.eval.bench_runs import RunSpec, train_or_reuse
from nerf2gs_plugin.eval.machine import machine_info, machine_line

SPLITS = ("street", "bev_1", "bev_2")
METRICS = (("psnr", "PSNR", True), ("ssim", "SSIM", True), ("lpips", "LPIPS", False))
TARGETS = ("splatfacto", "scaffold-gs", "2dgs")

# Per-scale overrides of each method's registered default config.
SCALE_OVERRIDES: dict[str, dict[str, dict[str, Any]]] = {
    "quick": {
        "streetnerf": {"max_num_iterations": 1500, "steps_per_eval_image": 0},
        "splatfacto": {"max_num_iterations": 800, "steps_per_eval_image": 0},
        "scaffold-gs": {"max_num_iterations": 800, "steps_per_eval_image": 0},
        "2dgs": {"max_num_iterations": 800, "steps_per_eval_image": 0},
    },
    "default": {m: {"steps_per_eval_image": 0} for m in ("streetnerf", *TARGETS)},
}


def _overrides(scale: str, method: str, extra: Optional[dict] = None) -> dict:
    base = json.loads(json.dumps(SCALE_OVERRIDES.get(scale, {}).get(method, {})))
    for k, v in (extra or {}).items():
        if isinstance(v, dict) and isinstance(base.get(k), dict):
            base[k].update(v)
        else:
            base[k] = v
    return base


def paper_table_plan(scale: str, targets=TARGETS, enhancer: Optional[str] = None) -> list[RunSpec]:
    plan = [RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf"))]
    for t in targets:
        plan.append(RunSpec(f"{t}", t, _overrides(scale, t)))
        plan.append(RunSpec(f"{t} + NeRF views", t, _overrides(scale, t), augment_from="StreetNeRF"))
        if enhancer:
            plan.append(RunSpec(f"{t} + NeRF views + enhancer", t, _overrides(scale, t), augment_from="StreetNeRF",
                                augment={"enhancer": enhancer}))
    return plan


def ablation_plan(scale: str, enhancer: Optional[str] = None) -> list[RunSpec]:
    t = "splatfacto"
    plan = [
        RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf")),
        RunSpec(t, t, _overrides(scale, t)),
        RunSpec(f"{t} + views from {t}", t, _overrides(scale, t), augment_from=t),
        RunSpec(f"{t} + views from StreetNeRF", t, _overrides(scale, t), augment_from="StreetNeRF"),
    ]
    if enhancer:
        plan.insert(3, RunSpec(f"{t} + views from {t} + enhancer", t, _overrides(scale, t), augment_from=t, augment={"enhancer": enhancer}))
        plan.append(RunSpec(f"{t} + views from StreetNeRF + enhancer", t, _overrides(scale, t), augment_from="StreetNeRF", augment={"enhancer": enhancer}))
    for flag in ("sky", "ground_reg", "transient_mask", "appearance"):
        plan.append(RunSpec(f"StreetNeRF w/o {flag}", "streetnerf", _overrides(scale, "streetnerf", {"pipeline": {"model": {flag: False}}})))
    return plan


def run_plan(plan: list[RunSpec], data: Path, runs_root: Path, log: Callable[[str], None] = print) -> dict[str, dict]:
    """Train (or reuse) and evaluate every run of a plan, in order; returns label -> eval result."""
    from nerf2gs_plugin.data.fingerprint import dataset_fingerprint
    from nerf2gs_plugin.engine.reference import load_run
    from nerf2gs_plugin.engine.trainer import pick_device
    from nerf2gs_plugin.eval.evaluate import evaluate_run
    from nerf2gs_plugin.eval.metrics import LPIPS

    device = pick_device("auto")
    from nerf2gs_plugin.data import parse_dataset

    dataset = dataset_fingerprint(parse_dataset(data, "train").image_filenames)
    done: dict[str, tuple[Path, str]] = {}
    results: dict[str, dict] = {}
    lpips_model = LPIPS.load_default(device=device)
    for i, spec in enumerate(plan):
        log(f"[bench] ({i + 1}/{len(plan)}) {spec.label}")
        ref = done[spec.augment_from] if spec.augment_from else None
        if spec.augment_from and ref is None:
            raise KeyError(f"run '{spec.label}' augments from '{spec.augment_from}', which is not earlier in the plan")
        run_dir, key = train_or_reuse(spec, data, runs_root, dataset, reference=ref, log=log)
        done[spec.label] = (run_dir, key)
        eval_path = run_dir / "bench_eval.json"
        if eval_path.is_file():
            res = json.loads(eval_path.read_text())
        else:
            run = load_run(run_dir, device=device)
            res = evaluate_run(run, list(SPLITS), render_dir=run_dir / "eval_renders", lpips_model=lpips_model)
            atomic_write_text(eval_path, json.dumps(res, indent=1))
        res["run_dir"] = str(run_dir)
        res["label"] = spec.label
        res["target"] = spec.method
        results[spec.label] = res
    return results


# ----------------------------------------------------------------------------- tables
def _value(res: dict, metric: str, split: str) -> Optional[float]:
    r = res["results"].get(split, {})
    return r.get(metric)


def _group_ranks(rows: list[dict], groups: dict[str, list[str]]) -> dict[tuple[str, str, str], int]:
    """(label, metric, split) -> 1 (best) or 2 (second) within each target group."""
    ranks = {}
    for labels in groups.values():
        if len(labels) < 2:
            continue
        for metric, _, higher in METRICS:
            for split in SPLITS:
                vals = [(r["label"], _value(r, metric, split)) for r in rows if r["label"] in labels]
                vals = [(lab, v) for lab, v in vals if v is not None]
                vals.sort(key=lambda x: -x[1] if higher else x[1])
                for rank, (lab, _) in enumerate(vals[:2], start=1):
                    ranks[(lab, metric, split)] = rank
    return ranks


def markdown_table(results: dict[str, dict], groups: dict[str, list[str]], title: str) -> str:
    rows = list(results.values())
    ranks = _group_ranks(rows, groups)
    head = ["method"] + [f"{name} {s}" for _, name, _ in METRICS for s in SPLITS] + ["FPS", "primitives", "MB", "train s"]
    lines = [f"### {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["label"]]
        for metric, _, _ in METRICS:
            for s in SPLITS:
                v = _value(r, metric, s)
                txt = "n/a" if v is None else (f"{v:.2f}" if metric == "psnr" else f"{v:.3f}")
                rank = ranks.get((r["label"], metric, s))
                cells.append(f"**{txt}**" if rank == 1 else f"_{txt}_" if rank == 2 else txt)
        size = r["size"]
        cells += [f"{r['fps']:.2f}", str(size["primitives"]), f"{size['megabytes']:.1f}", f"{r['train_seconds']:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Bold: best, italic: second best within each target method (rows sharing a target)."]
    return "\n".join(lines)


def rich_table(results: dict[str, dict], title: str):
    from rich.table import Table

    table = Table(title=title)
    table.add_column("method")
    for s in SPLITS:
        table.add_column(f"PSNR {s}", justify="right")
    for s in SPLITS:
        table.add_column(f"SSIM {s}", justify="right")
    table.add_column("FPS", justify="right")
    table.add_column("prims", justify="right")
    for r in results.values():
        ps = [_value(r, "psnr", s) for s in SPLITS]
        ss = [_value(r, "ssim", s) for s in SPLITS]
        table.add_row(r["label"], *[f"{v:.2f}" if v is not None else "n/a" for v in ps],
                      *[f"{v:.3f}" if v is not None else "n/a" for v in ss], f"{r['fps']:.2f}", str(r["size"]["primitives"]))
    return table


def target_groups(results: dict[str, dict]) -> dict[str, list[str]]:
    groups: dict[str, list[str]] = {}
    for label, r in results.items():
        key = r["target"] if " w/o " not in label else "streetnerf-ablation"
        groups.setdefault(key, []).append(label)
    return groups


# ----------------------------------------------------------------------------- charts
def _bev_psnr(r: dict) -> float:
    vals = [_value(r, "psnr", s) for s in ("bev_1", "bev_2")]
    vals = [v for v in vals if v is not None]
    return sum(vals) / len(vals) if vals else float("nan")


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points not dominated in (x up, y up)."""
    front = []
    for i, (x, y) in enumerate(points):
        if not any((x2 >= x and y2 >= y) and (x2 > x or y2 > y) for j, (x2, y2) in enumerate(points) if j != i):
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def speed_quality_chart(results: dict[str, dict], path: Path, title: str) -> None:
    from nerf2gs_plugin.eval.figures import _mpl, save_figure

    plt = _mpl()
    rows = [r for r in results.values() if r.get("fps")]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    for ax, xkey, xlabel, logx in ((axes[0], "fps", "render FPS (log)", True), (axes[1], "train_seconds", "training wall time, s (log)", True)):
        pts = [(max(r[xkey], 1e-6) if xkey == "fps" else -max(r[xkey], 1e-6), _bev_psnr(r)) for r in rows]
        for r, (x, y) in zip(rows, pts):
            xv = abs(x)
            ax.scatter([xv], [y], s=40)
            ax.annotate(r["label"], (xv, y), fontsize=7, xytext=(4, 3), textcoords="offset points")
        front = pareto_front([(x, y) for x, y in pts if not math.isnan(y)])
        if front:
            fx = [abs(pts[i][0]) for i in front]
            fy = [pts[i][1] for i in front]
            order = sorted(range(len(fx)), key=lambda k: fx[k])
            ax.plot([fx[k] for k in order], [fy[k] for k in order], "k--", lw=1, label="Pareto front")
            ax.legend(fontsize=8)
        if logx:
            ax.set_xscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("bird's-eye PSNR (mean of bev_1, bev_2), dB")
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


def psnr_bar_chart(results: dict[str, dict], path: Path, title: str) -> None:
    from nerf2gs_plugin.eval.figures import _mpl, save_figure

    plt = _mpl()
    labels = list(results)
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(labels)), 4.2))
    width = 0.27
    for k, s in enumerate(SPLITS):
        vals = [_value(results[l], "psnr", s) or 0.0 for l in labels]
        ax.bar([i + (k - 1) * width for i in range(len(labels))], vals, width, label=s)
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels, rotation=25, ha="right", fontsize=8)
    ax.set_ylabel("PSNR (dB)")
    lo = min((_value(r, "psnr", s) or 99) for r in results.values() for s in SPLITS)
    ax.set_ylim(max(0, lo - 3), None)
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


def renders_figure(results: dict[str, dict], labels: list[str], split: str, path: Path, image_index: int = 0) -> None:
    """Paper Fig. 4 analogue: GT and each run's render of one eval view."""
    from nerf2gs_plugin.engine.reference import load_run
    from nerf2gs_plugin.eval.figures import image_row

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
    md = f"# {title}\n\nMachine: {machine_line(info)}\n\n{md}\n\n{extra_md}"
    atomic_write_text(out_dir / f"{name}.json", json.dumps({"machine": info, "results": results}, indent=1))
    atomic_write_text(out_dir / f"{name}.md", md)
    psnr_bar_chart(results, out_dir / f"{name}.png", title)
    return md


def ratios_md(results: dict[str, dict], pairs: list[tuple[str, str]]) -> str:
    """Augmented vs baseline, measured in the same run of the bench (absolute times drift)."""
    lines = ["| comparison | d PSNR street | d PSNR bev_1 | d PSNR bev_2 | FPS ratio |", "|---|---|---|---|---|"]
    for a, b in pairs:
        if a in results and b in results:
            d = [(_value(results[a], "psnr", s) or 0) - (_value(results[b], "psnr", s) or 0) for s in SPLITS]
            fr = results[a]["fps"] / results[b]["fps"] if results[b]["fps"] else float("nan")
            lines.append(f"| {a} vs {b} | {d[0]:+.2f} | {d[1]:+.2f} | {d[2]:+.2f} | {fr:.2f}x |")
    return "\n".join(lines)


def run_named_bench(name: str, plan: list[RunSpec], data: Path, runs_root: Path, out_dir: Path, title: str,
                    compare: list[tuple[str, str]], figure_labels: Optional[list[str]] = None) -> dict[str, dict]:
    from rich.console import Console

    t0 = time.time()
    results = run_plan(plan, data, runs_root)
    md = write_results(out_dir, name, results, title, extra_md="Differences, same bench run:\n\n" + ratios_md(results, compare)
                       + f"\n\nBench wall time: {time.time() - t0:.0f} s (training reused where cached).\n")
    speed_quality_chart(results, Path(out_dir) / f"{name}_speed_quality.png", title)
    if figure_labels:
        renders_figure(results, figure_labels, "bev_1", Path(out_dir) / f"{name}_renders_bev_1.png")
        renders_figure(results, figure_labels, "street", Path(out_dir) / f"{name}_renders_street.png")
    Console().print(rich_table(results, title))
    print(ratios_md(results, compare))
    print(f"results: {out_dir}/{name}.md")
    return results
