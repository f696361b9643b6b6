"""Splatfacto alone vs + bird's-eye views vs + bird's-eye and lane-shift views (``--augment.views``),
all from one StreetNeRF reference, at the quick bench's step counts, on a synthetic street
(generator version 3: it has the lane-shift ground truth lane_1/lane_2/lane_4).

Rows: each family alone and both (an ablation per family). Why: the lane-shift family is meant to teach the target the views one lane over (lane_2, lane_4)
without costing the bird's-eye or street views; this measures that, same reference, same steps:
the lane-shift views with their own share of the samples (the family's defaults, chosen on the
validation views by lane_shift_sweep.py) and, for comparison, with the one share of before
(every additional view drawn alike: bird's-eye 0.25, lane-shift 0.5 of the samples).

Usage: python benchmarks/validation/view_families.py WORK [SEED] [REFERENCE_RUN] [--target METHOD]
  WORK holds the street (WORK/street-seedN) and the runs (WORK/runs); runs already trained are reused.
  REFERENCE_RUN: a finished StreetNeRF bench run of that street to render the views from (else one is
  trained at the quick bench's steps).
  --target: scaffold-gs or 2dgs instead of Splatfacto (alone, + birds-eye, + birds-eye lane-shift).
  --scale default: every method's registered steps (alone, + birds-eye, + birds-eye lane-shift only).
Writes benchmarks/results/view_families[_default][_TARGET].{json,md,png} (seed 0) or view_families[_default][_TARGET]_seedN.{json,md,png}.
"""
import argparse
import json
import sys
from pathlib import Path
from typing import Optional

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street, read_generator_version  # noqa: E402
from nerf2gs_bench.paper import _overrides, ratios_md, run_plan, step_overrides, write_results  # noqa: E402
from nerf2gs_bench.runner import EVAL_SPLITS, BenchRunner, failure_reason  # noqa: E402
from nerf2gs_bench.runs import RunSpec  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"

TARGET = "splatfacto"
SHARED = {"birds_eye_share": 0.25, "lane_shift": {"offsets": [-2.0, 2.0], "share": 0.5}}
"""The one share of before the per-family shares, on a street of N input views (N bird's-eye, 2N lane views)."""


def street(work: Path, seed: int) -> Path:
    data = work / f"street-seed{seed}"
    if read_generator_version(data) != 3:
        generate_street(SynthStreetConfig(out=data, seed=seed, overwrite=True))
    return data


