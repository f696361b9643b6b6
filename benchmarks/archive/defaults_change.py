"""What a change of defaults did to the committed tables: each row of a paper-table JSON now against
the same file at an earlier commit (the tables made before the change), PSNR per split and size.

Usage: python benchmarks/archive/defaults_change.py BEFORE_COMMIT OUT_STEM RESULT_JSON...
(RESULT_JSON relative to the repository, e.g. benchmarks/results/paper_table.json; writes
OUT_STEM.json and OUT_STEM.md). Made for the 2026-11-24 change (Splatfacto / 2DGS weight prune 0.1,
--augment.real-only-from 0.9), where BEFORE_COMMIT is the last commit with the old tables.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SPLITS = ("street", "bev_1", "bev_2")


def compare(before: str, path: str) -> list[dict]:
    new = json.loads((ROOT / path).read_text())["results"]
    old = json.loads(subprocess.check_output(["git", "show", f"{before}:{path}"], cwd=ROOT))["results"]
    rows = []
    for label, n in new.items():
        o = old.get(label)
        if o is None or n.get("results") is None or o.get("results") is None:
            continue
        rows.append({"label": label, "primitives_before": o["size"].get("primitives"), "primitives": n["size"].get("primitives"),
                     **{f"{s}_before": o["results"][s]["psnr"] for s in SPLITS if s in o["results"]},
                     **{s: n["results"][s]["psnr"] for s in SPLITS if s in n["results"]}})
    return rows


def markdown(before: str, tables: dict[str, list[dict]]) -> str:
    lines = [f"# The committed tables before (commit {before}) and after a change of defaults", ""]
    for path, rows in tables.items():
        lines += [f"## `{path}`", "", "| run | primitives before -> now | d PSNR street | d PSNR bev_1 | d PSNR bev_2 |", "|---|---|---|---|---|"]
        for r in rows:
            d = [f"{r[s] - r[s + '_before']:+.2f}" if s in r and s + "_before" in r else "n/a" for s in SPLITS]
            lines.append(f"| {r['label']} | {r['primitives_before']} -> {r['primitives']} | {' | '.join(d)} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    before, out, paths = sys.argv[1], Path(sys.argv[2]), sys.argv[3:]
    tables = {p: compare(before, p) for p in paths}
    out.with_suffix(".json").write_text(json.dumps({"before_commit": before, "tables": tables}, indent=1))
    out.with_suffix(".md").write_text(markdown(before, tables))
    print(out.with_suffix(".md").read_text())
