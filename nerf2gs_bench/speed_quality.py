"""speed-quality: render FPS (log x), training wall time and model size against bird's-eye PSNR for
every method and variant in the committed paper-table / ablation results, Pareto fronts marked: one
per panel, and the three-axis front (faster to render, better from above, smaller) listed.

It trains nothing: it reads ``<results>/<name>.json`` written by the table benches, so the chart
always shows exactly the runs the tables show (one point per run directory).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional, Sequence

from nerf2gs_plugin.errors import DataError
from nerf2gs_bench.runner import fmt, mean_psnr, write_bench_files
from nerf2gs_bench.machine import machine_line
from nerf2gs_plugin.utils.plotting import pyplot, save_figure

SOURCES = ("paper_table", "ablation")
FALLBACK_SOURCES = ("quick",)


def pareto_front(xs: Sequence[float], ys: Sequence[float], x_higher: bool = True) -> list[int]:
    """Indices of the points no other point dominates (y higher is better; x higher is better
    unless ``x_higher`` is False), ordered by x. Points with a non-finite coordinate are never on it."""
    pts = [(x if x_higher else -x, y) for x, y in zip(xs, ys)]
    ok = [i for i, (x, y) in enumerate(pts) if math.isfinite(x) and math.isfinite(y)]
    front = [i for i in ok if not any(
        pts[j][0] >= pts[i][0] and pts[j][1] >= pts[i][1] and (pts[j][0] > pts[i][0] or pts[j][1] > pts[i][1]) for j in ok)]
    return sorted(front, key=lambda i: xs[i])


def pareto_front_nd(columns: Sequence[Sequence[float]], higher: Sequence[bool]) -> list[int]:
    """Indices of the points no other point dominates on every axis at once (``columns[k][i]``: point
    i on axis k; ``higher[k]``: whether larger is better there), in input order. Points with a
    non-finite coordinate are never on it; ties dominate nobody."""
    n = len(columns[0]) if columns else 0
    pts = [tuple(c[i] if h else -c[i] for c, h in zip(columns, higher)) for i in range(n)]
    ok = [i for i in range(n) if all(math.isfinite(v) for v in pts[i])]
    return [i for i in ok if not any(all(a >= b for a, b in zip(pts[j], pts[i])) and pts[j] != pts[i] for j in ok)]


def points_from_results(results: dict[str, dict], source: str) -> list[dict]:
    """One point per result of a table bench's JSON (``results`` maps label -> eval result);
    failed runs have no measurement and no point."""
    pts = []
    for label, r in results.items():
        if r.get("failed"):
            continue
        bev = mean_psnr(r, ("bev_1", "bev_2"))
        pts.append({
            "label": r.get("label", label), "source": source, "method": r.get("target") or r.get("method_name"),
            "fps": r.get("fps"), "bev_psnr": bev, "street_psnr": mean_psnr(r, ("street",)),
            "train_seconds": r.get("train_seconds"), "primitives": (r.get("size") or {}).get("primitives"),
            "megabytes": (r.get("size") or {}).get("megabytes"),
            "run_dir": r.get("run_dir"),
        })
    return pts


def collect_points(results_dir: Path, names: Optional[Sequence[str]] = None) -> tuple[list[dict], list[dict]]:
    """Points of every named results file (default: paper_table and ablation, else quick),
    de-duplicated by run directory; plus the machines those files were measured on."""
    results_dir = Path(results_dir)
    chosen = list(names) if names else [n for n in SOURCES if (results_dir / f"{n}.json").is_file()]
    if not chosen:
        chosen = [n for n in FALLBACK_SOURCES if (results_dir / f"{n}.json").is_file()]
    if not chosen:
        raise DataError("no paper_table.json / ablation.json results (run `ns2gs-bench paper-table` first)", results_dir)
    points, machines, seen = [], [], {}
    for name in chosen:
        path = results_dir / f"{name}.json"
        if not path.is_file():
            raise DataError("results file does not exist", path)
        try:
            doc = json.loads(path.read_text())
            results = doc["results"]
            assert isinstance(results, dict)
        except (json.JSONDecodeError, KeyError, AssertionError, TypeError):
            raise DataError("not a bench results file (no 'results' mapping)", path) from None
        if doc.get("machine") and doc["machine"] not in machines:
            machines.append(doc["machine"])
        for p in points_from_results(results, name):
            key = p["run_dir"] or f"{name}:{p['label']}"
            if key in seen:
                seen[key]["source"] += f", {name}"
                continue
            seen[key] = p
            points.append(p)
    return points, machines


def _finite(v) -> float:
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) and v > 0 else float("nan")


def _bev(points: list[dict]) -> list[float]:
    return [_finite(p["bev_psnr"]) if p["bev_psnr"] is not None else float("nan") for p in points]


def fronts(points: list[dict]) -> tuple[list[int], list[int], list[int]]:
    """(front over FPS up / BEV PSNR up, over training time down / BEV PSNR up, over model size
    (MB) down / BEV PSNR up)."""
    ys = _bev(points)
    f_fps = pareto_front([_finite(p["fps"]) for p in points], ys, x_higher=True)
    f_time = pareto_front([_finite(p["train_seconds"]) for p in points], ys, x_higher=False)
    f_size = pareto_front([_finite(p.get("megabytes")) for p in points], ys, x_higher=False)
    return f_fps, f_time, f_size


def front_3d(points: list[dict]) -> list[int]:
    """The runs no other run beats at once on render FPS, BEV PSNR and model size, best PSNR first."""
    ys = _bev(points)
    idx = pareto_front_nd([[_finite(p["fps"]) for p in points], ys, [_finite(p.get("megabytes")) for p in points]],
                          (True, True, False))
    return sorted(idx, key=lambda i: -ys[i])


def chart(points: list[dict], path: Path, title: str) -> None:
    """Three panels, log x: FPS, training time and model size (MB) against BEV PSNR; marker area
    grows with the model's MB; each panel's front ringed and joined, three-axis front in red."""
    plt = pyplot()
    f_fps, f_time, f_size = fronts(points)
    f3 = set(front_3d(points))
    methods = sorted({str(p["method"]) for p in points})
    colours = {m: plt.get_cmap("tab10")(i % 10) for i, m in enumerate(methods)}
    mbs = [_finite(p.get("megabytes")) for p in points]
    top = max([v for v in mbs if math.isfinite(v)] or [1.0])
    area = [18 + 260 * math.sqrt(v / top) if math.isfinite(v) else 42 for v in mbs]
    ys = _bev(points)
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.2))
    panels = ((axes[0], "fps", "render FPS at eval resolution (log)", f_fps),
              (axes[1], "train_seconds", "training wall time, s (log)", f_time),
              (axes[2], "megabytes", "model size, MB (log)", f_size))
    for ax, key, xlabel, front in panels:
        shown = set()
        for i, p in enumerate(points):
            x, y = _finite(p.get(key)), ys[i]
            if not (math.isfinite(x) and math.isfinite(y)):
                continue
            m = str(p["method"])
            ax.scatter([x], [y], s=area[i], color=colours[m], alpha=0.75, label=m if m not in shown else None, zorder=3)
            shown.add(m)
            if i in front:
                ax.scatter([x], [y], s=area[i] + 90, facecolors="none", edgecolors="k", linewidths=1.2, zorder=4)
            if i in f3:
                ax.scatter([x], [y], s=14, marker="*", color="red", zorder=5)
            ax.annotate(p["label"], (x, y), fontsize=6.5, xytext=(4, 3), textcoords="offset points")
        if front:
            ax.plot([_finite(points[i][key]) for i in front], [points[i]["bev_psnr"] for i in front], "k--", lw=1,
                    label="Pareto front (this panel)", zorder=2)
        ax.scatter([], [], s=14, marker="*", color="red", label="front on all three axes")
        ax.set_xscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("bird's-eye PSNR (mean of bev_1, bev_2), dB")
        ax.grid(alpha=0.3, which="both")
        legend = ax.legend(fontsize=7)
        for handle in getattr(legend, "legend_handles", []):
            if hasattr(handle, "set_sizes"):
                handle.set_sizes([30])  # the legend names colours; sizes are the models'
    fig.suptitle(title + " (marker area: model MB)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


def markdown(points: list[dict]) -> str:
    f_fps, f_time, f_size = fronts(points)
    f3 = front_3d(points)
    lines = ["## The front on all three axes (render FPS, BEV PSNR, model MB)", "",
             "| run | FPS | BEV PSNR | MB | primitives |", "|---|---|---|---|---|"]
    for i in f3:
        p = points[i]
        lines.append(f"| {p['label']} | {fmt(p['fps'])} | {fmt(p['bev_psnr'])} | {fmt(p.get('megabytes'))} | "
                     f"{p['primitives'] if p['primitives'] is not None else 'n/a'} |")
    lines += ["", "No run outside this list renders at least as fast, scores at least as high from above and is at "
              "least as small (better on one). StreetNeRF's MB is its field's parameters.", "", "## Every run", "",
              "| run | from | FPS | BEV PSNR | street PSNR | train s | primitives | MB | front (FPS) | front (time) | front (MB) |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    order = sorted(range(len(points)), key=lambda i: -(_finite(points[i]["fps"]) if math.isfinite(_finite(points[i]["fps"])) else -1))
    for i in order:
        p = points[i]
        lines.append(f"| {p['label']} | {p['source']} | {fmt(p['fps'])} | {fmt(p['bev_psnr'])} | {fmt(p['street_psnr'])} | "
                     f"{fmt(p['train_seconds'], 0)} | {p['primitives'] if p['primitives'] is not None else 'n/a'} | "
                     f"{fmt(p.get('megabytes'))} | {'yes' if i in f_fps else ''} | {'yes' if i in f_time else ''} | "
                     f"{'yes' if i in f_size else ''} |")
    lines += ["", "Front (FPS): no other run renders faster with a higher BEV PSNR. Front (time): no other run "
              "trains faster with a higher BEV PSNR. Front (MB): no other run is smaller with a higher BEV PSNR. Runs without a BEV split or FPS are listed but not ranked. "
              "Training time is the run's own: a run with NeRF views also needs its reference (the StreetNeRF row's time)."]
    return "\n".join(lines)


def run(results_dir: Path, out_dir: Path, names: Optional[Sequence[str]] = None) -> dict:
    """Read the table results, write speed_quality.{json,md,png}; returns the JSON payload."""
    points, machines = collect_points(results_dir, names)
    f_fps, f_time, f_size = fronts(points)
    title = "Speed and size against quality (bird's-eye PSNR), from the table benches' results"
    body = markdown(points)
    if len(machines) > 1:
        body += "\n\nResults measured on: " + "; ".join(machine_line(m) for m in machines)
    payload = {"points": points, "front_fps": [points[i]["label"] for i in f_fps],
               "front_train_time": [points[i]["label"] for i in f_time],
               "front_megabytes": [points[i]["label"] for i in f_size],
               "front_fps_psnr_megabytes": [points[i]["label"] for i in front_3d(points)]}
    md = write_bench_files(out_dir, "speed_quality", title, payload, body + "\n\n![speed-quality](speed_quality.png)\n",
                           machine=machines[0] if machines else None)
    chart(points, Path(out_dir) / "speed_quality.png", title)
    print(md)
    return payload
