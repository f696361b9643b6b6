"""Why a target trained with NeRF views stays below its reference from above: does it fail to FIT the
reference's bird's-eye renders, or fit them and fail to carry that to other cameras from above?

For each "<target> + NeRF views" row of a paper table (and the table's StreetNeRF), it renders:
* the augmentation's own bird's-eye cameras (the training pose raised by delta-h, pitched by theta,
  as ``ViewGeometry.cameras`` makes them): PSNR of the target against the reference's render there (what
  it was trained on; the reference render is the only truth the target ever had there);
* the test cameras from above (bev_1, bev_2): PSNR of the target against the reference's render
  there, and of both against the true images.
A high first number with a low second says the target fits the views it was given and does not
generalise from them to other heights/pitches (view coverage); a low first number says capacity or
optimisation. Only the training views' cameras are reconstructed: no test image tunes anything.

Usage: python benchmarks/validation/fit_vs_generalise.py OUT_STEM TABLE.json DATA [TABLE.json DATA ...]
Produced benchmarks/results/fit_vs_generalise.{json,md} from default/paper_table.json (the embedded
street) and second_scene/paper_table.json (benchmarks/runs/data/street-seed7).
"""
import argparse
import json
import warnings
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.augment.datamanager import AugmentConfig  # noqa: E402
from nerf2gs_plugin.augment.geometry import ViewGeometry  # noqa: E402
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_plugin.runs.model import load_run_model  # noqa: E402
from nerf2gs_bench.runner import write_bench_files  # noqa: E402
from nerf2gs_plugin.utils.image_metrics import psnr  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("out_stem", type=Path)
ap.add_argument("pairs", nargs="+", help="PAPER_TABLE_JSON BENCH_RUNS_DIR, repeated")
args = ap.parse_args()
if len(args.pairs) % 2:
    ap.error("pairs: a paper_table.json and its runs folder each")
out = args.out_stem
pairs = list(zip(args.pairs[0::2], args.pairs[1::2]))
aug = AugmentConfig()
rows = []
for table, data in pairs:
    res = json.loads(Path(table).read_text())["results"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = load_run(Path(res["StreetNeRF"]["checkpoint"]), data=Path(data))
    dm = ref.pipeline.datamanager
    td = dm.inner.train_data if hasattr(dm, "inner") else dm.train_data
    cams = ViewGeometry.of(aug).cameras(dm.train_images.cameras, td)
    with torch.no_grad():
        ref_aug = [ref.model.render_camera(cams[i])["rgb"].cpu() for i in range(len(cams))]
        tests = {}
        for split in ("bev_1", "bev_2"):
            _, imgs = dm.eval_split(split)
            tests[split] = (imgs, [ref.model.render_camera(imgs.cameras[i])["rgb"].cpu() for i in range(len(imgs))])
        for label, r in res.items():
            if not label.endswith("+ NeRF views"):
                continue
            tgt = load_run_model(Path(r["checkpoint"])).model
            row = {"scene": Path(data).name, "target": label,
                   "fit_aug_views_vs_reference": sum(float(psnr(tgt.render_camera(cams[i])["rgb"].cpu(), ref_aug[i])) for i in range(len(cams))) / len(cams)}
            for split, (imgs, ref_r) in tests.items():
                t_r = [tgt.render_camera(imgs.cameras[i])["rgb"].cpu() for i in range(len(imgs))]
                n = len(imgs)
                row[f"{split}_target_vs_reference"] = sum(float(psnr(t_r[i], ref_r[i])) for i in range(n)) / n
                row[f"{split}_target_vs_truth"] = sum(float(psnr(t_r[i], imgs.image(i).cpu())) for i in range(n)) / n
                row[f"{split}_reference_vs_truth"] = sum(float(psnr(ref_r[i], imgs.image(i).cpu())) for i in range(n)) / n
            rows.append(row)
            print(json.dumps(row))
cols = ["fit_aug_views_vs_reference", "bev_1_target_vs_reference", "bev_2_target_vs_reference", "bev_1_target_vs_truth",
        "bev_1_reference_vs_truth", "bev_2_target_vs_truth", "bev_2_reference_vs_truth"]
md = ("Mean PSNR (dB). `fit_aug_views_vs_reference`: the target against the reference's render at the augmentation's own "
      "bird's-eye cameras (its training views from above); `bev_k_target_vs_reference`: the same comparison at the test "
      "cameras from above; `_vs_truth`: against the true images.\n\n| scene | target | " + " | ".join(cols) + " |\n|---|---|"
      + "---|" * len(cols) + "\n" + "".join(f"| {r['scene']} | {r['target']} | " + " | ".join(f"{r[c]:.2f}" for c in cols) + " |\n" for r in rows))
write_bench_files(out.parent, out.name, "Fit vs. generalisation from above (targets with NeRF views, default scale)",
                  {"rows": rows, "tables": [t for t, _ in pairs], "augment": {"delta_h": aug.delta_h, "theta_pitch": aug.theta_pitch}}, md)
print(md)
