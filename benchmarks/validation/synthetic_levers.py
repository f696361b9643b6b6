"""``--augment.*`` levers on synthetic streets at the product's augmentation settings: validation and test views.

``ns2gs-bench street-level --street`` trains the views from above at the input views' size and the bench's steps
(its levers were measured that way); this trains them as ``ns2gs-train --augment-from`` does by default (half-size
views, 1.4x the steps) so a default is chosen where it is used. Per street (``ns2gs-data synth-street``): StreetNeRF
600 steps, then each target alone and with NeRF views per lever and seed (700 steps before the step factor); PSNR of
the validation views (val_street, val_bev: choose on these) and the test views (street, bev_1, bev_2), means over the
seeds, and each lever's delta against the target alone. Writes OUT_STEM.{json,md}.

Usage: python benchmarks/validation/synthetic_levers.py OUT_STEM --streets DATA [DATA ...] [--targets splatfacto]
[--seeds 42 43] [--runs benchmarks/runs/synthetic_levers] [--lever "NAME=KEY=VALUE[,KEY=VALUE]" ...]
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_bench.paper import step_overrides
from nerf2gs_bench.runner import EVAL_SPLITS, VAL_SPLITS, BenchRunner, failure_reason
from nerf2gs_bench.runs import RunSpec
from nerf2gs_bench.street_level import SYNTHETIC_STEPS, augment_overrides
from nerf2gs_plugin.utils.io import atomic_write_text

SHOWN = ("val_street", "val_bev", "street", "bev_1", "bev_2")


def parse_lever(text: str) -> tuple[str, dict]:
    """``NAME=KEY=VALUE[,KEY=VALUE]`` -> (name, --augment overrides)."""
    name, _, pairs = text.partition("=")
    try:
        return name, augment_overrides([p for p in pairs.split(",") if p])
    except ValueError as e:
        raise SystemExit(f"{e} (--lever '{text}')") from None


def street_rows(data: Path, runs: Path, target: str, levers: dict[str, dict], seeds: list[int]) -> dict[str, dict[str, float]]:
    """label -> split -> mean PSNR over the seeds (``target`` alone, then each lever with NeRF views)."""
    ref = RunSpec("StreetNeRF", "streetnerf", step_overrides("streetnerf", SYNTHETIC_STEPS["streetnerf"]))
    psnr: dict[str, dict[str, list[float]]] = {}
    for splits in (VAL_SPLITS, EVAL_SPLITS):
        runner = BenchRunner(runs, splits=splits)
        done = runner.run(ref, data)
        if failure_reason(done) is not None:
            raise SystemExit(f"{data}: StreetNeRF failed: {failure_reason(done)}")
        for label, aug in {"alone": None, **levers}.items():
            for seed in seeds:
                spec = RunSpec(f"{label}, seed {seed}", target, {**step_overrides(target, SYNTHETIC_STEPS["splatfacto"]), "seed": seed},
                               augment_from="StreetNeRF" if aug is not None else None, augment=aug or {})
                out = runner.run(spec, data, reference=(Path(done.run_dir), done.key) if aug is not None else None)
                for split, r in ((out.result or {}).get("results") or {}).items():
                    psnr.setdefault(label, {}).setdefault(split, []).append(r["psnr"])
    return {label: {s: sum(v) / len(v) for s, v in d.items()} for label, d in psnr.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--streets", type=Path, nargs="+", required=True)
    ap.add_argument("--targets", nargs="+", default=["splatfacto"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[42, 43])
    ap.add_argument("--runs", type=Path, default=Path("benchmarks/runs/synthetic_levers"))
    ap.add_argument("--lever", action="append", default=[], help="NAME=KEY=VALUE[,KEY=VALUE] (repeat); 'default' is always run")
    args = ap.parse_args()
    levers = dict([("default", {}), *(parse_lever(t) for t in args.lever)])
    import subprocess

    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent).stdout.strip()
    doc = {"machine": machine_info(), "code": rev or None, "seeds": args.seeds, "levers": levers, "steps": SYNTHETIC_STEPS, "rows": {}}
    for target in args.targets:
        for street in args.streets:
            rows = street_rows(street, args.runs, target, levers, args.seeds)
            doc["rows"][f"{target} / {street.name}"] = rows
    atomic_write_text(args.out.parent / f"{args.out.name}.json", json.dumps(doc, indent=1))
    lines = ["# Levers on synthetic streets at the product's augmentation settings", "",
             f"Machine: {machine_line(doc['machine'])}; code {doc['code']} (its defaults are the rows' \"defaults\")", "",
             f"StreetNeRF {SYNTHETIC_STEPS['streetnerf']} steps; each target {SYNTHETIC_STEPS['splatfacto']} steps alone, with NeRF "
             f"views 1.4x that at half-size views from above (the defaults of --augment-from); seeds {', '.join(map(str, args.seeds))} "
             "(PSNR means over them). Deltas in dB against the target alone; val_*: validation views (choose on these), the "
             "rest test views.", ""]
    for key, rows in doc["rows"].items():
        alone = rows["alone"]
        splits = [s for s in SHOWN if s in alone]
        lines += [f"## {key}", "", "Alone: " + ", ".join(f"{s} {alone[s]:.2f}" for s in splits) + ".", "",
                  "| lever | " + " | ".join(splits) + " |", "|---|" + "---|" * len(splits)]
        for label, r in rows.items():
            if label != "alone":
                over = ", ".join(f"--augment.{k.replace('_', '-')} {v}" for k, v in levers[label].items()) or "the defaults"
                lines.append(f"| {label} ({over}) | " + " | ".join(f"{r[s] - alone[s]:+.2f}" for s in splits) + " |")
        lines.append("")
    atomic_write_text(args.out.parent / f"{args.out.name}.md", "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