def reference(data: Path, runs: Path, given: Optional[str], evaluate: bool = True, scale: str = "quick") -> tuple[Path, str, Optional[dict]]:
    """(run folder, run key, its evaluation on the test splits or None): ``given`` or a StreetNeRF trained here at ``scale``."""
    if given:
        ref = Path(given)
        key = json.loads((ref / "bench_run.json").read_text())["key"]
        if not evaluate:
            return ref, key, None
        saved = ref / "bench_eval.json"  # the test-split evaluation its own bench made (a NeRF's renders are slow)
        if saved.is_file():
            out = json.loads(saved.read_text())
        else:
            from nerf2gs_plugin.eval.evaluate import evaluate_run
            from nerf2gs_plugin.runs.load import load_run

            out = BenchRunner(runs)._evaluate(ref, key, load_run, evaluate_run)
        return ref, key, out | {"label": "StreetNeRF", "target": "streetnerf", "run_dir": str(ref)}
    res = run_plan([RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf"))], data, runs, name="view_families")["StreetNeRF"]
    return Path(res["run_dir"]), Path(res["run_dir"]).name, res


def target_overrides(target: str, steps: Optional[int] = None, scale: str = "quick") -> dict:
    """The bench overrides of ``target``: the bench's at ``scale`` (None) or ``steps`` with its schedules rescaled."""
    return _overrides(scale, target) if steps is None else {**step_overrides(target, steps), "steps_per_eval_image": 0}


def run_augmented(runner: BenchRunner, data: Path, ref: tuple[Path, str], label: str, augment: Optional[dict],
                  target: str = TARGET, steps: Optional[int] = None, scale: str = "quick") -> dict:
    """One ``target`` run at the quick bench's steps or ``steps`` (+ ``augment``'s views from ``ref``; None: the
    target alone), evaluated on the runner's splits."""
    spec = RunSpec(label, target, target_overrides(target, steps, scale), augment_from="StreetNeRF" if augment is not None else None,
                   augment=augment or {})
    out = runner.run(spec, data, reference=ref if augment is not None else None)
    reason = failure_reason(out)
    return out.result if reason is None else {"label": label, "target": target, "failed": True, "error": reason}


def chosen_lane_shift() -> tuple[str, dict]:
    """The lane-shift options lane_shift_sweep.py chose on the validation views (its results file; when no
    variant kept the bird's-eye and street views, the best val_lane gain of those tried on both streets)."""
    doc = json.loads((RESULTS / "lane_shift_sweep.json").read_text())
    name = doc["chosen"] or max(doc["tried_on_both"], key=doc["mean_val_lane_gain"].get)
    return name, doc["variants"][name]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("work", type=Path)
    ap.add_argument("seed", type=int, nargs="?", default=0)
    ap.add_argument("reference_run", nargs="?", default=None)
    ap.add_argument("--only-fixed-rows", action="store_true", help="the rows that do not wait for the sweep's choice")
    ap.add_argument("--target", default=TARGET, help="the target method; other than splatfacto: alone, + birds-eye, "
                    "+ birds-eye lane-shift only (the family rows are Splatfacto's)")
    ap.add_argument("--scale", choices=("quick", "default"), default="quick",
                    help="default: every method's registered steps; only alone, + birds-eye, + birds-eye lane-shift")
    args = ap.parse_args()
    work, seed, t, scale = args.work, args.seed, args.target, args.scale
    data = street(work, seed)
    ref_dir, ref_key, ref_result = reference(data, work / "runs", args.reference_run, scale=scale)
    runner = BenchRunner(work / "runs", splits=EVAL_SPLITS)
    ref = (ref_dir, ref_key)

    def row(label: str, augment: Optional[dict]) -> dict:
        return run_augmented(runner, data, ref, label, augment, target=t, scale=scale)

    rows = {"StreetNeRF": ref_result, t: row(t, None), f"{t} + birds-eye": row(f"{t} + birds-eye", {})}
    if t == TARGET and scale == "quick":
        rows[f"{t} + birds-eye lane-shift (one share)"] = row(f"{t} + birds-eye lane-shift (one share)",
                                                              {"views": ["birds-eye", "lane-shift"]} | SHARED)
    if args.only_fixed_rows:
        return
    chosen, lane = chosen_lane_shift()
    if t == TARGET and scale == "quick":
        rows[f"{t} + lane-shift"] = row(f"{t} + lane-shift", {"views": ["lane-shift"], "lane_shift": lane})
    rows[f"{t} + birds-eye lane-shift"] = row(f"{t} + birds-eye lane-shift", {"views": ["birds-eye", "lane-shift"], "lane_shift": lane})
    pairs = [(f"{t} + birds-eye", t), (f"{t} + lane-shift", t), (f"{t} + birds-eye lane-shift", t), (f"{t} + birds-eye lane-shift", f"{t} + birds-eye"),
             (f"{t} + birds-eye lane-shift (one share)", f"{t} + birds-eye")]
    pairs = [p for p in pairs if p[0] in rows]
    name = results_name(t, seed, scale)
    steps = "quick-bench steps (StreetNeRF 1500, {t} 800)" if scale == "quick" else "the registered steps (StreetNeRF 3000, {t} 3000)"
    note = (f"Street seed {seed} (200x112, generator version 3), {steps.format(t=t)}, one run each, "
            f"reference {ref_dir.name}. lane-shift: {chosen} ({json.dumps(lane)}), the options lane_shift_sweep.py chose on the "
            "validation views (the family's defaults)"
            + ("; (one share): offsets -2 and +2 m, every additional view drawn alike, as before the per-family shares "
               "(bird's-eye 0.25, lane-shift 0.5 of the samples). " if t == TARGET else ". ")
            + "`python benchmarks/validation/view_families.py WORK" + (f" {seed}" if seed else "") + " [REFERENCE_RUN]"
            + ("" if t == TARGET else f" --target {t}") + ("" if scale == "quick" else f" --scale {scale}") + "`.\n\n")
    write_results(RESULTS, name, rows, f"View families (synthetic street, {scale} scale){'' if t == TARGET else ', ' + t}",
                  extra_md=note + "Differences, same bench run:\n\n" + ratios_md(rows, pairs) + "\n")


def results_name(target: str, seed: int, scale: str = "quick") -> str:
    """view_families[_SCALE][_TARGET][_seedN] (no _SCALE for quick): Splatfacto's quick files keep their names."""
    return "view_families" + ("" if scale == "quick" else "_" + scale) + ("" if target == TARGET else "_" + target.replace("-", "_")) + ("" if seed == 0 else f"_seed{seed}")


if __name__ == "__main__":
    main()
