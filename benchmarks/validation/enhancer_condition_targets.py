"""Targets trained with NeRF views passed through another enhancer, from the saved configs of a
paper table's ``+ NeRF views + enhancer`` runs (everything else unchanged), measured on the
validation views (val_street, val_bev) beside those runs and their ``+ NeRF views`` runs.

Usage: python benchmarks/validation/enhancer_condition_targets.py RESULTS_JSON DATA REFERENCE_COPY ENHANCER WORK [TARGET...]
(RESULTS_JSON: a paper-table results file whose runs exist; DATA: the dataset (the saved configs may
name a removed worktree); REFERENCE_COPY: a copy of the table's StreetNeRF run, so that the new
augmentation cache is written there and not under the table's runs; ENHANCER: the .onnx; WORK: where
the new runs and WORK/targets.{json,md} go. Runs already trained under WORK are reused.)
"""
import argparse
import dataclasses
import json
import time
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.engine.config import load_config, read_config_doc  # noqa: E402
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_plugin.engine.trainer import Trainer  # noqa: E402
from nerf2gs_plugin.eval.evaluate import evaluate_run  # noqa: E402
from nerf2gs_bench.machine import machine_info, machine_line  # noqa: E402
from nerf2gs_plugin.utils.lpips import LPIPS  # noqa: E402
from nerf2gs_plugin.registry import get_method  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

SPLITS = ["val_street", "val_bev"]
AUG, ENH = " + NeRF views", " + NeRF views + enhancer"
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
for name in ("results_json", "data", "reference_copy", "enhancer", "work"):
    ap.add_argument(name, type=Path)
ap.add_argument("targets", nargs="*", help="row labels (default: every row with an enhancer)")
args = ap.parse_args()
results_json, data, ref_copy, enhancer, work = args.results_json, args.data, args.reference_copy, args.enhancer, args.work
table = json.loads(results_json.read_text())["results"]
root = results_json.resolve().parents[2]  # run_dir entries are relative to the repository
targets = args.targets or [label[: -len(ENH)] for label in table if label.endswith(ENH)]
lpips_model = LPIPS.load_default(device="cpu")


def evaluated(run_dir: Path, cache: Path) -> dict:
    if not cache.is_file():
        res = evaluate_run(load_run(run_dir, device="cpu", data=data), SPLITS, render_dir=None, lpips_model=lpips_model)["results"]
        atomic_write_text(cache, json.dumps({s: {k: res[s].get(k) for k in ("psnr", "ssim", "lpips", "num_images")} for s in SPLITS}))
    return json.loads(cache.read_text())


rows, t0 = {}, time.time()
for target in targets:
    old = root / table[target + ENH]["run_dir"]
    method = read_config_doc(old / "config.yml")["method_name"]
    cfg = load_config(old / "config.yml", get_method(method).config)
    cfg = dataclasses.replace(cfg, data=data, augment_from=ref_copy, augment=dataclasses.replace(cfg.augment, enhancer=f"onnx:{enhancer}"),
                              output_dir=work / "runs", timestamp=target, progress=False)
    done = list((work / "runs").glob(f"*/{method}/{target}/checkpoints/*.ckpt"))
    t = time.time()
    if done:
        new = done[0].parents[1]
    else:
        trainer = Trainer(cfg)
        trainer.setup()
        new = trainer.train()
    seconds = time.time() - t
    rows[target] = {"without": evaluated(root / table[target + AUG]["run_dir"], work / f"{target}_without.json"),
                    "enhancer": evaluated(old, work / f"{target}_enhancer.json"),
                    "new": evaluated(new, work / f"{target}_new.json"), "new_run": str(new), "new_seconds": seconds}
    print(target, {k: {s: round(v[s]["psnr"], 2) for s in SPLITS} for k, v in rows[target].items() if isinstance(v, dict)}, flush=True)

lines = ["| target | PSNR val_street without / enhancer / new | PSNR val_bev without / enhancer / new | LPIPS val_bev without / enhancer / new |",
         "|---|---|---|---|"]
for target, r in rows.items():
    cell = lambda s, m: " / ".join(f"{r[k][s][m]:.{2 if m == 'psnr' else 3}f}" for k in ("without", "enhancer", "new"))  # noqa: E731
    lines.append(f"| {target} | {cell('val_street', 'psnr')} | {cell('val_bev', 'psnr')} | {cell('val_bev', 'lpips')} |")
info = machine_info()
doc = {"title": "Targets with NeRF views through another enhancer", "machine": info, "source": str(results_json), "enhancer": str(enhancer),
       "date": time.strftime("%Y-%m-%d"), "seconds": time.time() - t0, "results": rows}
md = (f"# Targets with NeRF views through another enhancer\n\nMachine: {machine_line(info)}\n\n"
      f"`{enhancer}` in place of the table's enhancer in each `+ NeRF views + enhancer` run of `{results_json}` (same config otherwise); "
      "without = `+ NeRF views`, enhancer = the table's `+ NeRF views + enhancer`, new = retrained with this enhancer.\n\n"
      + "\n".join(lines) + "\n")
atomic_write_text(work / "targets.json", json.dumps(doc, indent=1, default=str))
atomic_write_text(work / "targets.md", md)
print(md)
