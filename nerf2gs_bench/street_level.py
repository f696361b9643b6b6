"""``ns2gs-bench street-level``: where the target pays at street level for the NeRF's views, and which lever keeps it.

Reads the runs of ``ns2gs-bench real-captures`` (``--from-runs``: its processed captures and their
StreetNeRF references), trains Splatfacto alone and with NeRF views in several variants (``VARIANTS``:
which views teach it, the knobs of ``--augment.*``), and scores every held-out frame per region: sky,
ground and the rest, near and far, all from the reference's render at that frame (its accumulation,
depth and ground plane). The held-out frames are split in two: validation frames (the 1st, 3rd, ...
held-out frame) choose a lever, test frames (2nd, 4th, ...) report it. Holes from above as in the
real-captures bench.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

from nerf2gs_plugin.utils.io import atomic_write_text

STEM = "street_level_lever"
TARGET = "target"
NEAR_CAMERA_HEIGHTS = 4.0
"""A pixel is near when the reference's depth is below this many camera heights (~6.5 m on a car)."""
GROUND_TOL_CAMERA_HEIGHTS = 0.15
"""A rendered surface within this many camera heights of the ground plane is ground."""

VARIANTS: dict[str, dict] = {
    TARGET: {},
    "default": {"augment": {}},
    "composites only": {"augment": {"extra_views": False}},
    "bev only": {"augment": {"composites": False}},
    "extra_prob 0.2": {"augment": {"extra_prob": 0.2}},
    "extra_weight 0.3": {"augment": {"extra_weight": 0.3}},
    "real_only_from 0.6": {"augment": {"real_only_from": 0.6}},
    "real_only_from 0.75": {"augment": {"real_only_from": 0.75}},
    "confidence visibility": {"augment": {"confidence": "visibility"}},
    "confidence unseen": {"augment": {"confidence": "unseen"}},
    "confidence unseen 0.3": {"augment": {"confidence": "unseen", "confidence_seen_weight": 0.3}},
    "confidence unseen 0.5": {"augment": {"confidence": "unseen", "confidence_seen_weight": 0.5}},
    "confidence footprint 1.25": {"augment": {"confidence": "footprint", "confidence_footprint_ratio": 1.25}},
    "confidence footprint 2": {"augment": {"confidence": "footprint", "confidence_footprint_ratio": 2.0}},
    "confidence footprint 4": {"augment": {"confidence": "footprint", "confidence_footprint_ratio": 4.0}},
    "sky_alpha 0.5": {"augment": {}, "model": {"sky_alpha_weight": 0.5}},
    "sky_alpha 0": {"augment": {}, "model": {"sky_alpha_weight": 0.0}},
    "target sky_alpha 0.5": {"model": {"sky_alpha_weight": 0.5}},
    "target sky_alpha 0": {"model": {"sky_alpha_weight": 0.0}},
    "sky_alpha 0 + real_only_from 0.6": {"augment": {"real_only_from": 0.6}, "model": {"sky_alpha_weight": 0.0}},
    "drop_outside_box": {"augment": {"drop_outside_box": True}},
    "drop_outside_box + sky_alpha 0": {"augment": {"drop_outside_box": True}, "model": {"sky_alpha_weight": 0.0}},
    "densify from input views": {"augment": {}, "model": {"densify_from_extra_views": False}},
    "drop_outside_box + background from input views": {"augment": {"drop_outside_box": True},
                                                        "model": {"background_from_extra_views": False}},
    "drop_outside_box + background from input views + sky_alpha 0": {
        "augment": {"drop_outside_box": True}, "model": {"background_from_extra_views": False, "sky_alpha_weight": 0.0}},
    "drop_outside_box + reference sky": {"augment": {"drop_outside_box": True, "reference_sky": True}},
    "drop_outside_box + reference sky, sky_alpha 0.5": {"augment": {"drop_outside_box": True, "reference_sky": True},
                                                         "model": {"sky_alpha_weight": 0.5}},
    "no seed points": {"augment": {"seed_points": 0.0}},
    "seed points only": {"augment": {"composites": False, "extra_prob": 0.0}},
    "bev only, no seed points": {"augment": {"composites": False, "seed_points": 0.0}},
    "default, input samples matched": {"augment": {}, "steps_factor": 1.8},
    "target, 1.8x steps": {"steps_factor": 1.8},
    "view-downscale 2": {"augment": {"view_downscale": 2}},
    "view-downscale 2, input samples matched": {"augment": {"view_downscale": 2}, "steps_factor": 1.8},
    "view-downscale 2, CPU matched": {"augment": {"view_downscale": 2}, "steps_factor": 1.4},
    "view-downscale 2, CPU matched, bev only": {"augment": {"view_downscale": 2, "composites": False}, "steps_factor": 1.4},
    "view-downscale 4": {"augment": {"view_downscale": 4}},
    "extra_decay": {"augment": {"extra_decay": True}},
    "extra_decay floor 0.5": {"augment": {"extra_decay": True, "extra_decay_floor": 0.5}},
    "birds_eye_share 0.25": {"augment": {"birds_eye_share": 0.25}},
    "appearance nearest": {"augment": {"appearance": "nearest"}},
    "appearance nearest + extra_decay": {"augment": {"appearance": "nearest", "extra_decay": True}},
    "extra appearance per-view": {"augment": {}, "model": {"extra_view_appearance": "per-view"}},
    "extra appearance shared": {"augment": {}, "model": {"extra_view_appearance": "shared"}},
    "extra appearance per-view, lr 0.02, reg 0.1": {"augment": {}, "optimizers": {"extra_appearance": {"lr": 0.02}},
                                                    "model": {"extra_view_appearance": "per-view", "extra_view_appearance_reg": 0.1}},
    "extra_decay + drop_outside_box + sky_alpha 0": {"augment": {"extra_decay": True, "drop_outside_box": True},
                                                     "model": {"sky_alpha_weight": 0.0}},
}
"""Label -> the augment overrides of a Splatfacto run (no ``augment`` key: the target alone), over
:data:`FULL_SIZE` (the levers were measured against views at the input views' size and the bench's steps), and
``model``: overrides of its model config (the sky / far levers live there); ``optimizers``: of its
optimizers' configs; ``steps_factor``: the run
trains this many times the bench's steps (1.8: the input views get as many samples as the target
alone's, where the views from above take about half of the samples until the last 10% of the run; 1.4 with
``view_downscale`` 2: Splatfacto's CPU time of the default's, a step on a half-size view costing less)."""


