"""The built-in enhancer unconditioned (``--condition none``, the default) against conditioned on the
nearest training view warped in (``--condition warped``), both trained at the bench's quick settings
on one StreetNeRF reference, then measured alone on that reference's renders of the validation views
(val_street, val_bev; never the test views): PSNR and LPIPS before/after, as ``ns2gs-enhance eval``.

Usage: python benchmarks/validation/enhancer_condition.py REFERENCE_RUN DATA OUT_DIR [SCALE]
(SCALE: a bench enhancer scale, default quick. Writes OUT_DIR/{none,warped}/enhancer.onnx (+ report)
and OUT_DIR/enhancer_condition.{json,md}; a model already there with its report is evaluated again, not retrained.)
"""
import argparse
import dataclasses
import json
import time
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.cli.enhance import evaluate_enhancer  # noqa: E402
from nerf2gs_bench.enhancer import bench_enhancer_config  # noqa: E402
from nerf2gs_plugin.enhancer.train import TrainReport, report_path, train_enhancer  # noqa: E402
from nerf2gs_bench.machine import machine_info, machine_line  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

SPLITS = ("val_street", "val_bev")
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("reference_run", type=Path)
ap.add_argument("data", type=Path)
ap.add_argument("out_dir", type=Path)
ap.add_argument("scale", nargs="?", default="quick")
args = ap.parse_args()
reference, data, out_dir, scale = args.reference_run, args.data, args.out_dir, args.scale
results, t0 = {}, time.time()
for condition in ("none", "warped"):
    model = out_dir / condition / "enhancer.onnx"
    cfg = dataclasses.replace(bench_enhancer_config(data, model, scale), reference=(reference,), condition=condition, threads=1)
    t = time.time()
    if model.is_file() and report_path(model).is_file():  # trained before: measured again (evaluation code changed)
        saved = json.loads(report_path(model).read_text())
        report = TrainReport(**{k: saved[k] for k in ("out", "steps", "seconds", "validation", "selected_step", "pairs")})
        print(f"[{condition}] reuse {model} (trained in {report.seconds:.0f} s)", flush=True)
    else:
        report = train_enhancer(cfg)
        for line in report.summary_lines():
            print(f"[{condition}] {line}", flush=True)
    ev = evaluate_enhancer(f"onnx:{model}", data, reference, SPLITS)
    results[condition] = {"train_seconds": report.seconds, "seconds": time.time() - t, "selected_step": report.selected_step,
                          "heldout_training_views": report.validation, "splits": ev["splits"], "pairs": report.pairs}
    print(condition, json.dumps(ev["splits"]), flush=True)

rows = ["| enhancer | split | PSNR before -> after | d PSNR | LPIPS before -> after | d LPIPS |", "|---|---|---|---|---|---|"]
for condition, r in results.items():
    for s in SPLITS:
        v = r["splits"][s]
        lp = v.get("lpips_before") is not None
        rows.append(f"| {condition} | {s} | {v['psnr_before']:.2f} -> {v['psnr_after']:.2f} | {v['psnr_after'] - v['psnr_before']:+.2f} | "
                    + (f"{v['lpips_before']:.3f} -> {v['lpips_after']:.3f} | {v['lpips_after'] - v['lpips_before']:+.3f} |" if lp else "n/a | n/a |"))
info = machine_info()
doc = {"title": "The built-in enhancer, unconditioned vs conditioned on a warped training view", "machine": info,
       "reference": str(reference), "data": str(data), "scale": scale, "splits": list(SPLITS), "date": time.strftime("%Y-%m-%d"),
       "seconds": time.time() - t0, "results": results,
       "how": f"benchmarks/validation/enhancer_condition.py {reference} {data} OUT {scale}"}
md = (f"# The built-in enhancer: unconditioned vs warped-view conditioned\n\nMachine: {machine_line(info)}\n\n"
      f"`python benchmarks/validation/enhancer_condition.py` on `{reference}` ({scale} enhancer settings): both enhancers "
      "trained on that reference's pairs (state chosen on held-out training views), then applied alone to the reference's "
      "renders of the validation views (before = the render, after = enhanced; against ground truth).\n\n" + "\n".join(rows) + "\n")
out_dir.mkdir(parents=True, exist_ok=True)
atomic_write_text(out_dir / "enhancer_condition.json", json.dumps(doc, indent=1, default=str))
atomic_write_text(out_dir / "enhancer_condition.md", md)
print(md)
