"""Rewrite the numbers of the README's results table from the JSON it cites.

Usage: python benchmarks/readme_tables.py [--check]
Every README table whose first column is ``method`` is read exactly as tests/test_readme_numbers.py
reads it (same citation rule, same column mapping); each number is replaced by its JSON value at
the cell's own decimals; where a column marks its best cell bold, the bold moves to the new best
(highest PSNR / FPS, lowest LPIPS). The result pages under docs/results are rewritten by
``python docs/results/generate.py``.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_readme_numbers import COLUMNS, README, _row_key, _tables, _value  # noqa: E402


def _format(value: float, like: str) -> str:
    text = like.replace("**", "").replace("_", "")
    digits = len(text.split(".")[1]) if "." in text else 0
    out = f"{value:,.{digits}f}" if "," in text else f"{value:.{digits}f}"
    return out


def rewrite(readme: str) -> str:
    lines = readme.splitlines()
    tables = iter(_tables())
    for i, line in enumerate(lines):
        if not line.startswith("| method |"):
            continue
        path, header, rows = next(tables)
        results = json.loads(path.read_text())["results"]
        new_rows = [list(r) for r in rows]
        for c, column in enumerate(header[1:], start=1):
            if column not in COLUMNS:
                continue
            bold = any(r[c].startswith("**") for r in rows)
            values = []
            for r, row in zip(new_rows, rows):
                if row[c].startswith("("):
                    values.append(None)
                    continue
                v = _value(results[_row_key(row[0])], column)
                values.append(v)
                r[c] = _format(v, row[c])
            if bold:
                best = (min if "LPIPS" in column else max)(v for v in values if v is not None)
                for r, v in zip(new_rows, values):
                    if v is not None and abs(v - best) < 1e-12:
                        r[c] = f"**{r[c]}**"
        for k, r in enumerate(new_rows):
            lines[i + 2 + k] = "| " + " | ".join(r) + " |"
    return "\n".join(lines) + ("\n" if readme.endswith("\n") else "")


if __name__ == "__main__":
    new = rewrite(README)
    if "--check" in sys.argv:
        sys.exit(0 if new == README else 1)
    (ROOT / "README.md").write_text(new)
    print("README tables rewritten" if new != README else "README tables already match")