FULL_SIZE = {"view_downscale": 1, "step_factor": 1.0}
"""Under every variant's augment overrides: the views at the input views' size, the run at the bench's steps
(``steps_factor`` sets its length), as before the product's half-size views and longer run."""


def augment_overrides(pairs: Sequence[str]) -> dict:
    """``KEY=VALUE`` pairs (``--augment.*`` fields, Python literals: ``real_only_from=0.6``) -> overrides;
    ValueError names the first bad pair in one line."""
    import ast
    import dataclasses

    from nerf2gs_plugin.engine.augment_config import AugmentConfig

    fields = {f.name for f in dataclasses.fields(AugmentConfig)}
    out = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        if key not in fields or not value:
            raise ValueError(f"lever '{pair}': expected KEY=VALUE with KEY an --augment field ({', '.join(sorted(fields))})")
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            raise ValueError(f"lever '{pair}': VALUE must be a Python literal (0.6, False, 'visibility')") from None
    return out


def variant_overrides(base: dict, variant: dict) -> dict:
    """``base`` run overrides with the variant's ``model`` overrides merged into ``pipeline.model`` and its
    ``optimizers`` overrides into ``optimizers``."""
    from nerf2gs_bench.paper import _merge

    out = _merge(base, {"pipeline": {"model": variant["model"]}}) if variant.get("model") else base
    return _merge(out, {"optimizers": variant["optimizers"]}) if variant.get("optimizers") else out


@dataclass(frozen=True)
class Reference:
    """One capture as the real-captures bench left it."""

    name: str
    data: Path
    run_dir: Path
    key: str
    options: dict


