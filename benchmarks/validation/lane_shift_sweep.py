"""The lane-shift family's options (offsets, share, look-ahead), chosen on the validation views.

Why: its defaults must come from views no reported number uses: each variant (+ bird's-eye views,
as the family is used) is scored on val_street, val_bev and val_lane (1.5 and 3 m to the side)
against the bird's-eye views alone, on two streets (the embedded layout, seed 0, and seed 7), at
the quick bench's steps, from one StreetNeRF reference per street. Successive halving, as the
machine is slow: every variant on the first street, then on the second only those that gained
val_lane there while keeping val_bev within 0.2 dB and val_street within 0.1 dB of the bird's-eye
views alone (plus ``SECOND_STREET_ALWAYS``). The choice: the best mean val_lane gain over both
streets among the variants that keep both on both; lane_2 / lane_4 (test) are never looked at.

Usage: python benchmarks/validation/lane_shift_sweep.py WORK [SEED=REFERENCE_RUN ...]
  WORK as view_families.py's (streets WORK/street-seedN, runs WORK/runs); a StreetNeRF bench run per
  seed may be given (else one is trained at the quick bench's steps).
Writes benchmarks/results/lane_shift_sweep.{json,md}.
"""
import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from view_families import TARGET, reference, run_augmented, street  # noqa: E402
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_bench.runner import VAL_SPLITS, BenchRunner  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

SEEDS = (0, 7)
VARIANTS: dict[str, dict] = {  # name -> --augment.lane-shift.* (always with the bird's-eye views)
    "offsets 2, share 0.15": {"offsets": [-2.0, 2.0], "share": 0.15},
    "offsets 2, share 0.3": {"offsets": [-2.0, 2.0], "share": 0.3},
    "offsets 3, share 0.15": {"offsets": [-3.0, 3.0], "share": 0.15},
    "offsets 3, share 0.3": {"offsets": [-3.0, 3.0], "share": 0.3},
    "offsets 3, share 0.3, every 2nd": {"offsets": [-3.0, 3.0], "share": 0.3, "every_n": 2},
    "offsets 3, share 0.3, every 2nd, look-ahead 20 m": {"offsets": [-3.0, 3.0], "share": 0.3, "every_n": 2, "look_ahead": 20.0},
}
BEV_TOL, STREET_TOL = 0.2, 0.1
SECOND_STREET_ALWAYS = ("offsets 2, share 0.15", "offsets 2, share 0.3")
"""Tried on the second street whatever the first said (the family's old offsets at both shares)."""


def promising(seed_rows: dict[str, dict]) -> list[str]:
    """The variants worth the second street: a val_lane gain, val_bev and val_street kept (see the module doc)."""
    base = seed_rows["birds-eye"]
    out = []
    for name in VARIANTS:
        r = seed_rows.get(name, {})
        if "failed" in r or not r:
            continue
        d = {s: r[s] - base[s] for s in VAL_SPLITS}
        if name in SECOND_STREET_ALWAYS or (d["val_lane"] > 0 and d["val_bev"] >= -BEV_TOL and d["val_street"] >= -STREET_TOL):
            out.append(name)
    return out


def psnr(res: dict, split: str) -> float:
    return res["results"][split]["psnr"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("work", type=Path)
    ap.add_argument("references", nargs="*", metavar="SEED=REFERENCE_RUN")
    args = ap.parse_args()
    work = args.work
    given = dict(a.split("=", 1) for a in args.references)
    rows: dict[str, dict[str, dict]] = {}
    for seed in SEEDS:
        data = street(work, seed)
        ref_dir, ref_key, _ = reference(data, work / "runs", given.get(str(seed)), evaluate=False)
        runner = BenchRunner(work / "runs", splits=VAL_SPLITS)
        base = run_augmented(runner, data, (ref_dir, ref_key), f"{TARGET} + birds-eye", {})
        seed_rows = {"birds-eye": base}
        names = list(VARIANTS) if not rows else promising(rows[str(SEEDS[0])])
        for name in names:
            seed_rows[name] = run_augmented(runner, data, (ref_dir, ref_key), f"{TARGET} + birds-eye lane-shift ({name})",
                                            {"views": ["birds-eye", "lane-shift"], "lane_shift": VARIANTS[name]})
        rows[str(seed)] = {k: {s: psnr(v, s) for s in VAL_SPLITS} if not v.get("failed") else {"failed": v["error"]}
                           for k, v in seed_rows.items()}
    deltas = {name: {seed: {s: rows[seed][name][s] - rows[seed]["birds-eye"][s] for s in VAL_SPLITS}
                     for seed in rows if name in rows[seed] and "failed" not in rows[seed][name]} for name in VARIANTS}
    deltas = {n: d for n, d in deltas.items() if d}
    both = [n for n, d in deltas.items() if len(d) == len(SEEDS)]  # only a variant tried on both streets is chosen
    keeps = {n: all(d[s]["val_bev"] >= -BEV_TOL and d[s]["val_street"] >= -STREET_TOL for s in d) for n, d in deltas.items()}
    gain = {n: sum(d[s]["val_lane"] for s in d) / len(d) for n, d in deltas.items()}
    chosen = max((n for n in both if keeps[n]), key=gain.get, default=None)
    doc = {"machine": machine_line(), "splits": list(VAL_SPLITS), "variants": VARIANTS, "second_street_always": list(SECOND_STREET_ALWAYS),
           "psnr": rows, "delta_vs_birds_eye": deltas, "tried_on_both": both,
           "keeps_bev_and_street": keeps, "mean_val_lane_gain": gain, "chosen": chosen}
    out = Path(__file__).resolve().parents[1] / "results" / "lane_shift_sweep"
    atomic_write_text(out.with_suffix(".json"), json.dumps(doc, indent=1))
    lines = ["# lane-shift options on the validation views (`benchmarks/validation/lane_shift_sweep.py`)", "",
             f"Machine: {doc['machine']}", "",
             f"Splatfacto at the quick bench's steps (800) + bird's-eye views + lane-shift views of each variant, one StreetNeRF "
             f"reference per street (quick, 1500 steps); PSNR on the validation views, d: against the bird's-eye views alone. "
             f"Kept: val_bev within {BEV_TOL} dB and val_street within {STREET_TOL} dB on both streets. Second street (seed {SEEDS[1]}): "
             f"only the variants that gained val_lane on the first and kept the rest, and {', '.join(SECOND_STREET_ALWAYS)} "
             "(-: not tried there).", "",
             "| variant | " + " | ".join(f"seed {s} {v}" for s in rows for v in ("val_street", "val_bev", "val_lane"))
             + " | mean d val_lane | kept |", "|---" * (2 + 3 * len(rows)) + "|"]
    for name in ["birds-eye", *VARIANTS]:
        cells = []
        for seed in rows:
            r = rows[seed].get(name, {})
            for v in VAL_SPLITS:
                if not r:
                    cells.append("-")
                elif "failed" in r:
                    cells.append("failed")
                elif name == "birds-eye":
                    cells.append(f"{r[v]:.2f}")
                else:
                    cells.append(f"{r[v]:.2f} ({deltas[name][seed][v]:+.2f})")
        tail = ("" if name == "birds-eye" or name not in gain else
                f"{gain[name]:+.2f} | {'yes' if keeps[name] and name in both else 'no' if name in both else 'first street only'}")
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {tail or '- | -'} |")
    lines += ["", f"Chosen: **{chosen or 'none'}**" + ("" if chosen else " (no variant keeps the bird's-eye and street views)") + ".", ""]
    atomic_write_text(out.with_suffix(".md"), "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
