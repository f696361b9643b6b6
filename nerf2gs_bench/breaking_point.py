"""Where each method breaks: the collapse rule, the walk that stops a stress at its first failure,
the breaking-point table and the PSNR-vs-level chart. Pure (rows in, rows/tables/figures out), so
a fresh sweep and a committed stability.json are judged by the same code.

A row is one run of the stability bench: ``method``, ``variant``, ``status`` and the PSNRs, plus
``stress`` / ``level`` (1-based rung; 0 for the unstressed seed runs) / ``level_label`` for a
sweep. Rows of the older one-level bench have no ``stress``: each non-seed variant then counts
as a stress of one level.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import Callable, Optional

FAILURES = ("diverged", "nan", "collapse", "error")
COLLAPSE_DB = 3.0  # a case more than this far below the unstressed runs' mean PSNR (street or BEV) failed
PSNR_KEYS = ("street_psnr", "bev_psnr")
SEED_STRESS = "seed"


def row_stress(row: dict) -> tuple[str, int, str]:
    """(stress, level, level label) of a row, old rows included (see the module docstring)."""
    if row.get("stress"):
        return row["stress"], int(row.get("level") or 0), str(row.get("level_label") or row["variant"])
    if str(row.get("variant", "")).startswith("seed "):
        return SEED_STRESS, 0, row["variant"]
    return str(row.get("variant")), 1, str(row.get("variant"))


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def baselines(rows: list[dict]) -> dict[str, dict[str, float]]:
    """Per method: the mean street and BEV PSNR of its ``ok`` unstressed seed runs."""
    base: dict[str, dict[str, float]] = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        seeds = [r for r in rows if r["method"] == m and row_stress(r)[0] == SEED_STRESS and r["status"] == "ok"]
        for name in PSNR_KEYS:
            vals = [r[name] for r in seeds if _finite(r.get(name))]
            if vals:
                base.setdefault(m, {})[name] = statistics.fmean(vals)
    return base


def drops(row: dict, base: dict[str, dict[str, float]]) -> dict[str, float]:
    """How far (dB) the row's street / BEV PSNR lies below its method's unstressed mean."""
    return {name: mean - row[name] for name, mean in base.get(row["method"], {}).items() if _finite(row.get(name))}


def mark_collapses(rows: list[dict], drop_db: float = COLLAPSE_DB) -> list[dict]:
    """Rows with every ``ok`` case whose street or BEV PSNR lies more than ``drop_db`` below its
    method's unstressed mean (the ``ok`` seed runs) turned into ``collapse``, the drop in ``error``.
    Pure: works on a fresh bench's rows and on the rows of a committed stability.json alike."""
    base = baselines(rows)
    out = []
    for r in rows:
        r = dict(r)
        if r["status"] == "ok":
            bad = {k: d for k, d in drops(r, base).items() if d > drop_db}
            if bad:
                r["status"] = "collapse"
                r["error"] = "; ".join(f"{k.split('_')[0]} PSNR {d:.2f} dB below the unstressed mean" for k, d in bad.items())
        out.append(r)
    return out


def sweep(cases: list, run_one: Callable[[int, object], dict], group: Callable[[object], Optional[tuple]],
          on_row: Optional[Callable[[object, list[dict]], None]] = None) -> list[dict]:
    """Run ``cases`` in order; once a case of a group (method x stress) fails (or its stress is
    unsupported), the group's later, harsher levels are skipped: the first failure is the
    breaking point. ``group(case)`` is None for cases never skipped (the seed runs). An exception
    from ``run_one`` is an ``error`` row with its kind, never the end of the bench."""
    rows: list[dict] = []
    broken: set[tuple] = set()
    for i, case in enumerate(cases):
        g = group(case)
        if g is not None and g in broken:
            continue
        try:
            row = run_one(i, case)
        except Exception as e:  # noqa: BLE001 - a level that raises is a measured failure
            msg = str(e).splitlines()[0][:200] if str(e) else ""
            row = {"method": g[0] if g else "?", "variant": getattr(case, "variant", str(case)), "status": "error",
                   "error": f"{type(e).__name__}: {msg}".rstrip(": "), "error_kind": type(e).__name__}
            for key in ("stress", "level", "level_label"):
                if hasattr(case, key):
                    row[key] = getattr(case, key)
            if hasattr(case, "label_method"):
                row["method"] = case.label_method
        rows.append(row)
        if g is not None and mark_collapses(rows)[-1]["status"] in FAILURES + ("unsupported",):
            broken.add(g)
        if on_row is not None:
            on_row(case, rows)
    return rows


def breaking_points(rows: list[dict]) -> dict[str, dict[str, object]]:
    """Per method and stress: the first failing level (``level``, ``level_index``, ``status``,
    ``drop_db`` = the worse of the street/BEV drops, ``error``), ``"none up to <last level>"``
    when every level walked was ok, or ``"unsupported"``."""
    marked = mark_collapses(rows)
    base = baselines(rows)
    out: dict[str, dict[str, object]] = {}
    for r in marked:
        stress, level, label = row_stress(r)
        if stress == SEED_STRESS:
            continue
        cell = out.setdefault(r["method"], {})
        if isinstance(cell.get(stress), dict):
            continue  # already broken: a later row (an older sweep's) does not move it
        if r["status"] in FAILURES:
            d = drops(r, base)
            cell[stress] = {"level": label, "level_index": level, "status": r["status"],
                            "drop_db": round(max(d.values()), 3) if d else None, "error": r.get("error")}
        elif r["status"] == "unsupported":
            cell[stress] = "unsupported"
        else:
            cell[stress] = f"none up to {label}"
    return out