def find_reference(from_runs: Path, name: str) -> Reference:
    """The processed capture and its StreetNeRF run, from a real-captures runs root."""
    from nerf2gs_plugin.errors import DataError

    doc_path = Path(from_runs) / "real_captures" / name / "results" / "real_photos.json"
    if not doc_path.is_file():
        raise DataError(f"no real-captures results for '{name}' (run `ns2gs-bench real-captures --runs {from_runs}` first)", doc_path)
    doc = json.loads(doc_path.read_text())
    ref = (doc["results"].get("StreetNeRF") or {})
    if ref.get("failed") or not ref.get("run_dir"):
        raise DataError(f"capture '{name}' has no StreetNeRF run", doc_path)
    # the runs root may have moved since: the run folders are found under it by their key
    run_dir = Path(from_runs) / "real_captures" / "data" / "streetnerf" / Path(ref["run_dir"]).name
    key = json.loads((run_dir / "bench_run.json").read_text())["key"]
    return Reference(name, Path(from_runs) / "real_captures" / "real_photos" / name / "data", run_dir, key, doc["options"])


def split_roles(names: Sequence[str]) -> dict[str, str]:
    """Held-out frame name -> 'val' (1st, 3rd, ... in name order) or 'test' (2nd, 4th, ...)."""
    return {n: ("val" if i % 2 == 0 else "test") for i, n in enumerate(sorted(names))}


def region_masks(view: dict, up, height: float, camera_height: float) -> dict:
    """Boolean ``[H, W]`` masks of one held-out frame from the reference's render at it."""
    from nerf2gs_plugin.masks import from_renders as fr

    sky = fr.sky_from_render(view["acc"], view["dirs"], up)
    ground = fr.ground_from_render(view["origin"], view["dirs"], view["depth"], view["acc"], up, height,
                                   GROUND_TOL_CAMERA_HEIGHTS * camera_height) & ~sky
    rest = ~sky & ~ground
    dist = view["depth"] * view["dirs"].norm(dim=-1)
    near = (dist < NEAR_CAMERA_HEIGHTS * camera_height) & ~sky
    return {"all": sky | ~sky, "sky": sky, "ground": ground, "rest": rest, "near": near, "far": ~near & ~sky,
            "ground near": ground & near, "ground far": ground & ~near, "rest near": rest & near, "rest far": rest & ~near}


def reference_regions(ref: Reference, log: Callable[[str], None] = print) -> dict[str, dict]:
    """Held-out frame name -> {'image', 'masks'} (regions from the reference's render)."""
    from nerf2gs_plugin.masking.auto_masks import render_views

    renders = render_views(ref.data, ref.run_dir, ["test"], log=log, progress=False)
    up = renders.up.float()
    # the input cameras' own height over the plane: the unit of near/far and of the ground tolerance
    cam_h = float(renders.metres_to_world) * float(ref.options.get("camera_height") or 1.6)
    return {v["name"]: {"image": v["image"], "masks": region_masks(v, up, float(renders.height), cam_h)}
            for v in renders.views["test"]}


def run_downscale(config) -> float:
    """The image downscale a run trained at (its dataparser's; a config from before the dataparser's
    own section: the datamanager's)."""
    dm = config.pipeline.datamanager
    return float(getattr(getattr(dm, "dataparser", None), "downscale", None) or getattr(dm, "downscale", None) or 1.0)


def frame_errors(run_dir: Path, data: Path, frames: dict[str, dict]) -> dict[str, dict[str, list[float]]]:
    """Frame name -> region -> [sum of squared error, pixels] of one run's render."""
    import torch
    import torch.nn.functional as F

    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.runs.load import load_run

    run = load_run(run_dir, data=data)
    run.model.eval()
    downscale = run_downscale(run.config)
    test = parse_dataset(data, "test", downscale=downscale)
    out: dict[str, dict[str, list[float]]] = {}
    with torch.no_grad():
        for i in range(len(test)):
            name = test.image_filenames[i].name
            if name not in frames:
                continue
            rgb = run.model.render_camera(test.cameras[i:i + 1])["rgb"].clamp(0, 1).cpu()
            gt = frames[name]["image"]
            if rgb.shape[:2] != gt.shape[:2]:
                rgb = F.interpolate(rgb.permute(2, 0, 1)[None], size=gt.shape[:2], mode="area")[0].permute(1, 2, 0)
            se = ((rgb - gt) ** 2).mean(-1)
            out[name] = {k: [float(se[m].sum()), int(m.sum())] for k, m in frames[name]["masks"].items()}
    return out


