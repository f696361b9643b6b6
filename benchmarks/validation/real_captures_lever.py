"""One ``--augment.*`` lever on a capture of the real-captures bench, over seeds: street level and holes from above.

Reads the bench's run of CAPTURE (``ns2gs-bench real-captures``: its processed capture, masks and StreetNeRF are
reused, never retrained), trains Splatfacto alone and with NeRF views with each seed and the lever (``KEY=VALUE``
pairs of ``--augment.*`` fields, Python literals: ``real_only_from=0.6``, ``composites=False``), and writes
OUT_STEM.{json,md}: per seed the held-out PSNR with NeRF views minus without (over the static pixels where the
held-out frames are labelled by hand, else all pixels) and the holes from above of both runs (accumulation < 0.5
on 8 of the augmentation's bird's-eye cameras, as ``ns2gs-bench street-level`` measures them), and their means. The held-out frames are the reported ones: a diagnosis,
not a choice of default.

Usage: python benchmarks/validation/real_captures_lever.py CAPTURE OUT_STEM [--seeds 42 43 44] [--runs benchmarks/runs]
[KEY=VALUE ...]
"""
import argparse
import json
from pathlib import Path

from nerf2gs_bench.real_captures import (AUGMENTED, CAPTURES, SCALES, STEM, TARGET, holes_from_above, other_seeds,
                                         pool_seeds)
from nerf2gs_bench.real_photos import RealPhotosOptions
from nerf2gs_bench.street_level import augment_overrides
from nerf2gs_plugin.engine.augment_config import AugmentConfig
from nerf2gs_plugin.utils.io import atomic_write_text


def _with_ext(stem: Path, ext: str) -> Path:
    """STEM.ext; a stem that names a value (``..._real_only_from_0.6``) keeps its dot, where ``with_suffix`` would cut it."""
    return stem.parent / f"{stem.name}{ext}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", choices=[c.name for c in CAPTURES])
    ap.add_argument("out", type=Path)
    ap.add_argument("lever", nargs="*", help="KEY=VALUE of --augment.* (none: the defaults)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[42, 43, 44])
    ap.add_argument("--runs", type=Path, default=Path("benchmarks/runs"))
    args = ap.parse_args()
    try:
        lever = augment_overrides(args.lever)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    cap = next(c for c in CAPTURES if c.name == args.capture)
    bench = args.runs / STEM / cap.name / "results" / "real_photos.json"
    if not bench.is_file():
        raise SystemExit(f"{bench}: no real-captures run of {cap.name} (run ns2gs-bench real-captures --captures {cap.name} first)")
    doc = json.loads(bench.read_text())
    opts = RealPhotosOptions(**{k: Path(v) if k == "images" else v for k, v in doc["options"].items()})
    records = other_seeds(cap, opts, Path(doc["data"]), args.runs, args.seeds, print, augment=lever)
    aug = AugmentConfig()
    for r in records:
        r["bev_hole_fraction"] = {label: holes_from_above(Path(d), aug.delta_h, aug.theta_pitch, SCALES["quick"].above_views)[0]
                                  for label, d in r["run_dirs"].items()}
    pooled = pool_seeds(records)
    static = pooled["static_psnr_delta"] is not None
    delta = pooled["static_psnr_delta" if static else "psnr_delta"]
    per = pooled["static_psnr_delta_per_seed" if static else "psnr_delta_per_seed"]
    key = "static_psnr" if static else "psnr"
    halves = pooled[f"{key}_delta_halves_per_seed"]
    ratios = [r["bev_hole_fraction"].get(AUGMENTED, float("nan")) / max(r["bev_hole_fraction"].get(TARGET, float("nan")), 1e-9)
              for r in records]
    from nerf2gs_bench.machine import machine_info, machine_line

    out = {"machine": machine_info(), "capture": cap.name, "lever": lever, **pooled, "hole_ratio_per_seed": ratios}
    atomic_write_text(_with_ext(args.out, ".json"), json.dumps(out, indent=1, default=str))
    name = " ".join(f"--augment.{k.replace('_', '-')} {v}" for k, v in lever.items()) or "the defaults"
    lines = [f"# {cap.name}: {name}, seeds {', '.join(map(str, args.seeds))}", "", f"Machine: {machine_line(out['machine'])}", "",
             f"Held-out PSNR with NeRF views minus without ({'hand-labelled static pixels' if static else 'all pixels'}), "
             "and holes from above (accumulation < 0.5 on the bird's-eye cameras) of each run, per seed. The bench's "
             "capture, masks and StreetNeRF; the reported held-out frames (a diagnosis).", "",
             "Validation / test: the delta over the 1st, 3rd, ... held-out frame (choose on these) and over the 2nd, 4th, ...", "",
             "| seed | delta dB | validation | test | holes alone | holes + NeRF views | ratio |", "|---|---|---|---|---|---|---|"]

    def f(x):
        return "n/a" if x is None else f"{x:+.2f}"

    for r, d, half, q in zip(records, per, halves, ratios):
        h = r["bev_hole_fraction"]
        lines.append(f"| {r['seed']} | {f(d)} | {f(half and half[0])} | {f(half and half[1])} | {100 * h.get(TARGET, float('nan')):.1f}% | "
                     f"{100 * h.get(AUGMENTED, float('nan')):.1f}% | {q:.3f}x |")
    lines.append(f"| **mean** | **{f(delta)}** | {f(pooled[f'{key}_delta_validation'])} | {f(pooled[f'{key}_delta_test'])} | | | "
                 f"{sum(ratios) / len(ratios):.3f}x |")
    atomic_write_text(_with_ext(args.out, ".md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