def _cell(v) -> str:
    if v is None:
        return "not run"
    if isinstance(v, str):
        return v
    error = str(v.get("error") or "")
    if v["status"] == "collapse" and "untrained" in error:
        what = "below the untrained model"
    elif v["status"] == "collapse" and v.get("drop_db") is not None:
        what = f"{v['drop_db']:.1f} dB below"
    else:
        what = error.split(":")[0] or v["status"]
    return f"**{v['level']}** ({v['status']}: {what})".replace("|", "/")


def breaking_markdown(points: dict[str, dict[str, object]]) -> str:
    """The breaking-point table: methods x stresses."""
    stresses = list(dict.fromkeys(s for cells in points.values() for s in cells))
    lines = ["## Breaking points", "", "| method | " + " | ".join(stresses) + " |", "|---|" + "---|" * len(stresses)]
    for m, cells in points.items():
        lines.append(f"| {m} | " + " | ".join(_cell(cells.get(s)) for s in stresses) + " |")
    lines += ["", "Each stress is walked mild -> harsh and stops at its first failure (the breaking point, in bold): "
              f"street or BEV PSNR more than {COLLAPSE_DB:g} dB below the method's unstressed seed mean, divergence, "
              "non-finite metrics or an error (its kind given). \"none up to X\": every level up to X stayed within the band."]
    return "\n".join(lines)


def level_chart(rows: list[dict], path: Path, title: str) -> None:
    """One panel per stress: PSNR change against the unstressed mean (the worse of street/BEV)
    per level, a line per method, the collapse threshold dashed, the breaking point ringed in red;
    failures without a PSNR drawn as crosses at the panel's floor."""
    from nerf2gs_plugin.utils.plotting import pyplot, save_figure

    plt = pyplot()
    marked = mark_collapses(rows)
    base = baselines(rows)
    stresses = list(dict.fromkeys(row_stress(r)[0] for r in marked if row_stress(r)[0] != SEED_STRESS))
    methods = list(dict.fromkeys(r["method"] for r in marked))
    colors = {m: plt.get_cmap("tab10")(k % 10) for k, m in enumerate(methods)}
    n = max(1, len(stresses))
    cols = min(3, n)
    rows_n = math.ceil(n / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(4.2 * cols, 3.2 * rows_n), squeeze=False)
    for ax in axes.flat[len(stresses):]:
        ax.set_visible(False)
    for ax, stress in zip(axes.flat, stresses):
        labels = {0: "none"}
        ys: list[float] = []
        failed: list[tuple[int, object]] = []
        broke: list[tuple[int, float]] = []
        for m in methods:
            pts, fails = ([(0, 0.0)] if m in base else []), []
            for r in marked:
                s, level, label = row_stress(r)
                if s != stress or r["method"] != m:
                    continue
                labels[level] = label
                d = drops(r, base)
                if d:
                    pts.append((level, -max(d.values())))
                    if r["status"] in FAILURES:
                        broke.append(pts[-1])
                elif r["status"] in FAILURES:
                    fails.append(level)
            color = colors[m]
            if len(pts) > 1:
                ax.plot(*zip(*pts), marker="o", color=color)
            ys += [y for _, y in pts]
            failed += [(x, color) for x in fails]
        floor = min(ys + [-COLLAPSE_DB]) - 1.0
        if broke:
            ax.scatter(*zip(*broke), s=160, facecolors="none", edgecolors="red", linewidths=1.5, zorder=4)
        for x, color in failed:
            ax.scatter([x], [floor + 0.3], marker="x", color=color, s=60, linewidths=2, zorder=3)
        ax.axhline(-COLLAPSE_DB, color="red", linestyle="--", linewidth=1)
        ax.set_xticks(sorted(labels))
        ax.set_xticklabels([labels[i] for i in sorted(labels)], rotation=25, ha="right", fontsize=7)
        ax.set_ylim(floor, max(ys + [0.0]) + 0.5)
        ax.set_title(stress, fontsize=9)
        ax.set_ylabel("PSNR vs unstressed (dB)", fontsize=8)
        ax.grid(alpha=0.3)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colors[m], marker="o", label=m) for m in methods]
    handles += [Line2D([], [], color="red", linestyle="--", label=f"collapse: {COLLAPSE_DB:g} dB below unstressed"),
                Line2D([], [], color="red", marker="o", markerfacecolor="none", linestyle="", label="breaking point"),
                Line2D([], [], color="grey", marker="x", linestyle="", label="failed without a PSNR (nan, error)")]
    fig.legend(handles=handles, loc="lower center", ncol=min(4, len(handles)), fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.06 + 0.02 * (len(handles) // 4), 1, 1))
    save_figure(fig, path)
