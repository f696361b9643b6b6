"""Replace some rows of a committed paper table with the rows of a newer run of the same bench, and
write the table again (JSON, Markdown with the differences, PSNR chart).

Usage: python benchmarks/merge_paper_rows.py TABLE_DIR NEW_DIR LABEL [LABEL ...]
TABLE_DIR and NEW_DIR each hold a paper_table.json (``ns2gs-bench paper-table``); the rows LABEL of
NEW_DIR replace (or join) TABLE_DIR's, every other row stays as it was. For a default change that
retrains only some targets (e.g. ``--targets scaffold-gs``) where the others provably train as before;
the Markdown says which rows came from where (the lines of earlier merges are kept).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MERGED = "Rows retrained in a later run of the bench and merged here"
sys.path.insert(0, str(ROOT))
from nerf2gs_bench.paper import TARGETS, paper_table_pairs, ratios_md, write_results  # noqa: E402


def main(table_dir: Path, new_dir: Path, labels: list[str]) -> None:
    old = json.loads((table_dir / "paper_table.json").read_text())["results"]
    new = json.loads((new_dir / "paper_table.json").read_text())["results"]
    missing = [lab for lab in labels if lab not in new]
    if missing:
        raise SystemExit(f"{new_dir / 'paper_table.json'}: no row {missing}")
    merged = {lab: new[lab] if lab in labels else row for lab, row in old.items()}
    merged.update({lab: new[lab] for lab in labels if lab not in merged})
    old_md = (table_dir / "paper_table.md").read_text().splitlines()
    title = old_md[0].lstrip("# ").strip()
    earlier = [line for line in old_md if line.startswith(MERGED)]  # a table merged before keeps saying so
    targets = [t for t in TARGETS if t in merged]
    modes = tuple(dict.fromkeys(lab.rsplit(" (", 1)[1][: -len(" confidence)")] for lab in merged if lab.endswith(" confidence)")))
    pairs = paper_table_pairs(targets, any(f"{t} + NeRF views + enhancer" in merged for t in targets), modes)
    line = f"{MERGED} (`benchmarks/merge_paper_rows.py`): {', '.join(labels)}; every other row is the earlier run's."
    note = "\n\n".join(earlier + [line]) + f"\n\nDifferences (rows as merged):\n\n{ratios_md(merged, pairs)}\n"
    print(write_results(table_dir, "paper_table", merged, title, extra_md=note))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3:])
