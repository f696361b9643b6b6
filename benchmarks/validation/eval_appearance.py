"""Which per-image colour transform a StreetNeRF should render unseen cameras with
(``--pipeline.model.eval-appearance mean|identity|nearest``), measured on finished runs.

Why: StreetNeRF's held-out renders of the castle-P30 photos were tinted blue and desaturated
(``real_photos_renders.png``). Its appearance model is a per-training-image affine colour transform;
a camera that is not a training image gets the mean transform. Each mode renders the run's eval
views for real (``render_camera``); the NeRF-W protocol (an affine fitted on the left half of the
photo, scored on the right half) is a diagnostic of how much a per-view colour fix could give at
most, not a mode: it looks at the photo.

Usage: python benchmarks/validation/eval_appearance.py OUT_STEM RUN:SPLIT[:LABEL[:DATA]] ...
(DATA: the run's dataset when its recorded path has moved).
Produced benchmarks/results/eval_appearance.{json,md} with the real-photos bench's StreetNeRF
(castle-P30, split test) and the quick paper-table StreetNeRF on the synthetic street (split street).
"""
import argparse
import json
import time
import warnings
from pathlib import Path

import torch

torch.set_num_threads(1)
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

MODES = ("mean", "identity", "nearest")


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(-10 * torch.log10(((a - b) ** 2).mean()))


def half_fit(raw: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """The affine colour map fitted (least squares) from the identity render to the photo on the left half."""
    h, w, _ = raw.shape
    x = torch.cat([raw[:, : w // 2].reshape(-1, 3), torch.ones(h * (w // 2), 1)], 1)
    a = torch.linalg.lstsq(x, gt[:, : w // 2].reshape(-1, 3)).solution  # [4, 3]
    return (torch.cat([raw.reshape(-1, 3), torch.ones(h * w, 1)], 1) @ a).reshape(h, w, 3).clamp(0, 1)


def measure(run_dir: Path, split: str, data: Path | None = None) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = load_run(run_dir, device="cpu", data=data)
    model, dm = run.model, run.pipeline.datamanager
    views = list(dm.eval_images(split))
    res = {m: {"psnr": [], "psnr_right": []} for m in (*MODES, "fit on left half")}
    t0 = time.time()
    for cam, batch in views:
        gt = batch["image"][..., :3]
        w = gt.shape[1]
        for mode in MODES:
            model.config.eval_appearance = mode
            img = model.render_camera(cam)["rgb"]
            res[mode]["psnr"].append(psnr(img, gt))
            res[mode]["psnr_right"].append(psnr(img[:, w // 2:], gt[:, w // 2:]))
            if mode == "identity":
                fit = half_fit(img, gt)
                res["fit on left half"]["psnr"].append(psnr(fit, gt))
                res["fit on left half"]["psnr_right"].append(psnr(fit[:, w // 2:], gt[:, w // 2:]))
    model.config.eval_appearance = "mean"
    T = model.appearance.transforms.detach()
    return {"run": str(run_dir), "split": split, "views": len(views), "seconds": round(time.time() - t0, 1),
            "modes": {m: {k: sum(v) / len(v) for k, v in r.items()} | {"per_view": r["psnr"]} for m, r in res.items()},
            "mean_transform": [[round(float(v), 4) for v in row] for row in T.mean(0)],
            "transform_offset_std": [round(float(v), 4) for v in T[:, :, 3].std(0)]}


def markdown(doc: dict) -> str:
    lines = ["# StreetNeRF: the colour transform of unseen cameras (`--pipeline.model.eval-appearance`)", "",
             f"Machine: {doc['machine']}", "", __doc__.split("Usage:")[0].strip(), "",
             "| run | split | views | mean (default) | identity | nearest | right half: mean | right half: nearest | right half: fit on left half |",
             "|---|---|---|---|---|---|---|---|---|"]
    for label, r in doc["runs"].items():
        m = r["modes"]
        lines.append(f"| {label} | {r['split']} | {r['views']} | {m['mean']['psnr']:.2f} | {m['identity']['psnr']:.2f} | "
                     f"{m['nearest']['psnr']:.2f} | {m['mean']['psnr_right']:.2f} | {m['nearest']['psnr_right']:.2f} | "
                     f"{m['fit on left half']['psnr_right']:.2f} |")
    lines += ["", "PSNR (dB), mean over the split's views; 'right half' columns score only the right half of each "
              "image (the NeRF-W protocol fits its colour map on the left half)."]
    for label, r in doc["runs"].items():
        lines += ["", f"{label}: mean transform {r['mean_transform']}; std of the per-image offsets {r['transform_offset_std']}; "
                  f"run {r['run']}"]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_stem", type=Path)
    ap.add_argument("runs", nargs="+", help="RUN:SPLIT[:LABEL[:DATA]]")
    args = ap.parse_args()
    out = args.out_stem
    doc = {"machine": machine_line(), "runs": {}}
    for arg in args.runs:
        run, split, *rest = arg.split(":")
        label = rest[0] if rest else Path(run).name
        doc["runs"][label] = measure(Path(run), split, Path(rest[1]) if len(rest) > 1 else None)
        print(json.dumps(doc["runs"], indent=1)[-600:], flush=True)
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    atomic_write_text(out.with_suffix(".md"), markdown(doc))


if __name__ == "__main__":
    main()