def psnr(sse: float, n: int) -> Optional[float]:
    return None if n == 0 else -10.0 * math.log10(max(sse / n, 1e-12))


def summarise(errors: dict[str, dict[str, list[float]]], roles: dict[str, str], role: str) -> dict[str, dict]:
    """Region -> mean per-frame PSNR, pixel share and summed squared error over the frames of ``role``."""
    names = [n for n in errors if roles.get(n) == role]
    regions = next(iter(errors.values())).keys() if errors else []
    out = {}
    for r in regions:
        vals = [psnr(*errors[n][r]) for n in names]
        vals = [v for v in vals if v is not None]
        px = sum(errors[n][r][1] for n in names)
        out[r] = {"psnr": sum(vals) / len(vals) if vals else None, "sse": sum(errors[n][r][0] for n in names),
                  "pixel_share": px / max(sum(errors[n]["all"][1] for n in names), 1)}
    return out


def summarise_seeds(per_seed: Sequence[dict[str, dict[str, list[float]]]], roles: dict[str, str], role: str) -> dict[str, dict]:
    """:func:`summarise` over several seeds' runs of one variant: PSNR the mean of the seeds', errors summed."""
    runs = [summarise(e, roles, role) for e in per_seed]
    out = {}
    for r in runs[0]:
        vals = [x[r]["psnr"] for x in runs if x[r]["psnr"] is not None]
        out[r] = {"psnr": sum(vals) / len(vals) if vals else None, "sse": sum(x[r]["sse"] for x in runs),
                  "pixel_share": runs[0][r]["pixel_share"],
                  "psnr_per_seed": [x[r]["psnr"] for x in runs]}
    return out


def loss_shares(variant: dict[str, dict], target: dict[str, dict]) -> dict[str, float]:
    """Region -> its share of the variant's extra squared error over the target's (sky + ground + rest = 1)."""
    extra = variant["all"]["sse"] - target["all"]["sse"]
    return {r: (variant[r]["sse"] - target[r]["sse"]) / extra if extra else 0.0 for r in variant if r != "all"}


def run(captures: Sequence[str], from_runs: Path, runs_root: Path, out_dir: Path, variants: Sequence[str],
        steps: int = 700, seeds: Sequence[int] = (42,), above_views: int = 8, street: Optional[Path] = None,
        stem: str = STEM, log: Callable[[str], None] = print) -> dict:
    """Every variant on every capture (and on the synthetic ``street`` when given); writes ``<stem>.{json,md}``; returns the document."""
    from nerf2gs_bench.real_captures import holes_from_above
    from nerf2gs_bench.real_photos import RealPhotosOptions, run_overrides
    from nerf2gs_bench.runner import BenchRunner, failure_reason
    from nerf2gs_bench.runs import RunSpec
    from nerf2gs_plugin.augment.config import AugmentConfig
    from nerf2gs_plugin.errors import ConfigError

    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise ConfigError(f"--variants: unknown variant '{unknown[0]}' (known: {', '.join(VARIANTS)})")
    variants = [TARGET] + [v for v in variants if v != TARGET]
    aug = AugmentConfig()
    runner = BenchRunner(Path(runs_root), log=log)
    records = []
    for name in captures:
        ref = find_reference(from_runs, name)
        frames = reference_regions(ref, log)
        roles = split_roles(list(frames))
        opts = RealPhotosOptions(images=ref.data, downscale=float(ref.options["downscale"]),
                                 holdout_every=int(ref.options["holdout_every"]))
        rec: dict = {"capture": name, "frames": roles, "variants": {}}
        for label in variants:
            v = VARIANTS[label]
            errs, holes, run_dirs = [], [], []
            for seed in seeds:
                v_steps = int(round(steps * v.get("steps_factor", 1.0)))
                overrides = variant_overrides({**run_overrides(opts, "splatfacto", v_steps), "seed": seed}, v)
                spec = RunSpec(label, "splatfacto", overrides, augment_from="StreetNeRF" if "augment" in v else None,
                               augment={"delta_h": aug.delta_h, "theta_pitch": aug.theta_pitch, **FULL_SIZE, **v.get("augment", {})})
                log(f"[street-level] {name}: {label}, seed {seed}")
                out = runner.run(spec, ref.data, reference=(ref.run_dir, ref.key) if "augment" in v else None)
                if failure_reason(out) is not None:
                    log(f"[street-level] {name}: {label} failed: {failure_reason(out)}")
                    break
                errs.append(frame_errors(Path(out.run_dir), ref.data, frames))
                holes.append(holes_from_above(Path(out.run_dir), aug.delta_h, aug.theta_pitch, above_views)[0])
                run_dirs.append(out.run_dir)
            if len(errs) < len(seeds):
                rec["variants"][label] = {"failed": True}
                continue
            rec["variants"][label] = {"augment": v.get("augment"), "run_dirs": run_dirs, "frame_errors": errs,
                                      "val": summarise_seeds(errs, roles, "val"), "test": summarise_seeds(errs, roles, "test"),
                                      "bev_hole_fraction": sum(holes) / len(holes), "bev_hole_fraction_per_seed": holes}
        base = rec["variants"].get(TARGET, {})
        for label, r in rec["variants"].items():
            if label == TARGET or "val" not in r or "val" not in base:
                continue
            for role in ("val", "test"):
                r[f"{role}_delta"] = {k: (r[role][k]["psnr"] - base[role][k]["psnr"]) if r[role][k]["psnr"] is not None
                                      and base[role][k]["psnr"] is not None else None for k in r[role]}
                r[f"{role}_loss_share"] = loss_shares(r[role], base[role])
            r["hole_ratio"] = r["bev_hole_fraction"] / base["bev_hole_fraction"] if base["bev_hole_fraction"] else None
        records.append(rec)
    from nerf2gs_bench.machine import machine_info

    synth = synthetic(street, runs_root, variants, seeds) if street is not None else None
    doc = {"synthetic": synth, "steps": steps, "seeds": list(seeds), "variants": {v: VARIANTS[v] for v in variants}, "captures": records, "machine": machine_info(),
           "near_camera_heights": NEAR_CAMERA_HEIGHTS, "ground_tol_camera_heights": GROUND_TOL_CAMERA_HEIGHTS}
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / f"{stem}.json", json.dumps(doc, indent=1, default=str))
    atomic_write_text(out_dir / f"{stem}.md", results_md(doc))
    return doc


