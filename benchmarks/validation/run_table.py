"""A table of finished bench runs, read from their folders: the evidence of a default or a diagnosis
made from a handful of ``BenchRunner`` runs (each trained with the overrides its ``bench_run.json``
records), without retraining anything.

Usage: python benchmarks/validation/run_table.py OUT_STEM ROWS.json
ROWS.json: {"title": ..., "about": ..., "rows": [{"scene": ..., "variant": ..., "run": RUN_DIR,
"splits": "val" | "test" | "eval"}, ...]} (or, for a plain ``ns2gs-train`` run, ``"eval": EVAL.json`` that
``ns2gs-eval`` wrote instead of ``"run"``); RUN_DIR and EVAL.json may start with a root of the plans' runner
(``{bench_runs}``, ``{val_runs}``: ``NS2GS_BENCH_RUNS``, ``NS2GS_VAL_RUNS``, see ``nerf2gs_bench/plans.py``); "val" reads the run's validation evaluation
(val_street, val_bev), "test" / "eval" its bench evaluation (a photo set's held-out photos, or the
street / bird's-eye views).
Produced: benchmarks/results/appearance_reg.{json,md} (rows: benchmarks/validation/appearance_reg_rows.json),
benchmarks/results/castle_floaters.{json,md} (rows: benchmarks/validation/castle_floaters_rows.json),
benchmarks/results/path_clearance.{json,md} (rows: benchmarks/validation/path_clearance_rows.json),
benchmarks/results/castle_confidence.{json,md} (rows: benchmarks/validation/castle_confidence_rows.json),
benchmarks/results/augment_appearance.{json,md} (rows: benchmarks/validation/augment_appearance_rows.json),
benchmarks/results/depth_loss.{json,md} (rows: benchmarks/validation/depth_loss_rows.json),
benchmarks/results/views_budget/castle_val.{json,md} (rows: benchmarks/validation/views_budget_castle_rows.json),
benchmarks/results/prune_margin/castle_val.{json,md} (rows: benchmarks/validation/prune_margin_castle_rows.json),
benchmarks/results/augment_weight_val.{json,md} (rows: benchmarks/validation/augment_weight_rows.json),
benchmarks/results/reference_length_val.{json,md} (rows: benchmarks/validation/reference_length_rows.json),
benchmarks/results/castle_bev_geometry_val.{json,md} (rows: benchmarks/validation/castle_bev_geometry_rows.json),
benchmarks/results/castle_steps_capacity_val.{json,md} (rows: benchmarks/validation/castle_steps_capacity_rows.json),
benchmarks/results/coarse_to_fine_synthetic.{json,md} (rows: benchmarks/validation/coarse_to_fine_synthetic_rows.json).
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.runner import EVAL_SPLITS, VAL_SPLITS, eval_cache_name
from nerf2gs_bench.machine import machine_line
from nerf2gs_bench.plans import expand_roots
from nerf2gs_plugin.registry import get_method
from nerf2gs_plugin.utils.io import atomic_write_text


def results(run: Path, splits: str) -> dict:
    name = eval_cache_name(VAL_SPLITS if splits == "val" else EVAL_SPLITS)
    return json.loads((run / name).read_text())["results"]


def plain_run(r: dict) -> tuple[dict, int, object]:
    """A row of a plain ``ns2gs-train`` run scored by ``ns2gs-eval`` (``"eval": EVAL.json``): its splits' results
    (the validation ones for "val", else the bench's), steps and primitives."""
    doc = json.loads(Path(r["eval"]).read_text())
    keep = VAL_SPLITS if r["splits"] == "val" else EVAL_SPLITS
    return {k: v for k, v in doc["results"].items() if k in keep}, doc["step"] + 1, doc.get("size", {}).get("primitives")


def bench_run(r: dict) -> tuple[dict, int, object]:
    """A row of a ``BenchRunner`` run (``"run": RUN_DIR``): as :func:`plain_run`."""
    res = results(Path(r["run"]), r["splits"])
    spec = json.loads((Path(r["run"]) / "bench_run.json").read_text())
    # not bench_io.planned_steps: a row may be a run of code that was tried and not kept, whose overrides name
    # fields today's config lacks; only its step count is read, the method's default when it set none
    steps = spec["overrides"].get("max_num_iterations") or get_method(spec["method"]).config.max_num_iterations
    size = json.loads((Path(r["run"]) / eval_cache_name(EVAL_SPLITS)).read_text()).get("size", {})
    return res, steps, size.get("primitives")


def main(out: Path, rows_path: Path) -> None:
    doc = json.loads(rows_path.read_text())
    rows = []
    for r in doc["rows"]:
        r = {**r, **{k: expand_roots(r[k]) for k in ("run", "eval") if k in r}}
        res, steps, primitives = plain_run(r) if "eval" in r else bench_run(r)
        psnr = {k: round(v["psnr"], 2) for k, v in res.items()}
        per_view = {k: [round(x, 2) for x in v["psnr_per_image"]] for k, v in res.items() if v.get("psnr_per_image")}
        rows.append({**r, "steps": steps, "primitives": primitives, "psnr": psnr,
                     "mean": round(sum(psnr.values()) / len(psnr), 2), "psnr_per_view": per_view})
    lines = [f"# {doc['title']}", "", f"Machine: {machine_line()}", "", doc["about"], "",
             "| scene | variant | steps | primitives | PSNR per split | mean | PSNR per view (photo sets) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        views = "; ".join(" / ".join(f"{x:.2f}" for x in v) for k, v in r["psnr_per_view"].items() if k == "test")
        lines.append(f"| {r['scene']} | {r['variant']} | {r['steps']} | {r['primitives'] if r['primitives'] is not None else 'n/a'} | " + ", ".join(f"{k} {v:.2f}" for k, v in r["psnr"].items())
                     + f" | {r['mean']:.2f} | {views} |")
    atomic_write_text(out.with_suffix(".json"), json.dumps({"machine": machine_line(), "title": doc["title"], "rows": rows}, indent=1))
    atomic_write_text(out.with_suffix(".md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_stem", type=Path)
    ap.add_argument("rows", type=Path, help="ROWS.json")
    args = ap.parse_args()
    main(args.out_stem, args.rows)
