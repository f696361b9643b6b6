"""The README and the docs say what the committed results say, and lead nowhere that is not there.

- The README's one results table equals, cell by cell, the bench JSON it cites (rounded as printed).
- docs/results/*.md are what docs/results/generate.py makes of benchmarks/results/*.json: a rerun
  bench fails here until its pages are regenerated.
- README.md stays a front door (at most 250 lines); every relative link of README.md and docs/
  points to a file that exists (and to a heading that exists, where it names one).
"""

from __future__ import annotations

import copy
import importlib.util
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
RESULTS = ROOT / "benchmarks" / "results"
DOCS = ROOT / "docs"
README_MAX_LINES = 250

# README column header -> (split, metric) in a result, or a top-level key
COLUMNS = {
    "PSNR street": ("street", "psnr"), "bev_1": ("bev_1", "psnr"), "bev_2": ("bev_2", "psnr"),
    "LPIPS bev_1": ("bev_1", "lpips"), "road PSNR bev_1": ("bev_1", "psnr_ground"), "road bev_1": ("bev_1", "psnr_ground"),
    "road bev_2": ("bev_2", "psnr_ground"), "FPS": (None, "fps"), "primitives": (None, "primitives"), "train s": (None, "train_seconds"),
}


def _row_key(label: str) -> str:
    """README row label -> the bench's result label ("Scaffold-GS + NeRF views" -> "scaffold-gs + NeRF views")."""
    label = re.sub(r"\s*\(.*?\)", "", label).strip()
    head, _, rest = label.partition(" + ")
    head = "StreetNeRF" if head.lower() == "streetnerf" else head.lower()
    return f"{head} + {rest}" if rest else head


def _tables(text: str = README) -> list[tuple[Path, list[str], list[list[str]]]]:
    """(results JSON the table cites, header, rows) for every table of ``text`` whose first column is 'method'."""
    lines = text.splitlines()
    out = []
    for i, line in enumerate(lines):
        if not line.startswith("| method |"):
            continue
        before = "\n".join(lines[max(0, i - 12):i])
        cited = re.findall(r"benchmarks/results/[\w/]+\.md", before)
        assert cited, f"README table at line {i + 1} cites no results file"
        header = [c.strip() for c in line.strip("|").split("|")]
        rows = []
        for row in lines[i + 2:]:
            if not row.startswith("|"):
                break
            rows.append([c.strip() for c in row.strip("|").split("|")])
        out.append((ROOT / cited[-1].replace(".md", ".json"), header, rows))
    return out


def _value(result: dict, column: str):
    split, metric = COLUMNS[column]
    if split is not None:
        return result["results"][split][metric]
    return result["size"]["primitives"] if metric == "primitives" else result[metric]


def _matches(cell: str, value: float) -> bool:
    """``cell`` is ``value`` as printed: same rounding to the cell's decimals (commas, bold ignored)."""
    text = cell.replace("**", "").replace("_", "").replace(",", "")
    digits = len(text.split(".")[1]) if "." in text else 0
    return abs(float(text) - value) <= 0.5 * 10 ** -digits + 1e-9


def table_mismatches(text: str) -> tuple[int, list[str]]:
    """(cells checked, one line per README cell that differs from its JSON)."""
    checked, bad = 0, []
    for path, header, rows in _tables(text):
        results = json.loads(path.read_text())["results"]
        for row in rows:
            result = results[_row_key(row[0])]
            for column, cell in zip(header[1:], row[1:]):
                if cell.startswith("("):  # "(hash grid)": no count to check
                    continue
                assert column in COLUMNS, f"README column '{column}' has no mapping to {path.name}"
                value = _value(result, column)
                if not _matches(cell, value):
                    bad.append(f"{path.relative_to(ROOT)} {row[0]} / {column}: README {cell}, JSON {value}")
                checked += 1
    return checked, bad


