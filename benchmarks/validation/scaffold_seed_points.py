"""Scaffold-GS + bird's-eye views with the seed points (anchors where only the views from above see the scene)
against without them, at the quick bench's steps, on two synthetic streets: the test PSNRs and the holes from
above (the share of pixels the target leaves empty on the augmentation's own bird's-eye cameras).

Why: Scaffold-GS starts from anchors on the sparse points' voxels; the seed points (``--augment.seed-points``)
give it anchors on the ground that only the bird's-eye views see, as they give Splatfacto and 2DGS Gaussians.

Usage: python benchmarks/validation/scaffold_seed_points.py WORK SEED=REFERENCE_RUN ...
  WORK as view_families.py's (streets WORK/street-seedN, runs WORK/runs); REFERENCE_RUN a finished quick
  StreetNeRF bench run of that street. Writes benchmarks/results/scaffold_seed_points.{json,md}.
"""
import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from view_families import RESULTS, run_augmented, street  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_bench.real_captures import holes_from_above  # noqa: E402
from nerf2gs_bench.runner import EVAL_SPLITS, BenchRunner  # noqa: E402
from nerf2gs_plugin.augment.config import AugmentConfig  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

TARGET = "scaffold-gs"
VARIANTS = {"seed points": 1.0, "no seed points": 0.0}
ABOVE_VIEWS = 12
SPLITS = ("street", "bev_1", "bev_2", "lane_2", "lane_4")


def one_street(work: Path, seed: int, ref_dir: Path) -> dict[str, dict]:
    """Each variant's test PSNRs, anchors and holes from above on street ``seed``."""
    data = street(work, seed)
    key = json.loads((ref_dir / "bench_run.json").read_text())["key"]
    runner = BenchRunner(work / "runs", splits=EVAL_SPLITS)
    aug = AugmentConfig()
    out = {}
    for name, share in VARIANTS.items():
        res = run_augmented(runner, data, (ref_dir, key), f"{TARGET} + birds-eye ({name})", {"seed_points": share}, target=TARGET)
        if res.get("failed"):
            out[name] = {"failed": res["error"]}
            continue
        holes = holes_from_above(Path(res["run_dir"]), aug.delta_h, aug.theta_pitch, ABOVE_VIEWS)[0]
        out[name] = {"psnr": {s: res["results"][s]["psnr"] for s in SPLITS}, "anchors": res["size"]["primitives"],
                     "megabytes": res["size"]["megabytes"], "holes_from_above": holes, "run_dir": res["run_dir"]}
    return out


def markdown(doc: dict) -> str:
    lines = ["# Scaffold-GS with the seed points (`benchmarks/validation/scaffold_seed_points.py`)", "",
             f"Machine: {doc['machine']}", "",
             "Scaffold-GS + StreetNeRF's bird's-eye views (quick scale: StreetNeRF 1500, Scaffold-GS 800 steps), "
             "`--augment.seed-points 1.0` (the default) against 0; holes from above: the share of empty pixels "
             f"(accumulation < 0.5) on {ABOVE_VIEWS} of the augmentation's bird's-eye cameras. One run each.", "",
             "| street | variant | " + " | ".join(f"PSNR {s}" for s in SPLITS) + " | holes from above | anchors | MB |",
             "|---" * (5 + len(SPLITS)) + "|"]
    for seed, rows in doc["streets"].items():
        for name, r in rows.items():
            if "failed" in r:
                lines.append(f"| seed {seed} | {name} | failed: {r['failed']} |")
                continue
            lines.append(f"| seed {seed} | {name} | " + " | ".join(f"{r['psnr'][s]:.2f}" for s in SPLITS)
                         + f" | {100 * r['holes_from_above']:.1f}% | {r['anchors']} | {r['megabytes']:.1f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("work", type=Path)
    ap.add_argument("references", nargs="+", metavar="SEED=REFERENCE_RUN")
    args = ap.parse_args()
    given = dict(a.split("=", 1) for a in args.references)
    doc = {"machine": machine_line(), "streets": {seed: one_street(args.work, int(seed), Path(ref)) for seed, ref in given.items()}}
    out = RESULTS / "scaffold_seed_points"
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    atomic_write_text(out.with_suffix(".md"), markdown(doc))
    print(markdown(doc))


if __name__ == "__main__":
    main()