def _f(v: Optional[float], fmt: str = "{:+.2f}") -> str:
    return "n/a" if v is None else fmt.format(v)


REGIONS = ("all", "sky", "ground", "rest", "near", "far")


def results_md(doc: dict) -> str:
    """The Markdown page of the JSON document."""
    from nerf2gs_bench.machine import machine_line

    lines = ["# Street level against the NeRF's views: where the loss sits, which lever keeps it (`ns2gs-bench street-level`)", "",
             f"Machine: {machine_line(doc['machine'])}", "",
             f"Splatfacto {doc['steps']} steps (seeds {', '.join(map(str, doc.get('seeds', [42])))}: PSNR the mean of the seeds') on the real-captures bench's quick captures and StreetNeRF references. "
             "Held-out frames (every 8th) split in validation (1st, 3rd, ...) and test (2nd, 4th, ...). Regions from the "
             f"reference's render at each frame: sky (accumulation < 0.5 above the horizon), ground (within "
             f"{doc['ground_tol_camera_heights']} camera heights of the ground plane), rest; near: closer than "
             f"{doc['near_camera_heights']} camera heights. PSNR deltas against the target alone (dB, mean over frames); "
             "loss share: the region's part of the extra squared error.", ""]
    for rec in doc["captures"]:
        roles = rec["frames"]
        lines += [f"## {rec['capture']}", "",
                  f"Validation frames: {', '.join(n for n, r in roles.items() if r == 'val')}; "
                  f"test frames: {', '.join(n for n, r in roles.items() if r == 'test')}.", ""]
        base = rec["variants"].get(TARGET, {})
        for role in ("val", "test"):
            lines += [f"**{role}**: target alone " + ", ".join(f"{k} {_f(base.get(role, {}).get(k, {}).get('psnr'), '{:.2f}')}" for k in REGIONS), "",
                      "| variant | " + " | ".join(f"d {k}" for k in REGIONS) + " | loss share sky / ground / rest | near / far | holes | holes ratio |",
                      "|---|" + "---|" * (len(REGIONS) + 4)]
            for label, r in rec["variants"].items():
                if label == TARGET or f"{role}_delta" not in r:
                    continue
                d, s = r[f"{role}_delta"], r[f"{role}_loss_share"]
                lines.append(f"| {label} | " + " | ".join(_f(d.get(k)) for k in REGIONS)
                             + f" | {_f(s['sky'], '{:.2f}')} / {_f(s['ground'], '{:.2f}')} / {_f(s['rest'], '{:.2f}')}"
                             + f" | {_f(s['near'], '{:.2f}')} / {_f(s['far'], '{:.2f}')}"
                             + f" | {100 * r['bev_hole_fraction']:.1f}% | {_f(r['hole_ratio'], '{:.2f}')} |")
            lines.append("")
        lines += [f"Target alone: holes from above {100 * base['bev_hole_fraction']:.1f}%." if base.get("bev_hole_fraction") is not None else "", ""]
    lines += synthetic_md(doc)
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- the synthetic street
SYNTHETIC_SPLITS = ("val_street", "val_bev", "street", "bev_1", "bev_2")