def test_readme_table_matches_its_json():
    tables = _tables()
    assert len(tables) == 1, "the README holds one results table (the paper table); the others live in docs/results"
    path, _, rows = tables[0]
    assert path == RESULTS / "paper_table.json"
    targets = {r["target"] for r in json.loads(path.read_text())["results"].values()}
    assert {_row_key(row[0]).split(" + ")[0].lower() for row in rows} == targets  # every method of the bench is shown
    checked, bad = table_mismatches(README)
    assert not bad, "\n".join(bad)
    assert checked >= 79  # 10 rows x 8 numeric columns, less the hash-grid cell


def test_a_moved_readme_cell_is_caught():
    row = next(line for line in README.splitlines() if line.startswith("| Splatfacto + NeRF views |"))
    cells = row.split("|")
    cells[3] = f" {float(cells[3]) + 0.05:.2f} "  # bev_1
    _, bad = table_mismatches(README.replace(row, "|".join(cells)))
    assert len(bad) == 1 and "bev_1" in bad[0]


def _generator():
    spec = importlib.util.spec_from_file_location("docs_results_generate", DOCS / "results" / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_results_pages_are_what_the_json_gives():
    pages = _generator().render_all()
    assert {"README.md", "paper-table.md", "ablation.md"} <= set(pages)
    stale = [name for name, text in pages.items()
             if not (DOCS / "results" / name).is_file() or (DOCS / "results" / name).read_text() != text]
    assert not stale, f"docs/results/{', '.join(stale)} differ from benchmarks/results: run python docs/results/generate.py"


def test_a_rerun_bench_makes_its_page_stale(monkeypatch):
    gen = _generator()
    real_load = gen.load

    def moved(rel: str) -> dict:
        doc = real_load(rel)
        if rel == "paper_table.json":
            doc = copy.deepcopy(doc)
            doc["results"]["splatfacto + NeRF views"]["results"]["bev_1"]["psnr"] += 0.5
        return doc

    monkeypatch.setattr(gen, "load", moved)
    page = gen.page_paper_table()
    committed = (DOCS / "results" / "paper-table.md").read_text()
    assert page not in committed  # the table cell and the sentence that quotes the gain both moved
    moved_cell = f"{real_load('paper_table.json')['results']['splatfacto + NeRF views']['results']['bev_1']['psnr'] + 0.5:.2f}"
    assert moved_cell in page


def test_readme_is_a_front_door():
    lines = README.splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines; at most {README_MAX_LINES}: move detail to docs/"
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", README), "README.md holds a date: measurement history belongs in docs/results"


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _headings(path: Path) -> set[str]:
    anchors, fenced = set(), False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("#"):
            anchors.add(_slug(line.lstrip("#")))
    return anchors


def _links(path: Path) -> list[str]:
    """Link targets of a Markdown file, outside fenced code blocks."""
    text = re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)
    return re.findall(r"\]\(([^)\s]+)\)", text)


def broken_links(files: list[Path], root: Path = ROOT) -> list[str]:
    bad = []
    for md in files:
        for target in _links(md):
            if re.match(r"[a-z]+:", target):  # http(s), mailto: not checked here
                continue
            file, _, anchor = target.partition("#")
            dest = (md.parent / file).resolve() if file else md
            if not dest.exists():
                bad.append(f"{md.relative_to(root)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _headings(dest):
                bad.append(f"{md.relative_to(root)}: {target} (no such heading)")
    return bad


def test_every_relative_link_leads_somewhere():
    files = [ROOT / "README.md", *sorted(DOCS.glob("*.md")), *sorted((DOCS / "results").glob("*.md"))]
    assert len(files) >= 10
    assert sum(len(_links(f)) for f in files) >= 50
    bad = broken_links(files)
    assert not bad, "\n".join(bad)


def test_a_broken_link_is_caught(tmp_path):
    (tmp_path / "a.md").write_text("# Title\n\n[ok](b.md#there) [gone](c.md) [no anchor](b.md#nowhere) [web](https://x.y)\n")
    (tmp_path / "b.md").write_text("# There\n\n```bash\n# not a heading\n```\n")
    bad = broken_links([tmp_path / "a.md"], tmp_path)
    assert bad == ["a.md: c.md (no such file)", "a.md: b.md#nowhere (no such heading)"]
