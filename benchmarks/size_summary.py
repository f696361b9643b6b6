"""Issue 20's size target over the model-size sweeps made with the budget read from the views as the
default (the code of 2026-11-25, 15th session, where it was; it is off by default now), in one table.

Usage: python benchmarks/size_summary.py
Reads the picks of each sweep (`ns2gs-bench model-size`, picks on the validation views) and writes
benchmarks/results/views_budget/summary.{json,md}: per sweep and method, the default's primitives and
validation PSNR, how far below the best swept configuration it ends, and its ratio to the smallest
configuration within 0.5 dB of the best (target: within 0.5 dB, at most 1.5x).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from nerf2gs_plugin.eval.machine import machine_line  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "views_budget"
SWEEPS = (
    ("embedded street, quick", "street_quick/model_size.json"),
    ("second street, quick", "second_street_quick/model_size.json"),
    ("embedded street + NeRF views, quick", "street_nerf_views_quick/model_size.json"),
    ("embedded street, default", "street_default/model_size.json"),
    ("second street, default", "second_street_default/model_size.json"),
)


def summary() -> list[dict]:
    rows = []
    for sweep, name in SWEEPS:
        path = RESULTS / name
        if not path.is_file():
            continue
        picks = json.loads(path.read_text())["picks"]
        for method, p in picks.items():
            d = p.get("default")
            if d is None:
                continue
            rows.append({"sweep": sweep, "file": name, "method": method, "primitives": d["primitives"],
                         "val_psnr": round(d["mean_psnr"], 2), "below_best_db": round(p["default_below_best_db"], 2),
                         "best": p["best"], "smallest_within_0_5dB": p["smallest"],
                         "default_over_smallest": round(p["default_over_smallest"], 2), "target_met": p["target_met"]})
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| sweep | method | default primitives | val PSNR | below best | / smallest in band | target met |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['sweep']} | {r['method']} | {r['primitives']:,} | {r['val_psnr']:.2f} | {r['below_best_db']:.2f} dB | "
                     f"{r['default_over_smallest']:.2f}x | {'yes' if r['target_met'] else '**no**'} |")
    return "\n".join(lines)


def main() -> None:
    rows = summary()
    met = sum(r["target_met"] for r in rows)
    table = markdown(rows)
    md = (f"# Issue 20's size target with the budget read from the views as the default\n\nMachine: {machine_line()}\n\n"
          f"Each sweep's picks on its validation views (`benchmarks/size_summary.py`): the default within 0.5 dB of the "
          f"best swept configuration and at most 1.5x the primitives of the smallest one within that band. "
          f"Met in {met} of {len(rows)}.\n\n{table}\n")
    atomic_write_text(RESULTS / "summary.json", json.dumps({"machine": machine_line(), "met": met, "of": len(rows),
                                                                       "rows": rows}, indent=1))
    atomic_write_text(RESULTS / "summary.md", md)
    print(md)


if __name__ == "__main__":
    main()
