"""StreetNeRF warm-started from the masks' first reference against StreetNeRF from scratch, on real captures.

Each pair is two StreetNeRF runs of one capture with the default 3000 steps: one ``--warm-start``ed from the masks
stage's 1000-step reference (2000 steps trained here; the real path of ``ns2gs-bench real-path-speed`` and of the
README), one from scratch (``ns2gs-train streetnerf --data CAPTURE``). Both are scored by ``ns2gs-eval`` on the
capture's held-out frames (every 8th) and from above; ``--static NAME=FILE`` adds capture NAME's static PSNR
from a JSON that ``static_psnr_hand_labels.py`` wrote for its two runs (hand-labelled held-out frames).

Usage: python benchmarks/validation/warm_start_real.py OUT_STEM NAME WARM_EVAL SCRATCH_EVAL [NAME WARM SCRATCH ...]
[--static NAME=STATIC.json ...] [--kinds A B --title TITLE]
(``--kinds second-pass first-reference``: any two runs of a capture, e.g. StreetNeRF warm-started from the masks'
second-pass reference against from their first reference: produced ``warm_start_second_pass.{json,md}``; with
``--setup``, other runs than StreetNeRF's: Splatfacto + NeRF views coarse to fine against at full size throughout
produced ``coarse_to_fine_real.{json,md}``.)
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.machine import machine_line
from nerf2gs_plugin.engine.checkpoints import resolve_checkpoint
from nerf2gs_plugin.utils.io import atomic_write_text


def _row(eval_json: Path) -> dict:
    doc = json.loads(Path(eval_json).read_text())
    test = doc["results"]["test"]
    run, _ = resolve_checkpoint(Path(doc["checkpoint"]))
    warm = run / "warm_start.json"  # the step the run started from, when it was warm-started
    start = json.loads(warm.read_text())["step"] + 1 if warm.is_file() else 0
    return {"run": str(run), "steps_trained": doc["step"] + 1 - start, "held_out": test["num_images"],
            "psnr": test["psnr"], "ssim": test["ssim"], "lpips": test["lpips"], "bev_hole_fraction": doc["bev_hole_fraction"],
            "train_seconds": doc.get("train_seconds"), "size": doc.get("size")}


def _size(size) -> str:
    """The eval JSON's model size: primitives and MB, where it has them."""
    if not isinstance(size, dict):
        return "-"
    parts = ([f"{size['primitives']:,} {size.get('primitive_kind', 'primitives')}"] if "primitives" in size else []) + \
        ([f"{size['megabytes']:.1f} MB"] if "megabytes" in size else [])
    return ", ".join(parts) or "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("triples", nargs="+", help="NAME WARM_EVAL.json SCRATCH_EVAL.json, repeated")
    ap.add_argument("--static", action="append", default=[], help="NAME=static_psnr_hand_labels.py JSON of that capture's runs")
    ap.add_argument("--kinds", nargs=2, default=["warm", "scratch"], help="the two runs' labels")
    ap.add_argument("--title", default="StreetNeRF warm-started from the masks' reference vs from scratch (real captures)")
    ap.add_argument("--setup", default="Default StreetNeRF (3000 steps)", help="what the runs are, for the page's first line")
    args = ap.parse_args()
    if len(args.triples) % 3:
        ap.error("give NAME WARM_EVAL SCRATCH_EVAL per capture")
    static = {}  # capture -> run folder name -> static PSNR
    for item in args.static:
        name, _, f = item.partition("=")
        static[name] = {run: r["hand"]["static_psnr"] for run, r in json.loads(Path(f).read_text())["runs"].items()}
    doc = {"machine": machine_line(), "captures": {}}
    lines = [f"# {args.title}", "",
             f"Machine: {doc['machine']}. {args.setup}; held-out frames every 8th, scored by "
             "`ns2gs-eval`; holes from above: 16 bird's-eye views (the run's augmentation views, else a fly-over 10 m up; "
             "accumulation < 0.5). One seed each; train s: the training loop's wall seconds.", "",
             "| capture | run | steps trained | train s | PSNR | SSIM | LPIPS | static PSNR (hand labels) | holes from above | size |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for i in range(0, len(args.triples), 3):
        name, warm, scratch = args.triples[i], Path(args.triples[i + 1]), Path(args.triples[i + 2])
        rows = {args.kinds[0]: _row(warm), args.kinds[1]: _row(scratch)}
        for kind, r in rows.items():
            r["static_psnr"] = static.get(name, {}).get(Path(r["run"]).name)
            st = f"{r['static_psnr']:.2f}" if r["static_psnr"] is not None else "-"
            secs = f"{r['train_seconds']:.0f}" if r["train_seconds"] is not None else "-"
            lines.append(f"| {name} ({r['held_out']} held out) | {kind} | {r['steps_trained']} | {secs} | {r['psnr']:.2f} | {r['ssim']:.3f} | "
                         f"{r['lpips']:.3f} | {st} | {100 * r['bev_hole_fraction']:.2f}% | {_size(r['size'])} |")
        doc["captures"][name] = rows
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(doc, indent=1))
    atomic_write_text(args.out.with_suffix(".md"), "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
