"""The enhancer's selection re-checked on the validation views (val_street, val_bev), never the test views.

Usage: python benchmarks/validation/enhancer.py [RESULTS_JSON] [OUT_DIR]
(RESULTS_JSON: a paper-table results file, default benchmarks/results/paper_table.json; its runs must
exist on disk. Writes OUT_DIR/enhancer_val.{json,md}, default benchmarks/results.)

The enhancer exports the state that scores best on held-out *training* views (the identity included:
`nerf2gs_plugin/enhancer/train.py`), so no test view chose it. This script asks whether that choice
holds on views no table reports: for every target, `+ NeRF views` against `+ NeRF views + enhancer`
(same reference, same steps) on val_street and val_bev, with LPIPS when its weights are available.
"""
import argparse
import json
import time
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_bench.runner import fmt  # noqa: E402
from nerf2gs_plugin.eval.evaluate import evaluate_run  # noqa: E402
from nerf2gs_plugin.utils.lpips import LPIPS  # noqa: E402
from nerf2gs_bench.machine import machine_info, machine_line  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

SPLITS = ["val_street", "val_bev"]
AUG, ENH = " + NeRF views", " + NeRF views + enhancer"

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("results_json", type=Path, nargs="?", default=Path("benchmarks/results/paper_table.json"))
ap.add_argument("out_dir", type=Path, nargs="?", default=Path("benchmarks/results"))
args = ap.parse_args()
results_json, out_dir = args.results_json, args.out_dir
table = json.loads(results_json.read_text())["results"]
targets = [label[: -len(ENH)] for label in table if label.endswith(ENH)]
lpips_model = LPIPS.load_default(device="cpu")
rows, t0 = {}, time.time()
for target in targets:
    for label in (target + AUG, target + ENH):
        run = load_run(Path(table[label]["run_dir"]), device="cpu")
        res = evaluate_run(run, SPLITS, render_dir=None, lpips_model=lpips_model)["results"]
        rows[label] = {s: {k: res[s].get(k) for k in ("psnr", "ssim", "lpips", "num_images")} for s in SPLITS}
        print(label, {s: round(rows[label][s]["psnr"], 2) for s in SPLITS}, flush=True)



lines = ["| target | d PSNR val_street | d PSNR val_bev | d LPIPS val_bev | PSNR val_bev without / with |", "|---|---|---|---|---|"]
deltas = {}
for target in targets:
    a, b = rows[target + AUG], rows[target + ENH]
    d = {s: b[s]["psnr"] - a[s]["psnr"] for s in SPLITS}
    dl = None if a["val_bev"]["lpips"] is None else b["val_bev"]["lpips"] - a["val_bev"]["lpips"]
    deltas[target] = {"psnr_val_street": d["val_street"], "psnr_val_bev": d["val_bev"], "lpips_val_bev": dl}
    lines.append(f"| {target} | {d['val_street']:+.2f} | {d['val_bev']:+.2f} | {'n/a' if dl is None else f'{dl:+.3f}'} | "
                 f"{fmt(a['val_bev']['psnr'])} / {fmt(b['val_bev']['psnr'])} |")
info = machine_info()
doc = {"title": "The enhancer on the validation views", "machine": info, "source": str(results_json),
       "how": f"benchmarks/validation/enhancer.py on the runs of {results_json}; splits {SPLITS}",
       "date": time.strftime("%Y-%m-%d"), "seconds": time.time() - t0, "results": rows, "enhancer_minus_without": deltas}
md = (f"# The enhancer on the validation views\n\nMachine: {machine_line(info)}\n\n"
      f"`python benchmarks/validation/enhancer.py` on the runs of `{results_json}`: each target's `+ NeRF views` run "
      "against `+ NeRF views + enhancer` (same reference and steps) on val_street and val_bev, views no table reports. "
      "The enhancer's exported state was chosen on held-out training views.\n\n" + "\n".join(lines) + "\n")
out_dir.mkdir(parents=True, exist_ok=True)
atomic_write_text(out_dir / "enhancer_val.json", json.dumps(doc, indent=1, default=str))
atomic_write_text(out_dir / "enhancer_val.md", md)
print(md)
