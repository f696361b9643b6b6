"""Splatfacto alone vs + bird's-eye views vs + bird's-eye and lane-shift views (``--augment.views``),
all from one StreetNeRF reference, at the quick bench's step counts, on the embedded street
(generator version 3: it has the lane-shift ground truth lane_1/lane_2/lane_4).

Why: the lane-shift family is meant to teach the target the views one lane over (lane_2, lane_4)
without costing the bird's-eye or street views; this measures that, same reference, same steps.

Usage: python benchmarks/validation/view_families.py WORK [SEED]
  WORK holds the street (WORK/street-seedN) and the runs (WORK/runs); runs already trained are reused.
Writes benchmarks/results/view_families.{json,md} (seed 0) or view_families_seedN.{json,md}.
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street, read_generator_version  # noqa: E402
from nerf2gs_bench.paper import _overrides, ratios_md, run_plan, write_results  # noqa: E402
from nerf2gs_bench.runs import RunSpec  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("work", type=Path)
ap.add_argument("seed", type=int, nargs="?", default=0)
args = ap.parse_args()
work, seed = args.work, args.seed
data = work / f"street-seed{seed}"
if read_generator_version(data) != 3:
    generate_street(SynthStreetConfig(out=data, seed=seed, overwrite=True))
t = "splatfacto"
plan = [RunSpec("StreetNeRF", "streetnerf", _overrides("quick", "streetnerf")),
        RunSpec(t, t, _overrides("quick", t)),
        RunSpec(f"{t} + birds-eye", t, _overrides("quick", t), augment_from="StreetNeRF"),
        RunSpec(f"{t} + birds-eye lane-shift", t, _overrides("quick", t), augment_from="StreetNeRF",
                augment={"views": ["birds-eye", "lane-shift"]})]
results = run_plan(plan, data, work / "runs", name="view_families")
pairs = [(f"{t} + birds-eye", t), (f"{t} + birds-eye lane-shift", t), (f"{t} + birds-eye lane-shift", f"{t} + birds-eye")]
name = "view_families" if seed == 0 else f"view_families_seed{seed}"
note = (f"Street seed {seed} (200x112, generator version 3), quick-bench steps (StreetNeRF 1500, Splatfacto 800), one run each; "
        "lane-shift: the family's defaults (offsets -2 and +2 m, every input view). "
        "`python benchmarks/validation/view_families.py WORK" + (f" {seed}" if seed else "") + "`.\n\n")
write_results(Path(__file__).resolve().parents[1] / "results", name, results, "View families (synthetic street, quick scale)",
              extra_md=note + "Differences, same bench run:\n\n" + ratios_md(results, pairs) + "\n")
