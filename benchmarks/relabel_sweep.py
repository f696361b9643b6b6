"""A model-size sweep read with another of its runs as the default, after the default changed to that run's
configuration (no run is retrained: the labels, the default mark and the picks change).

Usage: python benchmarks/relabel_sweep.py SRC_DIR OUT_DIR NEW_DEFAULT_LABEL SUFFIX "NOTE"

SRC_DIR/model_size.json is ``ns2gs-bench model-size``'s output. The run labelled NEW_DEFAULT_LABEL becomes
"<method> default"; the old default and every other run made under the old default's value get SUFFIX appended
(e.g. " prune_margin_db=3") unless their label already names that field; the picks (best, smallest within
0.5 dB, where the default stands) are recomputed by the bench's own code and written to OUT_DIR/model_size.
{json,md,png} with NOTE (which code made the runs, why they still are the configurations named) above the table.
Used for issue 20's prune_margin sweeps (made at 2DGS's prune-margin-db 3, read at 2).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from nerf2gs_bench.runner import write_bench_files  # noqa: E402
from nerf2gs_bench.size import chart, markdown, smallest_within  # noqa: E402


def relabel(rows: list[dict], new_default: str, suffix: str, keep: tuple[str, ...] = ()) -> list[dict]:
    """``rows`` with ``new_default`` as "<method> default" and ``suffix`` on the runs of the old default's value
    (every run but the new default, those whose label already names the field, and ``keep``)."""
    field = suffix.strip().split("=", 1)[0]
    if not any(r["label"] == new_default for r in rows):
        raise SystemExit(f"no run labelled '{new_default}' in the sweep")
    out = []
    for r in rows:
        r = dict(r)
        if r["label"] == new_default:
            r.update(label=f"{r['method']} default", default=True)
        elif r["label"].endswith(" default"):
            r.update(label=f"{r['method']}{suffix}", default=False)
        elif f" {field}=" not in r["label"] and r["label"] not in keep:
            r["label"] = r["label"] + suffix
        out.append(r)
    return out


def main(src: str, out: str, new_default: str, suffix: str, note: str, *keep: str) -> None:
    d = json.loads((Path(src) / "model_size.json").read_text())
    rows = relabel(d["rows"], new_default, suffix, keep)
    best = smallest_within(rows)
    payload = {k: v for k, v in d.items() if k not in ("title", "machine", "rows", "picks")}
    payload.update(rows=rows, picks=best, relabelled_from=str(src), note=note)
    body = f"{note}\n\n{markdown(rows, best)}\n\n![model size](model_size.png)\n"
    md = write_bench_files(Path(out), "model_size", d["title"], payload, body, machine=d["machine"])
    chart(rows, best, Path(out) / "model_size.png", d["title"])
    print(md)


if __name__ == "__main__":
    if len(sys.argv) < 6:
        raise SystemExit(__doc__)
    main(*sys.argv[1:])
