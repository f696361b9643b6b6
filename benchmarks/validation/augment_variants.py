"""A finished ``target + NeRF views`` run trained again with other ``--augment.*`` settings, every
variant beside the run itself, its baseline (no NeRF views) and its reference, on the same splits.

Why: ``--augment.real-only-from`` (a final phase on the input views alone) and ``--augment.confidence``
are meant to keep street views from paying for the views from above, most of all where the reference
is weak (a real photo set); this measures what they do to both, on a real capture and a synthetic
street, from the saved configs of bench runs (everything else unchanged). Choose on validation
splits where a scene has them (``val_street``, ``val_bev``); a real capture has only its held-out
photos (``test``), so there the figures are a measurement, not a selection.

Usage: python benchmarks/validation/augment_variants.py OUT_STEM SCENE:RUN:BASELINE:REFERENCE:SPLITS WORK VARIANT...
  SPLITS comma-separated; VARIANT name=key=json[,key=json] e.g. ro09=augment.real_only_from=0.9
  Variants already trained under WORK/<scene>/<name> (with eval.json) are reused.
Produced benchmarks/results/augment_variants.{json,md} and augment_spread.{json,md}: the calls are the plans
benchmarks/plans/augment_variants.yaml and augment_spread.yaml (``python -m nerf2gs_bench.plans run augment_variants``).
"""
import argparse
import dataclasses
import json
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from nerf2gs_plugin.engine.config import load_config, read_config_doc  # noqa: E402
from nerf2gs_plugin.runs.load import load_run  # noqa: E402
from nerf2gs_plugin.engine.trainer import Trainer  # noqa: E402
from nerf2gs_bench.size import _nested  # noqa: E402
from nerf2gs_plugin.eval.evaluate import evaluate_run  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.registry import get_method  # noqa: E402
from nerf2gs_plugin.utils.config import apply_plain  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402


def evaluated(run: Path, splits: list[str], out: Path) -> dict:
    """``out`` (eval JSON) of ``run`` on ``splits``, made once."""
    if not out.is_file():
        result = evaluate_run(load_run(run), splits, render_dir=out.parent / f"{out.stem}_renders")
        atomic_write_text(out, json.dumps(result, indent=1))
    return json.loads(out.read_text())


def trained(run: Path, work: Path, name: str, changes: dict) -> Path:
    """``run``'s saved config with ``changes``, trained under ``work`` as ``name`` (reused when finished)."""
    method = read_config_doc(run / "config.yml")["method_name"]
    cfg = load_config(run / "config.yml", get_method(method).config)
    for k, v in changes.items():  # the config machinery's own nested, type-checked override
        cfg = apply_plain(cfg, _nested(k, v), where=f"variant {name}")
    cfg = dataclasses.replace(cfg, output_dir=work, timestamp=name, progress=False)
    done = list(work.glob(f"*/{method}/{name}/checkpoints/*.ckpt"))
    if done:
        return done[0].parents[1]
    trainer = Trainer(cfg)
    trainer.setup()
    return trainer.train()


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition("=")
    changes = {}
    for kv in rest.split(","):
        k, _, v = kv.partition("=")
        changes[k] = json.loads(v)
    return name, changes


def summary(res: dict, splits: list[str]) -> dict:
    return {s: {m: res["results"][s].get(m) for m in ("psnr", "ssim", "lpips", "psnr_ground")} for s in splits} | {
        "primitives": res["size"].get("primitives") if res["size"].get("primitive_kind", "primitives") else None,  # not a NeRF's hash entries
        "train_seconds": res.get("train_seconds")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_stem", type=Path)
    ap.add_argument("scene", help="SCENE:RUN:BASELINE:REFERENCE:SPLITS (splits comma-separated)")
    ap.add_argument("work", type=Path)
    ap.add_argument("variants", nargs="*", help="NAME:FIELD=VALUE,... (see parse_variant)")
    args = ap.parse_args()
    out_stem, scene_arg, work = args.out_stem, args.scene, args.work
    scene, run, baseline, reference, splits = scene_arg.split(":")
    splits = splits.split(",")
    run, baseline, reference = Path(run), Path(baseline), Path(reference)
    work = work / re.sub(r"\W", "", scene.split(" ")[0])  # "castle-P30" -> castleP30, "2DGS," -> 2DGS
    work.mkdir(parents=True, exist_ok=True)
    rows = {"reference": summary(evaluated(reference, splits, work / "reference_eval.json"), splits),
            "baseline (no NeRF views)": summary(evaluated(baseline, splits, work / "baseline_eval.json"), splits),
            "NeRF views": summary(evaluated(run, splits, work / "run_eval.json"), splits)}
    variants = {}
    for text in args.variants:
        name, changes = parse_variant(text)
        rd = trained(run, work, name, changes)
        label = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in changes.items())
        rows[f"NeRF views, {label}"] = summary(
            evaluated(rd, splits, work / f"{name}_eval.json"), splits)
        variants[name] = changes
    path = out_stem.with_suffix(".json")
    doc = json.loads(path.read_text()) if path.is_file() else {"scenes": {}}
    doc["machine"] = machine_line()
    doc["scenes"][scene] = {"run": str(run), "baseline": str(baseline), "reference": str(reference), "splits": splits,
                            "variants": variants, "rows": rows}
    atomic_write_text(path, json.dumps(doc, indent=1))
    lines = ["# Augmentation variants from saved bench configs (`benchmarks/validation/augment_variants.py`)", "",
             f"Machine: {doc['machine']}", ""]
    for sc, d in doc["scenes"].items():
        lines += [f"## {sc}", "", f"Run `{d['run']}` trained again with each variant (everything else as saved).", "",
                  "| row | " + " | ".join(f"PSNR {s}" for s in d["splits"]) + " | " + " | ".join(f"LPIPS {s}" for s in d["splits"])
                  + " | primitives |", "|---" * (2 * len(d["splits"]) + 2) + "|"]
        for label, r in d["rows"].items():
            ps = " | ".join(f"{r[s]['psnr']:.2f}" for s in d["splits"])
            lp = " | ".join(f"{r[s]['lpips']:.3f}" if r[s]["lpips"] is not None else "n/a" for s in d["splits"])
            lines.append(f"| {label} | {ps} | {lp} | {r['primitives'] or '(NeRF)'} |")
        lines.append("")
    atomic_write_text(out_stem.with_suffix(".md"), "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