SYNTHETIC_STEPS = {"streetnerf": 600, "splatfacto": 700}
"""Short runs (a CPU check of the direction from above, as the real captures' quick scale)."""


def synthetic(data: Path, runs_root: Path, variants: Sequence[str], seeds: Sequence[int] = (42,),
              log: Optional[Callable[[str], None]] = None) -> dict:
    """StreetNeRF and Splatfacto (``SYNTHETIC_STEPS``) on a synthetic street, per variant and seed;
    split -> PSNR (mean over seeds) per variant: the views from above have ground truth here."""
    from nerf2gs_bench.paper import run_plan, step_overrides
    from nerf2gs_bench.runs import RunSpec

    plan = [RunSpec("StreetNeRF", "streetnerf", step_overrides("streetnerf", SYNTHETIC_STEPS["streetnerf"]))]
    for label in [TARGET] + [v for v in variants if v != TARGET]:
        v = VARIANTS[label]
        steps = int(round(SYNTHETIC_STEPS["splatfacto"] * v.get("steps_factor", 1.0)))
        plan += [RunSpec(f"{label}, seed {seed}", "splatfacto",
                         variant_overrides({**step_overrides("splatfacto", steps), "seed": seed}, v),
                         augment_from="StreetNeRF" if "augment" in v else None,
                         augment={**FULL_SIZE, **v["augment"]} if "augment" in v else {}) for seed in seeds]
    results = run_plan(plan, Path(data), Path(runs_root), log=log, name=STEM)
    out: dict[str, dict] = {}
    for label in [TARGET] + [v for v in variants if v != TARGET]:
        rows = [results[f"{label}, seed {seed}"] for seed in seeds]
        if any(r.get("failed") for r in rows):
            out[label] = {"failed": True}
            continue
        out[label] = {s: sum(r["results"][s]["psnr"] for r in rows) / len(rows) for s in SYNTHETIC_SPLITS
                      if all(s in r["results"] for r in rows)}
    base = out.get(TARGET, {})
    for label, r in out.items():
        if label != TARGET and not r.get("failed"):
            r["delta"] = {s: r[s] - base[s] for s in SYNTHETIC_SPLITS if s in r and s in base}
    return out


def synthetic_md(doc: dict) -> list[str]:
    """The synthetic street's table (deltas against the target alone)."""
    rows = doc.get("synthetic") or {}
    if not rows:
        return []
    base = rows.get(TARGET, {})
    splits = [s for s in SYNTHETIC_SPLITS if s in base]  # the splits the street has and the bench evaluated
    lines = ["## Synthetic street (ground truth from above)", "",
             f"StreetNeRF {SYNTHETIC_STEPS['streetnerf']} steps, Splatfacto {SYNTHETIC_STEPS['splatfacto']}, seeds as above. Target alone: "
             + ", ".join(f"{s} {base[s]:.2f}" for s in splits) + ".", "",
             "| variant | " + " | ".join(f"d {s}" for s in splits) + " |", "|---|" + "---|" * len(splits)]
    for label, r in rows.items():
        if label == TARGET or "delta" not in r:
            continue
        lines.append(f"| {label} | " + " | ".join(_f(r["delta"].get(s)) for s in splits) + " |")
    return lines + [""]
