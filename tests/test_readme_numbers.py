"""Every number in the README's results tables, and the prose figures tied to them, equals the
committed bench JSON it cites (rounded as printed). A rerun bench that moves a figure fails here
until the README says what the results say."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
RESULTS = ROOT / "benchmarks" / "results"

# README column header -> (split, metric) in a result, or a top-level key
COLUMNS = {
    "PSNR street": ("street", "psnr"), "bev_1": ("bev_1", "psnr"), "bev_2": ("bev_2", "psnr"),
    "LPIPS bev_1": ("bev_1", "lpips"), "road PSNR bev_1": ("bev_1", "psnr_ground"), "road bev_1": ("bev_1", "psnr_ground"),
    "road bev_2": ("bev_2", "psnr_ground"), "FPS": (None, "fps"), "primitives": (None, "primitives"), "train s": (None, "train_seconds"),
    # a real photo set's held-out photos (ns2gs-bench real-photos: the "test" split)
    "held-out photos": ("test", "num_images"), "PSNR held-out": ("test", "psnr"), "SSIM held-out": ("test", "ssim"),
    "LPIPS held-out": ("test", "lpips"),
}


def _row_key(label: str) -> str:
    """README row label -> the bench's result label ("Splatfacto (800 steps)" -> "splatfacto")."""
    label = re.sub(r"\s*\(.*?\)", "", label).strip()
    head, _, rest = label.partition(" + ")
    head = "StreetNeRF" if head.lower() == "streetnerf" else head.lower()
    return f"{head} + {rest}" if rest else head


def _tables() -> list[tuple[Path, list[str], list[list[str]]]]:
    """(results JSON the table cites, header, rows) for every README table whose first column is 'method'."""
    lines = README.splitlines()
    out = []
    for i, line in enumerate(lines):
        if not line.startswith("| method |"):
            continue
        before = "\n".join(lines[max(0, i - 12):i])
        cited = re.findall(r"benchmarks/results/[\w/]+\.md", before)
        assert cited, f"README table at line {i + 1} cites no results file"
        header = [c.strip() for c in line.strip("|").split("|")]
        rows = []
        for row in lines[i + 2:]:
            if not row.startswith("|"):
                break
            rows.append([c.strip() for c in row.strip("|").split("|")])
        out.append((ROOT / cited[-1].replace(".md", ".json"), header, rows))
    return out


def _value(result: dict, column: str):
    split, metric = COLUMNS[column]
    if split is not None:
        return result["results"][split][metric]
    return result["size"]["primitives"] if metric == "primitives" else result[metric]


def _matches(cell: str, value: float) -> bool:
    """``cell`` is ``value`` as printed: same rounding to the cell's decimals (commas, bold ignored)."""
    text = cell.replace("**", "").replace("_", "").replace(",", "")
    digits = len(text.split(".")[1]) if "." in text else 0
    return abs(float(text) - value) <= 0.5 * 10 ** -digits + 1e-9


def test_every_table_cell_matches_its_json():
    tables = _tables()
    assert len(tables) >= 2
    checked = 0
    for path, header, rows in tables:
        results = json.loads(path.read_text())["results"]
        for row in rows:
            result = results[_row_key(row[0])]
            for column, cell in zip(header[1:], row[1:]):
                if cell.startswith("("):  # "(hash grid)": no count to check
                    continue
                assert column in COLUMNS, f"README column '{column}' has no mapping to {path.name}"
                value = _value(result, column)
                assert _matches(cell, value), f"{path.relative_to(ROOT)} {row[0]} / {column}: README {cell}, JSON {value}"
                checked += 1
    assert checked >= 140  # 7 x 9 quick cells (less the hash-grid one) + 10 x 8 default cells


A = "ablation.json"


def _abl(switch: str, split: str, metric: str = "psnr") -> float:
    """StreetNeRF without ``switch`` minus the full StreetNeRF, in the ablation run."""
    return _psnr(_r(A), f"StreetNeRF w/o {switch}", split, metric) - _psnr(_r(A), "StreetNeRF", split, metric)


VB = "views_budget/"


def _size_pick(method: str, name: str = "model_size_fixed_cap.json") -> dict:
    """A method's picks in a model-size sweep (default: the embedded street's, quick, fixed caps)."""
    return _r(name, "picks")[method]


def _size_row(label: str, name: str = "model_size_fixed_cap.json") -> dict:
    return next(r for r in _r(name, "rows") if r["label"] == label)


def _castle_budget(seed_index: int, budget: str) -> dict:
    """A row of views_budget/castle_val.json: seed 0 or 2 (index 0 / 1), the fixed or the views budget."""
    scene = "castle-P30, validation photos" + ("" if seed_index == 0 else ", seed 2")
    variant = "splatfacto, fixed 60k budget" if budget == "fixed" else "splatfacto, views budget"
    return next(r for r in _r(VB + "castle_val.json", "rows") if r["scene"] == scene and r["variant"] == variant)


def _r(name: str, key: str = "results") -> dict:
    return json.loads((RESULTS / name).read_text())[key]


def _psnr(res: dict, label: str, split: str, metric: str = "psnr") -> float:
    return res[label]["results"][split][metric]


def _gain(res: dict, target: str, split: str, metric: str = "psnr", variant: str = " + NeRF views", base: str = "") -> float:
    return _psnr(res, target + variant, split, metric) - _psnr(res, target + base, split, metric)


def _stability(stem: str = "stability") -> dict:
    return json.loads((RESULTS / f"{stem}.json").read_text())


T_STAB = ("splatfacto", "2dgs", "scaffold-gs")
CONF_VIS, CONF_CONS = " + NeRF views (visibility confidence)", " + NeRF views (consistency confidence)"


def _conf(scene: str) -> dict:
    return _r(f"confidence/{scene}/paper_table.json")


def _stab_sn(variant: str, view: str) -> float:
    """benchmarks/results/stability_streetnerf: how far below its seed mean a StreetNeRF run ended."""
    return _stab_view("streetnerf", variant, "stability_streetnerf/stability", view)


def _table_row(stem: str, variant: str, scene: str = "", steps: int | None = None, exact: bool = False) -> dict:
    """The first row of a ``benchmarks/validation/run_table.py`` result (benchmarks/results/<stem>.json)
    whose scene starts with ``scene`` and whose variant is ``variant`` (``exact``) or starts with it."""
    rows = json.loads((RESULTS / f"{stem}.json").read_text())["rows"]
    return next(r for r in rows if r["scene"].startswith(scene) and (r["variant"] == variant if exact else r["variant"].startswith(variant))
                and (steps is None or r["steps"] == steps))


def _app_reg(scene: str, variant: str, steps: int | None = None) -> float:
    """benchmarks/results/appearance_reg.json: a row's mean PSNR over its splits."""
    return _table_row("appearance_reg", variant, scene, steps)["mean"]


def _clear(scene: str, variant: str, view: int | None = None) -> float:
    """benchmarks/results/path_clearance.json: a row's mean PSNR, or one held-out photo's."""
    row = _table_row("path_clearance", variant, scene, exact=True)
    return row["mean"] if view is None else row["psnr_per_view"]["test"][view]


def _scaffold_size(what: str) -> float:
    """benchmarks/results/model_size_scaffold/model_size.json (Scaffold-GS's sweep, embedded street, quick)."""
    pick = json.loads((RESULTS / "model_size_scaffold" / "model_size.json").read_text())["picks"]["scaffold-gs"]
    return {"default": pick["default"]["primitives"], "ratio": pick["default_over_smallest"],
            "smallest": pick["smallest_within_0_5dB"]["primitives"],
            "below": pick["best_quality"] - pick["smallest_within_0_5dB"]["mean_psnr"]}[what]


def _stab_view(method: str, variant: str, stem: str, view: str) -> float:
    """How far below its unstressed seed mean a stressed run ended on one view kind (negative: above)."""
    d = _stability(stem)
    s, r = d["summary"][method], next(r for r in d["rows"] if r["method"] == method and r["variant"] == variant)
    return s[f"seed_{view}_mean"] - r[f"{view}_psnr"]


def _aw(i: int) -> dict:
    """Row i of benchmarks/results/augment_weight_val.json (castle-P30's validation photos, then both streets' val views)."""
    return _r("augment_weight_val.json", "rows")[i]


def _rl(i: int) -> dict:
    """Row i of reference_length_val.json (castle-P30's validation photos, StreetNeRF trained for longer)."""
    return _r("reference_length_val.json", "rows")[i]


NV_DEFAULT = "prune_margin/street_nerf_views_default/"
SC_GROWTH = "scaffold_growth_only"  # Scaffold-GS's sweep before its views term
SECOND_T, SECOND_GROWTH = "second_scene/paper_table.json", "second_scene/paper_table_scaffold_growth_only.json"


def _nv_pick(method_dir: str) -> dict:
    """The picks of a default-scale sweep with NeRF views (prune_margin/street_nerf_views_default/<dir>)."""
    return next(iter(_r(NV_DEFAULT + f"{method_dir}/model_size.json", "picks").values()))


def _nv_default(method_dir: str, label: str) -> dict:
    return _size_row(label, NV_DEFAULT + f"{method_dir}/model_size.json")


AUG_TARGET = "splatfacto + NeRF views"
AUG_SC = "scaffold-gs + NeRF views"


def _stab_drop(method: str, variant: str, stem: str = "stability") -> float:
    """How far below its unstressed seed mean a stressed run ended (the worse of street and BEV)."""
    return max(_stab_view(method, variant, stem, view) for view in ("street", "bev"))


Q, D, GPU = "paper_table.json", "default/paper_table.json", "gpu/quick.json"
T = ("splatfacto", "scaffold-gs", "2dgs")
BEV = ("bev_1", "bev_2")
ENH, AUG = " + NeRF views + enhancer", " + NeRF views"


def _below_nerf(res: dict, targets=("splatfacto", "2dgs")) -> list[float]:
    return [_psnr(res, "StreetNeRF", s) - _psnr(res, t + AUG, s) for t in targets for s in BEV]


RP = "real_photos.json"
RP3 = "real_photos_run3.json"  # the run before the appearance change (the castle paragraphs of that run)
RP4 = "real_photos_run4.json"  # the run before the path clearance
RP5 = "real_photos_run5.json"  # the path clearance on the AMD host
RP6 = "real_photos_run6.json"  # the Intel host, before Splatfacto's depth loss
RP7 = "real_photos_run7.json"  # the depth loss, with the fixed caps


def _per_photo(label: str, stem: str = RP) -> list[float]:
    return _psnr(_r(stem), label, "test", "psnr_per_image")


def _floater_run(variant: str) -> float:
    return _table_row("castle_floaters", variant)["mean"]


def _rp_check(stem: str = RP) -> dict:
    return json.loads((RESULTS / stem).read_text())["reference_check"]


def _ground(capture: str, what: str) -> float:
    """A figure of benchmarks/results/ground_fit.json (the ground-plane fit against true cameras)."""
    return json.loads((RESULTS / "ground_fit.json").read_text())["captures"][capture]["plane"][what]


def _ground_up(capture: str) -> float:
    """The angle of the up ``process`` writes to the true up (benchmarks/results/ground_fit.json)."""
    return json.loads((RESULTS / "ground_fit.json").read_text())["captures"][capture]["up_to_true_up_deg"]


def _floaters() -> dict:
    """benchmarks/results/near_camera_floaters.json (the castle-P30 view the augmented Splatfacto lost)."""
    return json.loads((RESULTS / "near_camera_floaters.json").read_text())


def _c3000(what: str) -> float:
    """benchmarks/results/eval_appearance_castle3000.json: the 3000-step castle StreetNeRF."""
    d = json.loads((RESULTS / "eval_appearance_castle3000.json").read_text())
    run = next(iter(d["runs"].values()))
    if what in ("mean", "nearest"):
        return run["modes"][what]["psnr"]
    return d["bench_eval"][what]


RUN6 = ("real_run6", "real_run6_seed43")  # the real bench before the path clearance and the 1.0 appearance pull


RUN7 = ("real_run7", "real_run7_seed43")  # the real bench on the AMD host, before the empty-ray ground rule
GE_OFF = ("real_ground_empty_off", "real_ground_empty_off_seed43")  # the Intel host, the rule off
RUN8 = ("real_run8", "real_run8_seed43")  # the Intel host, the rule on, before Splatfacto's depth loss
SEEDS3 = ("real_depth_loss", "real_depth_loss_seed43", "real_depth_loss_seed44")  # the Intel host with the depth loss, three training seeds


def _two_seed_gain(side: str, split: str, stems: tuple[str, str] = ("real_depth_loss", "real_depth_loss_seed43")) -> float:
    """The bird's-eye gain of NeRF views in ns2gs-bench real, mean over the committed seeds ``stems``."""
    g = [_real_psnr(stem, "splatfacto + NeRF views", split, side) - _real_psnr(stem, "splatfacto", split, side)
         for stem in stems]
    return sum(g) / len(g)


APP_MEAN, APP_NEAR = "splatfacto + NeRF views, appearance mean (default)", "splatfacto + NeRF views, appearance nearest"
CASTLE_VAL, CASTLE_TEST = "castle-P30, validation photos", "castle-P30, held-out (test) photos"


def _aug_app(scene: str, variant: str) -> float:
    """The mean PSNR of a row of benchmarks/results/augment_appearance.json."""
    return _table_row("augment_appearance", variant, scene, exact=True)["mean"]


def _ncf_val() -> dict:
    return json.loads((RESULTS / "near_camera_floaters_castle_val.json").read_text())


def _sfm120(variant: str, what: str) -> float:
    """A figure of benchmarks/results/sfm_speed_120.json (benchmarks/sfm_speed.py on the 120-photo stand-in)."""
    r = json.loads((RESULTS / "sfm_speed_120.json").read_text())["variants"][variant]
    s = r["stage_seconds"]
    if what == "sfm":
        return s["features"] + s["matching"] + s["mapping"]
    if what in ("registered", "frames", "matched_pairs", "wall_seconds"):
        return r[what]
    return s[what] if what in s else r["pose"][what]


def _growth(label: str = "default", final: bool = False):
    """benchmarks/results/growth_signals/<label>.json: its refinements up to the end of densification, or its final figures."""
    doc = json.loads((RESULTS / "growth_signals" / f"{label}.json").read_text())
    return doc["final"] if final else [r for r in doc["refinements"] if r["step"] < 400 and r["gaussians"] >= doc["refinements"][0]["gaussians"]]


def _growth_last_growing() -> dict:
    """The last refinement of the default run that added Gaussians before the weight prune (the peak)."""
    return max((r for r in _growth() if r["cloned"] + r["split"] > 0 and r["step"] < 300), key=lambda r: r["step"])


def _growth_ranges() -> list:
    """Train-subset PSNR gain per refinement while growing (13-21% more) and while nothing is added, steps 81-351."""
    rs = [r for r in _growth() if r["step"] <= 351]
    grow, still = [], []
    for a, b in zip(rs, rs[1:]):
        (grow if b["gaussians"] > a["gaussians"] else still).append((b["train_subset_psnr"] - a["train_subset_psnr"],
                                                                    100 * (b["gaussians"] / a["gaussians"] - 1)))
    return [min(g for g, _ in grow), max(g for g, _ in grow), min(x for _, x in grow), max(x for _, x in grow),
            min(g for g, _ in still), max(g for g, _ in still)]


def _prior_intel() -> dict:
    return json.loads((RESULTS / "enhancer_prior" / "prior_intel.report.json").read_text())


def _prior_intel_selected() -> dict:
    """The validation record of the state the prior kept (its selected step)."""
    return next(v for v in _prior_intel()["validation"] if v["step"] == _prior_intel()["selected_step"])


CONF_NONE, CONF_C = "splatfacto + NeRF views, confidence none (default)", "splatfacto + NeRF views, consistency confidence"


def _conf_depth(scene: str, variant: str) -> dict:
    """A row of benchmarks/results/confidence_depth_val.json (validation views, with Splatfacto's depth loss)."""
    rows = json.loads((RESULTS / "confidence_depth_val.json").read_text())["rows"]
    return next(r for r in rows if r["scene"] == scene and r["variant"] == variant)


def _scale_check(label: str) -> dict:
    """A row of benchmarks/results/scale_check.json (process's capture check on finished captures)."""
    return next(r for r in json.loads((RESULTS / "scale_check.json").read_text())["rows"] if r["label"].startswith(label))


DAB, DAB_EXH, FWD_EARLY = "street drive down and back", "the same, exhaustive matching", "street forward pass, 120 frames (stand-in, an earlier"
DAB_KEPT = "street drive down and back as process keeps it"
GOOD_CAPTURES = ("street forward pass, 120 frames (sfm_speed_120's sequential", "street forward pass, 120 frames (sfm_speed_120's exhaustive",
                 "castle-P30", "ns2gs-bench real's drive")
NO_DEPTH, DEPTH_01 = "splatfacto, no depth loss", "splatfacto, depth loss 0.1 (default)"
STREET_E, STREET_7 = "street (embedded)", "street-seed7"


def _depth_two_seeds(scene: str, variant: str) -> float:
    """Mean over the default seed and seed 2 of a benchmarks/results/depth_loss.json row pair."""
    rows = json.loads((RESULTS / "depth_loss.json").read_text())["rows"]
    got = [r["mean"] for r in rows if r["variant"] == variant and r["scene"] in (scene, scene + ", seed 2")]
    assert len(got) == 2, (scene, variant, got)
    return sum(got) / 2


def _video4_mask_rises(kind: str) -> list[float]:
    """IoU of ``kind`` with the video at 800x448 minus at 200x112: the bench street and seeds 7 and 3."""
    return [_real("real")["mask_iou"][kind] - _real("real_scene_budget")["mask_iou"][kind]] + [
        _auto_masks(f"{n}_video4")["mask_iou"][kind] - _auto_masks(n)["mask_iou"][kind] for n in (7, 3)]


def _auto_masks(seed: int | str) -> dict:
    """benchmarks/results/auto_masks_seed<seed>.json (benchmarks/validation/auto_masks_scene.py)."""
    return json.loads((RESULTS / f"auto_masks_seed{seed}.json").read_text())


def _real(stem: str) -> dict:
    """benchmarks/results/<stem>.json of ``ns2gs-bench real``."""
    return json.loads((RESULTS / f"{stem}.json").read_text())


def _real_psnr(stem: str, label: str, split: str = "street", side: str = "estimated") -> float:
    return _real(stem)["results"][side][label]["results"][split]["psnr"]


def _appearance(run: str, mode: str, what: str = "psnr") -> float:
    """A figure of benchmarks/results/eval_appearance.json (StreetNeRF's eval-appearance modes)."""
    return json.loads((RESULTS / "eval_appearance.json").read_text())["runs"][run]["modes"][mode][what]


CASTLE_SN, STREET_SN = "castle-P30 (real-photos bench StreetNeRF)", "synthetic street (quick paper-table StreetNeRF)"


def _sfm(variant: str, what: str) -> float:
    """A figure of benchmarks/results/real_photos_sfm.json: pairs matched, matching s per pair, SfM s."""
    r = json.loads((RESULTS / "real_photos_sfm.json").read_text())["variants"][variant]
    s = r["stage_seconds"]
    return {"pairs": r["matched_pairs"], "per_pair": s["matching"] / r["matched_pairs"],
            "sfm": s["features"] + s["matching"] + s["mapping"]}[what]


def _min_max(vals) -> list[float]:
    vals = list(vals)
    return [min(vals), max(vals)]


def _scale() -> dict:
    return json.loads((RESULTS / "scale.json").read_text())


def _scale_rows(method: str, sweep: str, key: str) -> list[float]:
    rows = [r for r in _scale()["rows"] if r["method"] == method and r["sweep"] == sweep]
    return [r[key] for r in sorted(rows, key=lambda r: (r["images"], r["pixels"]))]


def _law(method: str, what: str) -> dict:
    return _scale()["laws"][method][what]


def _proj(method: str, plan: str, key: str) -> float:
    return _scale()["projection"][method][plan][key]


def _blocks_gaps(scene: int) -> list[float]:
    gaps = list(json.loads((RESULTS / "blocks.json").read_text())["gaps"].values())[scene]
    return [gaps[s] for s in ("street", "bev_1", "bev_2")]


# (text in the README, the numbers it prints, the values they stand for, signed as printed)
def _dist(i: int, key: str) -> float:
    return json.loads((RESULTS / "dist_speedup.json").read_text())["rows"][i][key]


def _size(scene: str, method: str, label: str, what: str = "primitives") -> float:
    """A figure of benchmarks/results/size_prune.json (the blend-weight prune on the validation views)."""
    d = json.loads((RESULTS / "size_prune.json").read_text())["scenes"][scene][method]
    if what in ("over_smallest", "below_best_db"):
        return d["prune"][label][what]
    return d["rows"][label][what]


def _size_default_ratio(scene: str, method: str) -> float:
    return json.loads((RESULTS / "size_prune.json").read_text())["scenes"][scene][method]["default_over_smallest"]


def _size_gap(scene: str, method: str, label: str) -> float:
    d = json.loads((RESULTS / "size_prune.json").read_text())["scenes"][scene][method]
    return d["rows"][d["best"]]["mean_psnr"] - d["rows"][label]["mean_psnr"]


def _av(scene: str, row: str, split: str, what: str = "psnr") -> float:
    """A figure of benchmarks/results/augment_variants.json (saved bench runs trained again with other --augment settings)."""
    return json.loads((RESULTS / "augment_variants.json").read_text())["scenes"][scene]["rows"][row][split][what]


AV_EMB, AV_SEC, AV_CASTLE = "embedded street (default scale)", "second street (default scale)", "castle-P30"
RO9, RO8, CONS = "NeRF views, real_only_from=0.9", "NeRF views, real_only_from=0.8", "NeRF views, confidence=consistency"


def _frag_rows(stem: str) -> list[dict]:
    return json.loads((RESULTS / f"{stem}.json").read_text())["rows"]


def _frag(drive: str, variant: str, what: str, stem: str = "sfm_fragility") -> float:
    """A figure of benchmarks/results/<stem>.json (the real bench's SfM on two renders of its drive)."""
    return next(r[what] for r in _frag_rows(stem) if r["drive"] == drive and r["variant"] == variant)


def _second(label: str, split: str, what: str = "psnr") -> float:
    """A figure of benchmarks/results/second_scene/paper_table.json (default scale, the seed-7 street)."""
    return json.loads((RESULTS / "second_scene" / "paper_table.json").read_text())["results"][label]["results"][split][what]


TARGETS3 = ("splatfacto", "scaffold-gs", "2dgs")


AV_2DGS, AV_SCAF = "2DGS, second street (default scale)", "Scaffold-GS, second street (default scale)"


def _enh_cond(scene: str, enhancer: str, split: str, what: str = "psnr") -> float:
    """A change made by an enhancer alone (after - before), benchmarks/results/enhancer_condition/<scene>.json."""
    r = json.loads((RESULTS / "enhancer_condition" / f"{scene}.json").read_text())["results"][enhancer]["splits"][split]
    return r[f"{what}_after"] - r[f"{what}_before"]


def _enh_targets_gap() -> float:
    d = json.loads((RESULTS / "enhancer_condition" / "targets_warped.json").read_text())["results"]
    return max(abs(r["new"]["val_bev"]["psnr"] - r["enhancer"]["val_bev"]["psnr"]) for r in d.values())


def _stab_aug() -> dict:
    return json.loads((RESULTS / "stability_augmented" / "stability.json").read_text())


def _stab_pose(what: str) -> float:
    """splatfacto+nerf under 4 deg / 40 cm pose noise against its seeds (stability_augmented_pose)."""
    d = json.loads((RESULTS / "stability_augmented_pose" / "stability.json").read_text())
    s = d["summary"]["splatfacto + NeRF views"]
    r = next(r for r in d["rows"] if r["variant"] == "pose noise 4deg/40cm")
    return {"street_drop": s["seed_street_mean"] - r["street_psnr"], "bev_drop": s["seed_bev_mean"] - r["bev_psnr"],
            "street": r["street_psnr"], "bev": r["bev_psnr"], "seed_street": s["seed_street_mean"], "seed_bev": s["seed_bev_mean"]}[what]


def _stab_aug_case(case: str, what: str = "bev_psnr") -> float:
    return next(r[what] for r in _stab_aug()["rows"] if f"{r['stress']} {r['level_label']}" == case)


def _fitgen(what: str, target: str = "") -> list[float]:
    return [r[what] for r in _r("fit_vs_generalise.json", "rows") if r["target"].startswith(target)]


def _prior(scene: str, name: str, split: str, metric: str) -> float:
    v = _r(f"enhancer_prior/{scene}/enhancer_prior.json")[name]["splits"][split]
    return v[f"{metric}_after"] - v[f"{metric}_before"]


def _prior_report() -> dict:
    return json.loads((RESULTS / "enhancer_prior" / "prior.report.json").read_text())


def _spread(scene: str, row: str, split: str) -> float:
    return _r("augment_spread.json", "scenes")[scene]["rows"][row][split]["psnr"]


SPREAD_ROW, SCENES_SPREAD = "NeRF views, delta_h_spread=4, theta_pitch_spread=10", ("street (default scale)", "second street (default scale)")
def _enh_d(table: str, target: str, split: str, metric: str) -> float:
    r = _r(table)
    return _psnr(r, target + " + NeRF views + enhancer", split, metric) - _psnr(r, target + " + NeRF views", split, metric)


ENH_TABLES = (Q, "second_scene/quick/paper_table.json")
def _stab_masks(method: str, variant: str, what: str = "worst") -> float:
    """A stressed run of stability_masks against its method's seeds (street, bev or the worse of the two)."""
    if what == "worst":
        return _stab_drop(method, variant, "stability_masks/stability")
    return _stab_view(method, variant, "stability_masks/stability", what)


def _stab_drops(stem: str) -> dict:
    """Every stressed run of a stability bench: (method, case) -> (street, BEV) dB below its method's seed mean."""
    return {(r["method"], r["variant"]): tuple(_stab_view(r["method"], r["variant"], f"{stem}/stability", v) for v in ("street", "bev"))
            for r in _stability(f"{stem}/stability")["rows"] if r["stress"] is not None}


def _stab_shift(new: str, old: str, skip: tuple) -> float:
    """The largest change of any drop between two runs of one stability bench, ``skip`` = ((method, case), view index) left out."""
    n, o = _stab_drops(new), _stab_drops(old)
    return max(abs(n[k][i] - o[k][i]) for k in n for i in (0, 1) if (k, i) != skip)


def _aug_today_shift() -> float:
    """The largest change of a drop between stability_augmented_today and the five augmented benches before it."""
    old: dict = {}
    for stem in ("stability_augmented", "stability_augmented_masks", "stability_augmented_pose", "stability_augmented_transients",
                 "stability_augmented_views_exposure"):
        old.update({case: v for (_, case), v in _stab_drops(stem).items()})
    new = {case: v for (_, case), v in _stab_drops("stability_augmented_today").items()}
    assert set(new) == set(old)
    return max(abs(new[c][i] - old[c][i]) for c in new for i in (0, 1))


PROSE = [
    ("Scaffold-GS breaks first, at 8x the cars (street\n3.21 dB below its seeds), where Splatfacto and 2DGS end 2.01 / 2.21 dB below",
     "8 3.21 2.01 2.21", lambda: [8, _stab_masks("scaffold-gs", "transients 8x")] + [_stab_masks(m, "transients 8x") for m in ("splatfacto", "2dgs")]),
    ("Splatfacto + NeRF views breaks when StreetNeRF gets 6% of its steps (BEV 3.38 dB below its seeds) and at\n+-2 stops of exposure (street 3.16 dB below)",
     "6 3.38 2 3.16",
     lambda: [6 if _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["reference steps"]["level"] == "6%" else 0,
              _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["reference steps"]["drop_db"],
              2 if _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["exposure"]["level"] == "+-2 stop" else 0,
              _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["exposure"]["drop_db"]]),
    ("and at no level of transients (up to 8x), pose noise (up to 4 deg /\n40 cm), fewer views (down to 12%) or mask errors; every drop is within 0.51 dB",
     "8 4 40 12 0.51",
     lambda: [8 if _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["transients"] == "none up to 8x" else 0,
              4 if _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["pose noise"] == "none up to 4deg/40cm" else 0, 40,
              12 if _r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET]["views kept"] == "none up to 12%"
              and all(str(_r("stability_augmented_today/stability.json", "breaking_point")[AUG_TARGET][s]).startswith("none")
                      for s in ("mask erosion", "mask dilation", "mask drop")) else 0, _aug_today_shift()]),
    ("their unstressed targets 4.1-7.7k Gaussians where today's keep 3.4-3.5k", "4.1 7.7 3.4 3.5",
     lambda: list(_min_max(r["primitives"] / 1000 for stem in ("stability_augmented", "stability_augmented_masks", "stability_augmented_pose",
                                                               "stability_augmented_transients", "stability_augmented_views_exposure")
                           for r in _r(f"{stem}/stability.json", "rows") if r["stress"] is None))
     + list(_min_max(r["primitives"] / 1000 for r in _r("stability_augmented_today/stability.json", "rows") if r["stress"] is None))),
    ("each drop within 0.31 dB of it but for\n2DGS's view from above without masks", "0.31",
     lambda: [_stab_shift("stability_masks", "stability_masks_fixed_cap", (("2dgs", "no masks"), 1))]),
    ("Masks grown by 12 px (real pixels given to the reference) cost street views\n1.59 / 1.82 / 2.07 dB", "12 1.59 1.82 2.07",
     lambda: [12] + [_stab_masks(m, "mask dilation 12px", "street") for m in T_STAB]),
    ("without masks at all the view from above pays 0.35 / -0.04 /\n0.89 dB", "0.35 -0.04 0.89",
     lambda: [_stab_masks(m, "no masks", "bev") for m in T_STAB]),
    ("LPIPS from above moves by -0.020 to +0.009 (bev_1 / bev_2;\nScaffold-GS -0.019 / -0.020 on the second street, Splatfacto -0.001 / +0.009 on the embedded one), PSNR from above by -0.21 to +0.23 dB, street PSNR by -0.04 to +0.11 dB",
     "-0.020 0.009 1 2 -0.019 -0.020 -0.001 0.009 -0.21 0.23 -0.04 0.11",
     lambda: list(_min_max(_enh_d(tb, t, sp, "lpips") for tb in ENH_TABLES for t in T for sp in BEV)) + [1, 2]
     + [_enh_d(ENH_TABLES[1], "scaffold-gs", sp, "lpips") for sp in BEV] + [_enh_d(Q, "splatfacto", sp, "lpips") for sp in BEV]
     + list(_min_max(_enh_d(tb, t, sp, "psnr") for tb in ENH_TABLES for t in T for sp in BEV))
     + list(_min_max(_enh_d(tb, t, "street", "psnr") for tb in ENH_TABLES for t in T))),
    ("(Splatfacto 0.347, Scaffold-GS 0.239, 2DGS 0.306 on bev_1\nagainst StreetNeRF's own 0.152)", "0.347 0.239 0.306 1 0.152",
     lambda: [_psnr(_r(Q), t + AUG, "bev_1", "lpips") for t in T] + [1, _psnr(_r(Q), "StreetNeRF", "bev_1", "lpips")]),
    ("table of 2026-11-25 in 33 min on one thread beside another bench: 24.02 -> 24.17 dB, LPIPS 0.145 -> 0.108", "33 24.02 24.17 0.145 0.108",
     lambda: [_prior_intel()["seconds"] / 60] + [r[k] for r in (_prior_intel()["validation"][0], _prior_intel_selected()) for k in ("psnr",)]
     + [r["lpips"] for r in (_prior_intel()["validation"][0], _prior_intel_selected())]),
    ("21.26 / 0.346 with the prior", "21.26 0.346",
     lambda: [_psnr(_r(Q), "splatfacto + NeRF views + enhancer", "bev_1"), _psnr(_r(Q), "splatfacto + NeRF views + enhancer", "bev_1", "lpips")]),
    ("val_bev +0.05 / +0.08 dB and val_street +0.13 /\n+0.23 dB (embedded / second street), which leaves val_bev 0.05 / 0.59 dB below the reference (23.73 vs\n23.78, 22.98 vs 23.56)",
     "0.05 0.08 0.13 0.23 0.05 0.59 23.73 23.78 22.98 23.56",
     lambda: [_spread(sc, SPREAD_ROW, "val_bev") - _spread(sc, "NeRF views", "val_bev") for sc in SCENES_SPREAD]
     + [_spread(sc, SPREAD_ROW, "val_street") - _spread(sc, "NeRF views", "val_street") for sc in SCENES_SPREAD]
     + [_spread(sc, "reference", "val_bev") - _spread(sc, SPREAD_ROW, "val_bev") for sc in SCENES_SPREAD]
     + [v for sc in SCENES_SPREAD for v in (_spread(sc, SPREAD_ROW, "val_bev"), _spread(sc, "reference", "val_bev"))]),
    ("on the held-out sixth street it moves PSNR 24.12 ->\n24.25 dB and LPIPS 0.146 -> 0.108", "24.12 24.25 0.146 0.108",
     lambda: [(v := _prior_report()["validation"])[0]["psnr"], next(x for x in v if x["step"] == _prior_report()["selected_step"])["psnr"],
              v[0]["lpips"], next(x for x in v if x["step"] == _prior_report()["selected_step"])["lpips"]]),
    ("prior moves LPIPS by -0.032 / -0.028 and PSNR by +0.12 / -0.05 dB, where the enhancer trained on the\ncapture's own pairs moves LPIPS by -0.001 / +0.005",
     "-0.032 -0.028 0.12 -0.05 -0.001 0.005",
     lambda: [_prior(sc, "prior", "val_bev", "lpips") for sc in ("street", "street-seed7")]
     + [_prior(sc, "prior", "val_bev", "psnr") for sc in ("street", "street-seed7")]
     + [_prior(sc, "own", "val_bev", "lpips") for sc in ("street", "street-seed7")]),
    ("from above (LPIPS -0.004 / +0.008) while it gains most at street level (val_street LPIPS -0.031 /\n-0.062)",
     "-0.004 0.008 -0.031 -0.062",
     lambda: [_prior(sc, "prior + fine-tune", "val_bev", "lpips") for sc in ("street", "street-seed7")]
     + [_prior(sc, "prior + fine-tune", "val_street", "lpips") for sc in ("street", "street-seed7")]),
    ("70 pairs a\nstreet", "70", lambda: [_prior_report()["streets"][0]["pairs"]]),
    ("to\n28.1-29.7 dB PSNR, but at the test cameras from above, which circle the street at other heights and\npitches, only to 25.9-27.2 dB (bev_1) and 22.6-25.1 dB (bev_2)",
     "28.1 29.7 25.9 27.2 1 22.6 25.1 2",
     lambda: [min(_fitgen("fit_aug_views_vs_reference")), max(_fitgen("fit_aug_views_vs_reference")),
              min(_fitgen("bev_1_target_vs_reference")), max(_fitgen("bev_1_target_vs_reference")), 1,
              min(_fitgen("bev_2_target_vs_reference")), max(_fitgen("bev_2_target_vs_reference")), 2]),
    ("carries the reference furthest (26.6 / 27.2 dB bev_1 on the two streets)", "26.6 27.2 1",
     lambda: _fitgen("bev_1_target_vs_reference", "scaffold-gs") + [1]),
    ("`consistency` moves street / bev_1 / bev_2 by -0.03 / -0.07 / -0.12 dB for\nSplatfacto, -0.02 / -0.12 / +0.00 for Scaffold-GS and +0.02 / +0.61 / +0.73 for 2DGS",
     "-0.03 -0.07 -0.12 -0.02 -0.12 0.00 0.02 0.61 0.73",
     lambda: [_gain(_r(D), t, s, variant=CONF_CONS, base=" + NeRF views") for t in T for s in ("street",) + BEV]),
    ("At 4 deg / 40 cm it ends 2.35 dB below\nits unstressed seeds on street views and 1.22 dB from above (street 17.91, BEV 18.81 dB against 20.26 /\n20.03), where Splatfacto alone ended 2.84 dB below "
     "(`stability_preprune.md`, made before the weight prune; 2.62 in `stability_fixed_cap.md` with it)",
     "4 40 2.35 1.22 17.91 18.81 20.26 20.03 2.84 2.62",
     lambda: [4, 40] + [_stab_pose(k) for k in ("street_drop", "bev_drop", "street", "bev", "seed_street", "seed_bev")]
     + [_stab_drop("splatfacto", "pose noise 4deg/40cm", "stability_preprune"), _stab_drop("splatfacto", "pose noise 4deg/40cm", "stability_fixed_cap")]),
    ("at the level of Splatfacto's unstressed BEV (18.78 dB in `stability_preprune.md`)", "18.78",
     lambda: [_stability("stability_preprune")["summary"]["splatfacto"]["seed_bev_mean"]]),
    ("30/30 registered, ATE 0.31%\nof the trajectory after Sim(3) alignment on the bench's video, 2.89% on a second render", "0.31 2.89",
     lambda: [_frag("bench video", "sequential (bench)", "ate_percent"), _frag("second render", "sequential (bench)", "ate_percent")]),
    ("(BEV 3.89 dB below the unstressed 20.13 dB); with 25% its views still beat\nSplatfacto alone from above (19.07 vs 18.78 dB BEV in `stability_preprune.md`'s seeds, both made before the weight prune), with 12% they cost it\n(17.78)",
     "3.89 20.13 19.07 18.78 17.78",
     lambda: [_stab_aug()["breaking_point"]["splatfacto + NeRF views"]["reference steps"]["drop_db"],
              _stab_aug()["summary"]["splatfacto + NeRF views"]["seed_bev_mean"], _stab_aug_case("reference steps 25%"),
              _stability("stability_preprune")["summary"]["splatfacto"]["seed_bev_mean"], _stab_aug_case("reference steps 12%")]),
    ("lifts val_street by +0.83 dB (LPIPS -0.041) on the embedded street and +0.86 dB on the second, where the\nunconditioned one gives +0.12 / +0.24, but it moves val_bev by -0.01 dB on both",
     "0.83 -0.041 0.86 0.12 0.24 -0.01",
     lambda: [_enh_cond("street", "warped", "val_street"), _enh_cond("street", "warped", "val_street", "lpips"),
              _enh_cond("street-seed7", "warped", "val_street"), _enh_cond("street", "none", "val_street"),
              _enh_cond("street-seed7", "none", "val_street"), _enh_cond("street", "warped", "val_bev")]),
    ("2DGS +0.11 / -0.02\ndB val_street / val_bev, Scaffold-GS +0.44 / +0.20 dB", "0.11 -0.02 0.44 0.20",
     lambda: [_av(sc, RO9, sp) - _av(sc, "NeRF views", sp) for sc in (AV_2DGS, AV_SCAF) for sp in ("val_street", "val_bev")]),
    ("(here +2.00 / +3.66 /\n+3.22 dB for Splatfacto / Scaffold-GS / 2DGS", "2.00 3.66 3.22",
     lambda: [_second(f"{t} + NeRF views", "street") - _second(t, "street") for t in TARGETS3]),
    ("24.8-25.8 vs 28.57 dB), and Scaffold-GS + NeRF views beats StreetNeRF on them\n(29.46)", "24.8 25.8 28.57 29.46",
     lambda: _min_max(_second(t, "street") for t in TARGETS3) + [_second("StreetNeRF", "street"), _second("scaffold-gs + NeRF views", "street")]),
    ("(bev_1 0.23 dB above,\nbev_2 0.08 dB below StreetNeRF", "0.23 -0.08",
     lambda: [_second("scaffold-gs + NeRF views", s) - _second("StreetNeRF", s) for s in BEV]),
    ("views term: 6,715 anchors where the growth term alone kept 4,528, +0.40 / +0.02 / -0.10 dB street / bev_1 / bev_2",
     "6,715 4,528 0.40 0.02 -0.10",
     lambda: [_r(SECOND_T)[AUG_SC]["size"]["primitives"], _r(SECOND_GROWTH)[AUG_SC]["size"]["primitives"]]
     + [_psnr(_r(SECOND_T), AUG_SC, s) - _psnr(_r(SECOND_GROWTH), AUG_SC, s) for s in ("street",) + BEV]),
    ("stay bev_1 0.49 / 0.22 dB and bev_2 0.63 / 0.97 dB below it", "0.49 0.22 0.63 0.97",
     lambda: [_second("StreetNeRF", s) - _second(f"{t} + NeRF views", s) for s in BEV for t in ("splatfacto", "2dgs")]),
    ("registers 30/30 again but at ATE 2.89% and a 5.27 deg rotation error", "2.89 5.27",
     lambda: [_frag("second render", "sequential (bench)", "ate_percent"), _frag("second render", "sequential (bench)", "rotation_error_deg")]),
    ("(ATE 23.24% / 15.80%: the repeated facades", "23.24 15.80",
     lambda: [_frag("bench video", "exhaustive", "ate_percent"), _frag("second render", "exhaustive", "ate_percent")]),
    ("F = 0.9 lifts val_street by +0.34 dB on the embedded street (28.27 -> 28.61,\nabove its reference's 28.42) and +0.14 dB on the second street (F = 0.8: +0.30), and moves val_bev by\n+0.05 / +0.01 dB (F = 0.8: +0.02)",
     "0.34 28.27 28.61 28.42 0.14 0.30 0.05 0.01 0.02",
     lambda: [_av(AV_EMB, RO9, "val_street") - _av(AV_EMB, "NeRF views", "val_street"), _av(AV_EMB, "NeRF views", "val_street"),
              _av(AV_EMB, RO9, "val_street"), _av(AV_EMB, "reference", "val_street"),
              _av(AV_SEC, RO9, "val_street") - _av(AV_SEC, "NeRF views", "val_street"),
              _av(AV_SEC, RO8, "val_street") - _av(AV_SEC, "NeRF views", "val_street"),
              _av(AV_EMB, RO9, "val_bev") - _av(AV_EMB, "NeRF views", "val_bev"),
              _av(AV_SEC, RO9, "val_bev") - _av(AV_SEC, "NeRF views", "val_bev"),
              _av(AV_SEC, RO8, "val_bev") - _av(AV_SEC, "NeRF views", "val_bev")]),
    ("F = 0.9 gives 25.07 dB against 24.68\nwithout, still 1.58 dB below Splatfacto alone (26.66)", "25.07 24.68 1.58 26.66",
     lambda: [_av(AV_CASTLE, RO9, "test"), _av(AV_CASTLE, "NeRF views", "test"),
              _av(AV_CASTLE, "baseline (no NeRF views)", "test") - _av(AV_CASTLE, RO9, "test"), _av(AV_CASTLE, "baseline (no NeRF views)", "test")]),
    ("`--augment.confidence consistency` cost castle-P30 2.50 dB\n(22.18)", "2.50 22.18",
     lambda: [_av(AV_CASTLE, "NeRF views", "test") - _av(AV_CASTLE, CONS, "test"), _av(AV_CASTLE, CONS, "test")]),
    ("F = 0.1 ends Splatfacto at 5,950 Gaussians on the embedded street (0.25 dB\nbelow the best swept configuration, 0.99x the smallest within 0.5 dB) and 4,321 on the second street\n(0.35 dB, 0.88x), 2DGS at 7,285 and 5,718 surfels (0.26 / 0.24 dB, 1.13x / 0.87x)",
     "5,950 0.25 0.99 4,321 0.35 0.88 7,285 5,718 0.26 0.24 1.13 0.87",
     lambda: [_size("street", "splatfacto", "w0.1"), _size("street", "splatfacto", "w0.1", "below_best_db"),
              _size("street", "splatfacto", "w0.1", "over_smallest"), _size("street-seed7", "splatfacto", "w0.1"),
              _size("street-seed7", "splatfacto", "w0.1", "below_best_db"), _size("street-seed7", "splatfacto", "w0.1", "over_smallest"),
              _size("street", "2dgs", "w0.1"), _size("street-seed7", "2dgs", "w0.1"),
              _size("street", "2dgs", "w0.1", "below_best_db"), _size("street-seed7", "2dgs", "w0.1", "below_best_db"),
              _size("street", "2dgs", "w0.1", "over_smallest"), _size("street-seed7", "2dgs", "w0.1", "over_smallest")]),
    ("where today's defaults carry 1.8-2.4x", "1.8 2.4",
     lambda: _min_max(_size_default_ratio(sc, m) for sc in ("street", "street-seed7") for m in ("splatfacto", "2dgs"))),
    ("sit 0.96 / 0.99 dB below the best on the validation\nviews", "0.96 0.99",
     lambda: [_size_gap("street", "splatfacto", "cap2000"), _size_gap("street", "2dgs", "cap2000")]),
    ("seed-to-seed spread (up to 0.19 dB in", "0.19",
     lambda: [max(v[k] for v in _stability("stability_preprune")["summary"].values() for k in ("seed_street_std", "seed_bev_std"))]),
    ("`consistency`\n+0.07 / +0.05 / +0.12 and +0.06 / +0.11 / +0.13 dB (LPIPS bev_1 0.330 -> 0.325 and 0.348 -> 0.338)",
     "0.07 0.05 0.12 0.06 0.11 0.13 0.330 0.325 0.348 0.338",
     lambda: [_gain(_conf(sc), "splatfacto", s, variant=CONF_CONS, base=AUG) for sc in ("street", "second_street") for s in ("street", *BEV)]
     + [_psnr(_conf(sc), "splatfacto" + v, "bev_1", "lpips") for sc in ("street", "second_street") for v in (AUG, CONF_CONS)]),
    ("`visibility` moves PSNR by -0.08 / -0.00 / +0.03 dB (street / bev_1 / bev_2)\non the embedded street and +0.01 / +0.03 / +0.03 dB on the second",
     "-0.08 -0.00 0.03 0.01 0.03 0.03", lambda: [_gain(_conf(sc), "splatfacto", s, variant=CONF_VIS, base=AUG) for sc in ("street", "second_street") for s in ("street", *BEV)]),
    ("(bev_1 21.35 vs 23.17 dB, second street 21.38 vs 23.12)", "21.35 23.17 21.38 23.12",
     lambda: [_psnr(_conf(sc), lab, "bev_1") for sc in ("street", "second_street") for lab in ("splatfacto + NeRF views", "StreetNeRF")]),
    ("(+0.90 and +0.16 dB street, +1.89 and +3.00 dB bev_1)", "0.90 0.16 1.89 3.00",
     lambda: [_gain(_conf(sc), "splatfacto", s) for s in ("street", "bev_1") for sc in ("street", "second_street")]),
    ("(load average 4.0-4.5), 2 ranks of one thread\nran 5.80 steps/s against 6.25 for one process of one thread drawing both batches (0.93x)",
     "4.0 4.5 5.80 6.25 0.93", lambda: [min(_dist(i, k) for i in range(3) for k in ("load_before", "load_after")),
                                        max(_dist(i, k) for i in range(3) for k in ("load_before", "load_after")),
                                        _dist(2, "steps_per_second"), _dist(0, "steps_per_second"), _dist(2, "speedup_vs_1_thread")]),
    ("(one process with 2 threads: 4.71 steps/s,\nand its kernel's thread-order sums moved the parameters by up to 0.047)", "4.71 0.047",
     lambda: [_dist(1, "steps_per_second"), _dist(1, "max_param_diff")]),
    ("0.39 / 0.25 / 0.26 dB below the whole-scene run", "0.39 0.25 0.26", lambda: _blocks_gaps(0)),
    ("0.57 dB below at street level but 0.22 / 0.34 dB above", "0.57 0.22 0.34",
     lambda: [_blocks_gaps(1)[0], -_blocks_gaps(1)[1], -_blocks_gaps(1)[2]]),
    ("(load average about 8 during the run)", "8", lambda: [sum(r["load_average"] for r in _scale()["rows"]) / len(_scale()["rows"])]),
    ("0.096 / 0.190 / 0.458 s per step", "0.096 0.190 0.458", lambda: _scale_rows("splatfacto", "resolution", "seconds_per_step")),
    ("0.163 -> 0.299 s from 30 to", "0.163 0.299", lambda: _scale_rows("splatfacto", "images", "seconds_per_step")[::3]),
    ("time per step = 0.0523 s + 4.16e-06 s x", "0.0523 4.16e-06", lambda: _law("splatfacto", "time")["coef"][:2]),
    ("pixels + 4.67e-06 s x primitives (8.3% RMS residual)", "4.67e-06 8.3",
     lambda: [_law("splatfacto", "time")["coef"][2], 100 * _law("splatfacto", "time")["rms_relative_residual"]]),
    ("0.41 s whatever the resolution (11.8% RMS", "0.41 11.8",
     lambda: [_law("streetnerf", "time")["coef"][0], 100 * _law("streetnerf", "time")["rms_relative_residual"]]),
    ("(0.34 -> 0.46 s from 30 to 240", "0.34 0.46", lambda: _scale_rows("streetnerf", "images", "seconds_per_step")[::3]),
    ("489 MB + 24.9 bytes per training pixel", "489 24.9", lambda: [_law("streetnerf", "rss")["coef"][0], _law("streetnerf", "rss")["coef"][1] * 2**20]),
    ("371 MB + 26.6 bytes per pixel (Splatfacto), 2.9% / 1.0% RMS residual", "371 26.6 2.9 1.0",
     lambda: [_law("splatfacto", "rss")["coef"][0], _law("splatfacto", "rss")["coef"][1] * 2**20,
              100 * _law("streetnerf", "rss")["rms_relative_residual"], 100 * _law("splatfacto", "rss")["rms_relative_residual"]]),
    ("checkpoint stays 13.0 MB", "13.0 13.0", lambda: _min_max(_scale_rows("streetnerf", "images", "checkpoint_mb"))),
    ("(2.7 MB per 4,000", "2.7", lambda: _scale_rows("splatfacto", "images", "checkpoint_mb")[:1]),
    ("21.6 MB at 240 frames", "21.6", lambda: _scale_rows("splatfacto", "images", "checkpoint_mb")[-1:]),
    ("(625 frames at the", "625", lambda: [_scale()["projection"]["images"]]),
    ("one Splatfacto run needs 78.8 h and 32.4 GB", "78.8 32.4",
     lambda: [_proj("splatfacto", "one run", "hours"), _proj("splatfacto", "one run", "peak_rss_gb")]),
    ("than the machine has (23.5 GB)", "23.5", lambda: [_scale()["machine"]["memory_gb"]]),
    ("need 10.6 h and 4.9 GB each, 106.2 h one", "10.6 4.9 106.2",
     lambda: [_proj("splatfacto", "per block", "hours"), _proj("splatfacto", "per block", "peak_rss_gb"),
              _scale()["projection"]["splatfacto"]["blocks one after another, hours"]]),
    ("projects to 333 h and 30.5 GB as one run vs 46.6 h and 4.7 GB per block", "333 30.5 46.6 4.7",
     lambda: [_proj("streetnerf", "one run", "hours"), _proj("streetnerf", "one run", "peak_rss_gb"),
              _proj("streetnerf", "per block", "hours"), _proj("streetnerf", "per block", "peak_rss_gb")]),
    ("+2.0 (Splatfacto), +2.7 (Scaffold-GS) and +1.9\n(2DGS) dB on bev_1", "2.0 2.7 1.9", lambda: [_gain(_r(Q), t, "bev_1") for t in T]),
    ("+1.7 / +2.6 / +1.5 dB on bev_2", "1.7 2.6 1.5", lambda: [_gain(_r(Q), t, "bev_2") for t in T]),
    ("the road from above by 2.8-4.5 dB", "2.8 4.5", lambda: _min_max(_gain(_r(Q), t, s, "psnr_ground") for t in T for s in BEV)),
    ("street PSNR by 1.0-1.6 dB", "1.0 1.6", lambda: _min_max(_gain(_r(Q), t, "street") for t in T)),
    ("(38-208x StreetNeRF's\nFPS", "38 208", lambda: _min_max(_r(Q)[t + AUG]["fps"] / _r(Q)["StreetNeRF"]["fps"] for t in T)),
    ("(bev_1 23.2 vs 19.5 dB)", "23.2 19.5", lambda: [_psnr(_r(Q), "StreetNeRF", "bev_1"), _psnr(_r(Q), "splatfacto", "bev_1")]),
    ("-0.21 to +0.23 dB from above\n(Splatfacto bev_1 21.26, Scaffold-GS 23.12, 2DGS 21.80)", "-0.21 0.23 21.26 23.12 21.80",
     lambda: _min_max(_gain(_r(Q), t, s, variant=ENH, base=AUG) for t in T for s in BEV) + [_psnr(_r(Q), t + ENH, "bev_1") for t in T]),
    ("1.1-1.8 dB below\nit at the quick scale", "1.1 1.8", lambda: _min_max(_below_nerf(_r(Q)))),
    ("NeRF views add +3.0 / +3.1 / +2.3 dB bev_1 and +1.8 / +2.7 / +2.3 dB street", "3.0 3.1 2.3 1.8 2.7 2.3",
     lambda: [_gain(_r(D), t, "bev_1") for t in T] + [_gain(_r(D), t, "street") for t in T]),
    ("(27.67 / 24.35 / 22.80\nvs 26.46 / 23.84 / 22.30 dB street / bev_1 / bev_2)", "27.67 24.35 22.80 26.46 23.84 22.30",
     lambda: [_psnr(_r(D), lab, s) for lab in ("scaffold-gs + NeRF views", "StreetNeRF") for s in ("street", *BEV)]),
    ("(25.97 vs 26.54 dB;\n25.10 vs 25.68 bev_2)", "25.97 26.54 25.10 25.68",
     lambda: [_psnr(_r(D), lab, s, "psnr_ground") for s in BEV for lab in ("scaffold-gs + NeRF views", "StreetNeRF")]),
    ("(0.133 vs 0.118 bev_1)", "0.133 0.118", lambda: [_psnr(_r(D), lab, "bev_1", "lpips") for lab in ("scaffold-gs + NeRF views", "StreetNeRF")]),
    ("The enhancer moves bev_1 / bev_2\nby +0.02 / -0.20 dB for Splatfacto, -0.13 / -0.01 for Scaffold-GS and +0.43 / +0.48 for 2DGS",
     "0.02 -0.20 -0.13 -0.01 0.43 0.48", lambda: [_gain(_r(D), t, s, variant=ENH, base=AUG) for t in T for s in BEV]),
    ("+0.02 /\n-0.20 dB bev_1 / bev_2 for Splatfacto, -0.13 / -0.01 for Scaffold-GS, +0.43 / +0.48 for 2DGS",
     "0.02 -0.20 -0.13 -0.01 0.43 0.48", lambda: [_gain(_r(D), t, s, variant=ENH, base=AUG) for t in T for s in BEV]),
    ("(12.4k surfels;", "12.4", lambda: [_r(D)["2dgs"]["size"]["primitives"] / 1000]),
    ("its default is the best\nconfiguration (5,628 primitives) and 1.60x the smallest one inside the band (`max_anchors` 1000: 3,515,\n0.26 dB below)",
     "5,628 1.60 1000 3,515 0.26", lambda: [_scaffold_size("default"), _scaffold_size("ratio"), 1000, _scaffold_size("smallest"),
                                            _scaffold_size("below")]),
    ("the reference breaks FIRST under pose noise, at 2 deg / 20 cm\n(street 4.64 dB below its seeds; 1 deg / 10 cm already costs 2.79)",
     "2 20 4.64 1 10 2.79", lambda: [2, 20, _stab_sn("pose noise 2deg/20cm", "street"), 1, 10, _stab_sn("pose noise 1deg/10cm", "street")]),
    ("fewer views do not break it down to 12% (2.00 dB\nbelow from above there)", "12 2.00", lambda: [12, _stab_sn("views kept 12%", "bev")]),
    ("Splatfacto + NeRF views does not break up to 8x\nthe cars and loses nothing measurable there (street 0.05 dB ABOVE its seeds, BEV 0.22 above), where\n"
     "Splatfacto alone ends 2.01 dB below at 8x", "8 0.05 0.22 2.01 8",
     lambda: [8, -_stab_view("splatfacto + NeRF views", "transients 8x", "stability_augmented_transients/stability", "street"),
              -_stab_view("splatfacto + NeRF views", "transients 8x", "stability_augmented_transients/stability", "bev"),
              _stab_view("splatfacto", "transients 8x", "stability_masks/stability", "street"), 8]),
    ("masks\ngrown by 12 px break it (street 3.62 dB below; 6 px costs 1.89)", "12 3.62 6 1.89",
     lambda: [12, _stab_sn("mask dilation 12px", "street"), 6, _stab_sn("mask dilation 6px", "street")]),
    ("eroded masks (none up to\n12 px, 0.82 below), half or all of the masks dropped (none; 1.16 below with no masks at all) and 8x the\n"
     "cars (0.70 below", "12 0.82 1.16 8 0.70",
     lambda: [12, _stab_sn("mask erosion 12px", "street"), _stab_sn("no masks", "street"), 8, _stab_sn("transients 8x", "street")]),
    ("+-2 stops (street 3.89 dB below) like every splatting method, and +-1 stop costs it 1.60 dB", "2 3.89 1 1.60",
     lambda: [2, _stab_sn("exposure +-2 stop", "street"), 1, _stab_sn("exposure +-1 stop", "street")]),
    ("8 failures in 45 runs", "8 45", lambda: [sum(s["failures"] for s in _stability()["summary"].values()), len(_stability()["rows"])]),
    ("2DGS and Scaffold-GS at 4 deg / 40 cm (3.10 / 3.99 dB below), Splatfacto not up to it\n  (2.54 dB below there)",
     "4 40 3.10 3.99 2.54", lambda: [4, 40] + [_stab_drop(m, "pose noise 4deg/40cm") for m in ("2dgs", "scaffold-gs", "splatfacto")]),
    ("down to 12% of the training views (0.61 / 1.15 / 1.48 dB below", "12 0.61 1.15 1.48",
     lambda: [12] + [_stab_drop(m, "views kept 12%") for m in T_STAB]),
    ("+-1 stop holds (1.57 / 1.91 /\n  2.78 dB below), +-2 stops breaks all three (3.99 / 4.38 / 5.54 dB below",
     "1 1.57 1.91 2.78 2 3.99 4.38 5.54", lambda: [1] + [_stab_drop(m, "exposure +-1 stop") for m in T_STAB]
     + [2] + [_stab_drop(m, "exposure +-2 stop") for m in T_STAB]),
    ("breaks all three now (Splatfacto 3.56, 2DGS 3.85, Scaffold-GS\n  3.87 dB below). Splatfacto ends with 287 Gaussians (546 with the fixed caps, where it ended just inside the\n  band, 2.78 dB below",
     "3.56 3.85 3.87 287 546 2.78",
     lambda: [_stab_drop(m, "random init") for m in T_STAB]
     + [next(r["primitives"] for r in _stability(stem)["rows"] if r["method"] == "splatfacto" and r["variant"] == "random init")
        for stem in ("stability", "stability_fixed_cap")] + [_stab_drop("splatfacto", "random init", "stability_fixed_cap")]),
    ("every other drop moved by\nat most 0.47 dB (2DGS's BEV at 12% of the views: 1.15 against 0.82)", "0.47 12 1.15 0.82",
     lambda: [max(abs(_stab_view(m, r["variant"], "stability", v) - _stab_view(m, r["variant"], "stability_fixed_cap", v))
                  for m in T_STAB for r in _stability()["rows"] if r["method"] == m and not r["variant"].startswith("seed")
                  and r["variant"] != "random init" for v in ("street", "bev")), 12,
              _stab_view("2dgs", "views kept 12%", "stability", "bev"), _stab_view("2dgs", "views kept 12%", "stability_fixed_cap", "bev")]),
    ("where before the prune it broke (3.12)", "3.12", lambda: [_stab_drop("splatfacto", "random init", "stability_preprune")]),
    ("(0.02 dB over 2 seeds, `stability_preprune.md`)", "0.02 2",
     lambda: [_stability("stability_preprune")["summary"]["splatfacto"]["seed_bev_std"], _stability("stability_preprune")["summary"]["splatfacto"]["seed_bev_n"]]),
    ("128 s of training in all (StreetNeRF 105 s", "128 105",
     lambda: [sum(r["train_seconds"] for r in _r(GPU).values()), _r(GPU)["StreetNeRF"]["train_seconds"]]),
    ("Splatfacto + NeRF views +2.6 / +2.3 dB from above (CPU +2.3 / +1.9)", "2.6 2.3 2.3 1.9",
     lambda: [_gain(_r(GPU), "splatfacto", s) for s in BEV] + [_gain(_r("quick_fixed_cap.json"), "splatfacto", s) for s in BEV]),
    ("val_bev 21.15 dB at degree 0 vs 19.46\n  at degree 3, val_street 24.34 vs 24.08", "21.15 19.46 24.34 24.08",
     lambda: [_r("sh_degree_val.json")[f"sh_degree {d}"]["results"][s]["psnr"] for s in ("val_bev", "val_street") for d in (0, 3)]),
    ("Splatfacto from above -0.07 /\n-0.16 dB and Splatfacto + NeRF views +0.29 / +0.26 dB", "-0.07 -0.16 0.29 0.26",
     lambda: [_psnr(_r(GPU), lab, s) - _psnr(_r("quick_fixed_cap.json"), lab, s) for lab in ("splatfacto", "splatfacto + NeRF views") for s in BEV]),
    ("enhancer moves val_bev by +0.19 / +0.06 / -0.12 dB", "0.19 0.06 -0.12",
     lambda: [_r("enhancer_val.json", "enhancer_minus_without")[t]["psnr_val_bev"] for t in T]),
    # the budget read from the views, tried as the default (benchmarks/results/views_budget/)
    ("a fixed 8,000 budget was inside the band on both\nstreets at the quick scale but 0.67 dB below the best with NeRF views, and at the default scale a 15,000\n"
     "budget ends 0.82 dB below the best", "8,000 0.67 15,000 0.82",
     lambda: [8000, _size_pick("splatfacto", "model_size_augmented/model_size.json")["best_quality"]
              - _size_row("splatfacto max_gaussians=8000", "model_size_augmented/model_size.json")["val_quality"], 15000,
              _size_pick("splatfacto", VB + "street_default/model_size.json")["best_quality"]
              - _size_row("splatfacto pixel_steps_per_gaussian=108000", VB + "street_default/model_size.json")["val_quality"]]),
    ("target in 10 of 15 cases", "10 15", lambda: [_r(VB + "summary.json", "met"), _r(VB + "summary.json", "of")]),
    ("(Splatfacto 3,773 Gaussians\nwhere the fixed budget keeps 6,512, 1.07x the smallest model in the band)", "3,773 6,512 1.07",
     lambda: [_size_pick("splatfacto", VB + "street_quick/model_size.json")["default"]["primitives"],
              _size_row("splatfacto pixel_steps_per_gaussian=0", VB + "street_quick/model_size.json")["primitives"],
              _size_pick("splatfacto", VB + "street_quick/model_size.json")["default_over_smallest"]]),
    ("Scaffold-GS with NeRF views (1.66x", "1.66", lambda: [_size_pick("scaffold-gs", VB + "street_nerf_views_quick/model_size.json")["default_over_smallest"]]),
    ("2DGS (0.57 / 0.82 dB below its unpruned best", "0.57 0.82",
     lambda: [_size_pick("2dgs", VB + f"{st}/model_size.json")["default_below_best_db"] for st in ("street_default", "second_street_default")]),
    ("`prune-weight-fraction 0.05` gives 12,373\nsurfels, 0.23 dB below", "0.05 12,373 0.23",
     lambda: [0.05, _size_row("2dgs prune_weight_fraction=0.05", VB + "street_default/model_size.json")["primitives"],
              _size_pick("2dgs", VB + "street_default/model_size.json")["best_quality"]
              - _size_row("2dgs prune_weight_fraction=0.05", VB + "street_default/model_size.json")["val_quality"]]),
    ("growth buys\n0.35 dB for 2.46x the anchors, and 0.03 dB for 2.33x on the second street", "0.35 2.46 0.03 2.33",
     lambda: [v for st in ("street_default", "second_street_default") for v in (
         _size_pick("scaffold-gs", VB + f"{st}/model_size.json")["best_quality"] - _size_pick("scaffold-gs", VB + f"{st}/model_size.json")["smallest_quality"],
         _size_pick("scaffold-gs", VB + f"{st}/model_size.json")["default_over_smallest"])]),
    ("Splatfacto keeps 4,090 Gaussians where the\nfixed budget keeps 13,707 and loses 0.75 / 0.70 dB (25.37 -> 24.62, 25.34 -> 24.64)",
     "4,090 13,707 0.75 0.70 25.37 24.62 25.34 24.64",
     lambda: [_castle_budget(0, "views")["primitives"], _castle_budget(0, "fixed")["primitives"]]
     + [_castle_budget(k, "fixed")["mean"] - _castle_budget(k, "views")["mean"] for k in (0, 1)]
     + [_castle_budget(k, v)["mean"] for k in (0, 1) for v in ("fixed", "views")]),
    ("Splatfacto's default ends at 6,512 Gaussians, 0.23 dB below the best configuration (the unpruned\n12,703), but 1.72x "
     "the smallest one inside the band (the 8,000 budget, pruned too: 3,792, 0.29 dB", "6,512 0.23 12,703 1.72 3,792 0.29",
     lambda: [_size_pick("splatfacto")["default"]["primitives"], _size_pick("splatfacto")["default_below_best_db"],
              _size_pick("splatfacto")["best_primitives"], _size_pick("splatfacto")["default_over_smallest"],
              _size_pick("splatfacto")["smallest_primitives"],
              _size_pick("splatfacto")["best_quality"] - _size_pick("splatfacto")["smallest_quality"]]),
    ("(7,254 surfels, 0.24 dB below the\nunpruned 15,258)", "7,254 0.24 15,258",
     lambda: [_size_pick("2dgs")["smallest_primitives"], _size_pick("2dgs")["default_below_best_db"], _size_pick("2dgs")["best_primitives"]]),
    ("rises by 0.24-0.62 dB\nper refinement while they grow by 13-19% and by 0.23-0.47 dB per refinement while none are added",
     "0.24 0.62 13 19 0.23 0.47", lambda: _growth_ranges()),
    ("(3,674 -> 7,220 as they grow 5,587 -> 14,137); a Gaussian is visible\nin 34-49% of the steps", "3,674 7,220 5,587 14,137 34 49",
     lambda: [_growth()[0]["carry_90pct_weight"], _growth_last_growing()["carry_90pct_weight"], _growth()[0]["gaussians"],
              _growth_last_growing()["gaussians"]] + [100 * f(r["visible_per_step"] for r in _growth()) for f in (min, max)]),
    ("`growth_signals/stop_split_at_162.md`: 3,533 Gaussians, 21.17 dB)\nlands outside the band where the budget itself (3,792, 21.51)",
     "162 3,533 21.17 3,792 21.51",
     lambda: [162, _growth("stop_split_at_162", final=True)["primitives"], _growth("stop_split_at_162", final=True)["val_mean"],
              _size_row("splatfacto max_gaussians=8000")["primitives"], _size_row("splatfacto max_gaussians=8000")["val_quality"]]),
    ("Splatfacto 25.37 dB, + NeRF views 22.34 (one photo lost to a veil again, 17.23 dB, which Splatfacto alone\n"
     "no longer loses), + NeRF views with `consistency` 24.49 (that photo 24.11); the streets' validation views\n"
     "move by -0.07 / +0.01 dB. Still 0.88 dB below Splatfacto", "25.37 22.34 17.23 24.49 24.11 -0.07 0.01 0.88",
     lambda: [_conf_depth(CASTLE_VAL, "splatfacto")["mean"], _conf_depth(CASTLE_VAL, CONF_NONE)["mean"],
              _conf_depth(CASTLE_VAL, CONF_NONE)["psnr_per_view"]["test"][3], _conf_depth(CASTLE_VAL, CONF_C)["mean"],
              _conf_depth(CASTLE_VAL, CONF_C)["psnr_per_view"]["test"][3]]
     + [_conf_depth(sc, CONF_C)["mean"] - _conf_depth(sc, CONF_NONE)["mean"] for sc in (STREET_E, STREET_7)]
     + [_conf_depth(CASTLE_VAL, "splatfacto")["mean"] - _conf_depth(CASTLE_VAL, CONF_C)["mean"]]),
    ("at seed 2 (the targets only) no photo is veiled\nand `consistency` is the worse one: 25.34 / 24.13 / 23.90 dB", "2 25.34 24.13 23.90",
     lambda: [2] + [_conf_depth(CASTLE_VAL + ", seed 2", v)["mean"] for v in ("splatfacto", CONF_NONE, CONF_C)]),
    ("Splatfacto scores 24.67 dB, + NeRF views 23.75, with weight\n0.3 24.38, with 0.1 22.83 (a photo lost to a veil, 19.53), with `real-only-from 0.6` 24.06",
     "24.67 23.75 0.3 24.38 0.1 22.83 19.53 0.6 24.06",
     lambda: [_aw(0)["mean"], _aw(1)["mean"], 0.3, _aw(2)["mean"], 0.1, _aw(3)["mean"], min(_aw(3)["psnr_per_view"]["test"]), 0.6, _aw(4)["mean"]]),
    ("weight 0.3 costs 0.50 / 1.02 dB val_bev and 0.84 / 1.16 dB val_street", "0.3 0.50 1.02 0.84 1.16",
     lambda: [0.3] + [_aw(i)["psnr"][s] - _aw(i + 1)["psnr"][s] for s in ("val_bev", "val_street") for i in (5, 7)]),
    ("(10,261 -> 6,269 and 8,332 -> 5,239 Gaussians)", "10,261 6,269 8,332 5,239", lambda: [_aw(i)["primitives"] for i in (5, 6, 7, 8)]),
    ("than Splatfacto alone (8,256 against 10,513)", "8,256 10,513", lambda: [_aw(1)["primitives"], _aw(0)["primitives"]]),
    ("ranking the prune by each kind's share, was tried and did not help: 23.42 / 23.21 dB)", "23.42 23.21",
     lambda: [_aw(11)["mean"], _aw(12)["mean"]]),
    ("Trained 600 / 3000 / 6000 steps it scores\n21.30 / 22.75 / 23.26 dB there (Splatfacto 24.67), and Splatfacto + NeRF views from each scores 23.75 / 23.55 /\n22.78",
     "600 3000 6000 21.30 22.75 23.26 24.67 23.75 23.55 22.78",
     lambda: [_rl(i)["steps"] for i in (1, 2, 3)] + [_rl(i)["mean"] for i in (1, 2, 3, 0, 4, 5, 6)]),
    ("and score higher: 25.16 dB alone (15,142 Gaussians), 24.47 with NeRF views (11,969), a gap of 0.69 dB",
     "25.16 15,142 24.47 11,969 0.69",
     lambda: [_aw(9)["mean"], _aw(9)["primitives"], _aw(10)["mean"], _aw(10)["primitives"], _aw(9)["mean"] - _aw(10)["mean"]]),
    ("its 1.25x growth alone stopped at 4,451 anchors, 0.51 dB below the uncapped\nbest (8,679 anchors, 27.36 dB) where the band ends at 0.50",
     "1.25 4,451 0.51 8,679 27.36 0.50",
     lambda: [1.25, _nv_default(SC_GROWTH, "scaffold-gs default")["primitives"], _nv_pick(SC_GROWTH)["default_below_best_db"],
              _nv_pick(SC_GROWTH)["best_primitives"], _nv_pick(SC_GROWTH)["best_quality"], 0.5]),
    ("growth 1.5: 5,343 anchors, 0.30 dB below", "1.5 5,343 0.30",
     lambda: [1.5, _nv_default(SC_GROWTH, "scaffold-gs anchor_growth=1.5")["primitives"],
              _nv_pick(SC_GROWTH)["best_quality"] - _nv_default(SC_GROWTH, "scaffold-gs anchor_growth=1.5")["val_quality"]]),
    ("(120 views of 200x112 px x 1,350 growing steps / 540,000 = 6,720) it keeps 6,712 anchors, 0.12 dB below the\nuncapped best",
     "120 200 112 1,350 540,000 6,720 6,712 0.12",
     lambda: [120, 200, 112, 1350, 540000, 120 * 200 * 112 * 1350 // 540000, _nv_default("scaffold", "scaffold-gs default")["primitives"],
              _nv_pick("scaffold")["default_below_best_db"]]),
    ("reproduce the earlier default and the\nuncapped run to the digit (4,451 / 26.85 dB, 8,679 / 27.36 dB)", "4,451 26.85 8,679 27.36",
     lambda: [x for a, b in (("scaffold-gs pixel_steps_per_anchor=0", "scaffold-gs default"), ("scaffold-gs pixel_steps_per_anchor=20000", "scaffold-gs anchor_growth=0"))
              for x in (_nv_default("scaffold", a)["primitives"], _nv_default("scaffold", a)["val_quality"])
              if _nv_default("scaffold", a)["primitives"] == _nv_default(SC_GROWTH, b)["primitives"]
              and f"{_nv_default('scaffold', a)['val_quality']:.2f}" == f"{_nv_default(SC_GROWTH, b)['val_quality']:.2f}"]),
    ("keeps 12,194 surfels (0.17 dB below its best, 1.35x the\nfixed 10%'s 9,050) and the fixed 10% scores the same from above (test BEV 22.15 against 22.22 dB)",
     "12,194 0.17 1.35 10 9,050 10 22.15 22.22",
     lambda: [_nv_default("2dgs", "2dgs default")["primitives"], _nv_pick("2dgs")["default_below_best_db"], _nv_pick("2dgs")["default_over_smallest"], 10,
              _nv_default("2dgs", "2dgs prune_margin_db=0")["primitives"], 10, _nv_default("2dgs", "2dgs prune_margin_db=0")["bev_psnr"],
              _nv_default("2dgs", "2dgs default")["bev_psnr"]]),
    # the ablation (quick): changes against the full StreetNeRF / the Splatfacto baseline
    ("itself +0.06 / +0.07 dB, by StreetNeRF +1.97 / +1.67 dB", "0.06 0.07 1.97 1.67",
     lambda: [_gain(_r(A), "splatfacto", s, variant=v) for v in (" + views from splatfacto", " + views from StreetNeRF") for s in BEV]),
    ("without its sky model -0.8 / -8.1 dB", "-0.8 -8.1", lambda: [_abl("sky", s) for s in BEV]),
    ("half-built (bev_1 19.1 dB, below Splatfacto", "19.1", lambda: [_psnr(_r(A), "StreetNeRF w/o point_depth", "bev_1")]),
    ("without the point-depth loss -4.2 / -3.5", "-4.2 -3.5", lambda: [_abl("point_depth", s) for s in BEV]),
    ("masking -1.9 dB street", "-1.9", lambda: [_abl("transient_mask", "street")]),
    ("without ground regularisation -0.7 / -0.6 dB on the road from above (-0.2 / -0.2 on", "-0.7 -0.6 -0.2 -0.2",
     lambda: [_abl("ground_reg", s, "psnr_ground") for s in BEV] + [_abl("ground_reg", s) for s in BEV]),
    ("without appearance -0.1 street", "-0.1", lambda: [_abl("appearance", "street")]),
    ("the Splatfacto baseline had 6,512 Gaussians and its views from StreetNeRF added\n+2.21 / +1.85 dB; today's 3,793 Gaussians (6,246 with the views) score 0.31 dB lower at street level and 0.13 /\n0.11 dB higher from above",
     "6,512 2.21 1.85 3,793 6,246 0.31 0.13 0.11",
     lambda: [_r("ablation_fixed_cap.json")["splatfacto"]["size"]["primitives"]]
     + [_gain(_r("ablation_fixed_cap.json"), "splatfacto", s, variant=" + views from StreetNeRF") for s in BEV]
     + [_r(A)["splatfacto"]["size"]["primitives"], _r(A)["splatfacto + views from StreetNeRF"]["size"]["primitives"],
        _psnr(_r("ablation_fixed_cap.json"), "splatfacto", "street") - _psnr(_r(A), "splatfacto", "street")]
     + [_psnr(_r(A), "splatfacto", s) - _psnr(_r("ablation_fixed_cap.json"), "splatfacto", s) for s in BEV]),
    ("StreetNeRF by -0.14 / -0.26 / -0.15 dB street / bev_1 / bev_2", "-0.14 -0.26 -0.15",
     lambda: [_gain(_r(A), "splatfacto", s, variant=" + views from StreetNeRF (consistency confidence)", base=" + views from StreetNeRF")
              for s in ("street",) + BEV]),
    ("adds -0.02 / -0.03 dB to views from Splatfacto and -0.21 / -0.22 dB to", "-0.02 -0.03 -0.21 -0.22",
     lambda: [_gain(_r(A), "splatfacto", s, variant=v + " + enhancer", base=v)
              for v in (" + views from splatfacto", " + views from StreetNeRF") for s in BEV]),
    # the real photo set (castle-P30): held-out photos, and SfM time per variant
    ("StreetNeRF 22.46 / 22.50 / 23.13 / 22.36, Splatfacto\n24.81 / 28.32 / 25.07 / 25.72, + NeRF views 24.58 / 8.61 / 24.32 / 24.59",
     "22.46 22.50 23.13 22.36 24.81 28.32 25.07 25.72 24.58 8.61 24.32 24.59",
     lambda: _per_photo("StreetNeRF", RP4) + _per_photo("splatfacto", RP4) + _per_photo("splatfacto + NeRF views", RP4)),
    ("StreetNeRF 22.46 / 22.50 / 23.13 / 22.36, Splatfacto 25.00 / 28.48 / 25.32 /\n25.97, + NeRF views 24.47 / 17.23 / 25.31 / 24.52",
     "22.46 22.50 23.13 22.36 25.00 28.48 25.32 25.97 24.47 17.23 25.31 24.52",
     lambda: _per_photo("StreetNeRF", RP5) + _per_photo("splatfacto", RP5) + _per_photo("splatfacto + NeRF views", RP5)),
    ("StreetNeRF is 3.58 dB below\nSplatfacto, Splatfacto + NeRF views 3.31 dB", "3.58 3.31",
     lambda: [_psnr(_r(RP5), "splatfacto", "test") - _psnr(_r(RP5), n, "test") for n in ("StreetNeRF", "splatfacto + NeRF views")]),
    ("lifted every photo of\nSplatfacto alone a little (+0.15 to +0.25 dB)", "0.15 0.25",
     lambda: [min(a - b for a, b in zip(_per_photo("splatfacto", RP5), _per_photo("splatfacto", RP4))),
              max(a - b for a, b in zip(_per_photo("splatfacto", RP5), _per_photo("splatfacto", RP4)))]),
    ("other three photos the augmented run is 0.01-1.46 dB below Splatfacto", "0.01 1.46",
     lambda: [min(a - b for k, (a, b) in enumerate(zip(_per_photo("splatfacto", RP5), _per_photo("splatfacto + NeRF views", RP5))) if k != 1),
              max(a - b for k, (a, b) in enumerate(zip(_per_photo("splatfacto", RP5), _per_photo("splatfacto + NeRF views", RP5))) if k != 1)]),
    ("PSNR per held-out photo: StreetNeRF 22.83 / 20.77 / 23.34 / 21.26, Splatfacto 25.43 / 25.45 / 25.43 /\n"
     "25.39, + NeRF views 25.00 / 24.22 / 24.44 / 24.20", "22.83 20.77 23.34 21.26 25.43 25.45 25.43 25.39 25.00 24.22 24.44 24.20",
     lambda: _per_photo("StreetNeRF", RP6) + _per_photo("splatfacto", RP6) + _per_photo("splatfacto + NeRF views", RP6)),
    ("StreetNeRF is 3.38\ndB below Splatfacto, Splatfacto + NeRF views 0.96 dB, on every photo (0.43-1.23 dB)", "3.38 0.96 0.43 1.23",
     lambda: [_psnr(_r(RP6), "splatfacto", "test") - _psnr(_r(RP6), n, "test") for n in ("StreetNeRF", "splatfacto + NeRF views")]
     + [f(a - b for a, b in zip(_per_photo("splatfacto", RP6), _per_photo("splatfacto + NeRF views", RP6))) for f in (min, max)]),
    ("augmented run (15.17 dB; mean\n22.13 against Splatfacto's 25.69", "15.17 22.13 25.69",
     lambda: [_table_row("augment_appearance", APP_MEAN, CASTLE_TEST + ", seed 2", exact=True)["psnr_per_view"]["test"][1],
              _aug_app(CASTLE_TEST + ", seed 2", APP_MEAN), _aug_app(CASTLE_TEST + ", seed 2", "splatfacto")]),
    ("Splatfacto alone loses one photo to it (16.60 dB)", "16.60",
     lambda: [_table_row("augment_appearance", "splatfacto", CASTLE_VAL, exact=True)["psnr_per_view"]["test"][3]]),
    ("its camera stands 5.4 m from the nearest training camera\nand the Gaussians within 2.2 m in front of it (33; muted: 24.11 dB;\n"
     "`benchmarks/results/near_camera_floaters_castle_val.md`) lie 3.1-10.9 m from the capture path", "5.4 2.2 33 24.11 3.1 10.9",
     lambda: [_ncf_val()["camera_to_nearest_training_camera_m"], _ncf_val()["rows"][2]["within_m"], _ncf_val()["rows"][2]["gaussians"],
              _ncf_val()["rows"][2]["psnr_muted"], min(_ncf_val()["rows"][2]["to_path_m"]), max(_ncf_val()["rows"][2]["to_path_m"])]),
    ("PSNR per held-out photo: StreetNeRF 22.83 / 20.77 / 23.34 / 21.26, Splatfacto 25.31 / 27.21 / 26.24 /\n"
     "25.66, + NeRF views 25.26 / 25.51 / 25.39 / 24.32. Point 5 is not met: StreetNeRF is 4.05 dB below\n"
     "Splatfacto, Splatfacto + NeRF views 0.98 dB. The depth loss lifts both targets (Splatfacto +0.68 dB, + NeRF\nviews +0.65",
     "22.83 20.77 23.34 21.26 25.31 27.21 26.24 25.66 25.26 25.51 25.39 24.32 4.05 0.98 0.68 0.65",
     lambda: _per_photo("StreetNeRF", RP7) + _per_photo("splatfacto", RP7) + _per_photo("splatfacto + NeRF views", RP7)
     + [_psnr(_r(RP7), "splatfacto", "test") - _psnr(_r(RP7), n, "test") for n in ("StreetNeRF", "splatfacto + NeRF views")]
     + [_psnr(_r(RP7), n, "test") - _psnr(_r(RP6), n, "test") for n in ("splatfacto", "splatfacto + NeRF views")]),
    ("PSNR per held-out photo: StreetNeRF 22.96 / 21.84 / 22.81 / 21.64, Splatfacto 24.98 / 28.28 / 27.32 /\n"
     "25.27, + NeRF views 24.39 / 25.40 / 25.33 / 24.69. Point 5 is not met: StreetNeRF is 4.15 dB below\n"
     "Splatfacto, Splatfacto + NeRF views 1.51 dB (12,495 and 10,542 Gaussians). On castle-P30's validation photos\n"
     "(`augment_weight_val.md`, see \"Augmentation\") the gap is 0.92 dB",
     "22.96 21.84 22.81 21.64 24.98 28.28 27.32 25.27 24.39 25.40 25.33 24.69 4.15 1.51 12,495 10,542 0.92",
     lambda: _per_photo("StreetNeRF") + _per_photo("splatfacto") + _per_photo("splatfacto + NeRF views")
     + [_psnr(_r(RP), "splatfacto", "test") - _psnr(_r(RP), n, "test") for n in ("StreetNeRF", "splatfacto + NeRF views")]
     + [_r(RP)[n]["size"]["primitives"] for n in ("splatfacto", "splatfacto + NeRF views")] + [_aw(0)["mean"] - _aw(1)["mean"]]),
    ("StreetNeRF gained 0.85 dB with\nthe colour transforms held to the identity", "0.85",
     lambda: [_psnr(_r(RP4), "StreetNeRF", "test") - _psnr(_r(RP3), "StreetNeRF", "test")]),
    ("no appearance model at all gives 22.84,\nand 1800 steps 23.82 with the pull / 24.36 without), still 3.37 dB below Splatfacto",
     "22.84 1800 23.82 24.36 3.37",
     lambda: [_app_reg("castle", "no appearance", 600), 1800, _app_reg("castle", "affine, reg 1.0", 1800), _app_reg("castle", "no appearance", 1800),
              _psnr(_r(RP4), "splatfacto", "test") - _psnr(_r(RP4), "StreetNeRF", "test")]),
    ("plain Splatfacto at 500 steps (19.65 dB mean)", "500 19.65", lambda: [500, _floater_run("splatfacto, 500")]),
    ("no longer has it but stays below Splatfacto, 23.07 dB", "23.07", lambda: [_floater_run("splatfacto + NeRF views, 2000")]),
    ("StreetNeRF is 4.22 dB\nbelow Splatfacto", "4.22", lambda: [_psnr(_r(RP3), "splatfacto", "test") - _psnr(_r(RP3), "StreetNeRF", "test")]),
    ("Splatfacto + NeRF views falls 5.56 dB below Splatfacto", "5.56",
     lambda: [_psnr(_r(RP3), "splatfacto", "test") - _psnr(_r(RP3), "splatfacto + NeRF views", "test")]),
    ("the reference is 4.22 dB BELOW the baseline on 4\nheld-out views (test: reference 21.77 dB vs baseline 25.98 dB PSNR", "4.22 4 21.77 25.98",
     lambda: [-_rp_check(RP3)["delta_db"], _rp_check(RP3)["views"], _rp_check(RP3)["reference_psnr"], _rp_check(RP3)["baseline_psnr"]]),
    ("halving\nthe features cut matching per pair from 0.77 to 0.27 s and the whole SfM to 253 s", "0.77 0.27 253",
     lambda: [_sfm("sequential + loop pairs", "per_pair"), _sfm("sequential + loop pairs, 2048 features", "per_pair"),
              _sfm("sequential + loop pairs, 2048 features", "sfm")]),
    # the ground-plane fit on captures with true cameras, and StreetNeRF's colour transform of unseen cameras
    ("the floor 0.9 deg from the true up, +14.9% in metres per unit", "0.9 14.9",
     lambda: [_ground("castle-P30", "to_true_up_deg"), _ground("castle-P30", "scale_error_percent")]),
    ("(4.1 deg and +3.3% on the real-capture bench's drive", "4.1 3.3",
     lambda: [_ground("real-bench drive", "to_true_up_deg"), _ground("real-bench drive", "scale_error_percent")]),
    ("0.7 deg from the true up\non castle-P30 and 0.6 on the bench's drive, where the plane's normal is 0.9 and 4.1 off", "0.7 0.6 0.9 4.1",
     lambda: [_ground_up("castle-P30"), _ground_up("real-bench drive"), _ground("castle-P30", "to_true_up_deg"),
              _ground("real-bench drive", "to_true_up_deg")]),
    # the real-capture bench: the local eval mapping and the up from the cameras
    ("took the gain ratio to 0.66 / 0.78 and ground IoU from 0.738 to 0.789", "0.66 0.78 0.738 0.789",
     lambda: [_real("real_run6")["gain_ratio"]["bev_1"], _real("real_run6")["gain_ratio"]["bev_2"],
              _real("real_run5")["mask_iou"]["ground"], _real("real_run6")["mask_iou"]["ground"]]),
    ("the estimated StreetNeRF rose from 16.17 to 17.97 dB street and Splatfacto from 15.63 to\n16.72", "16.17 17.97 15.63 16.72",
     lambda: [_real_psnr("real_run4", "StreetNeRF"), _real_psnr("real_run5", "StreetNeRF"),
              _real_psnr("real_run4", "splatfacto"), _real_psnr("real_run5", "splatfacto")]),
    ("gives 0.59 / 0.63; over the two seeds the bird's-eye gain with everything estimated is 0.72 / 0.76 dB\nagainst 1.16 / 1.08 with "
     "ground truth, a ratio of 0.62 / 0.70", "0.59 0.63 0.72 0.76 1.16 1.08 0.62 0.70",
     lambda: [_real("real_run6_seed43")["gain_ratio"]["bev_1"], _real("real_run6_seed43")["gain_ratio"]["bev_2"]]
     + [_two_seed_gain(side, s, RUN6) for side in ("estimated",) for s in ("bev_1", "bev_2")]
     + [_two_seed_gain(side, s, RUN6) for side in ("ground_truth",) for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("estimated", s, RUN6) / _two_seed_gain("ground_truth", s, RUN6) for s in ("bev_1", "bev_2")]),
    ("the gain ratio only to 0.34 / 0.35", "0.34 0.35",
     lambda: [_real("real_run5")["gain_ratio"]["bev_1"], _real("real_run5")["gain_ratio"]["bev_2"]]),
    ("scores 16.01 / 16.74 dB (street / bev_1) with it against 18.05 / 17.19 without, and the gain ratio\nfalls to 0.41 / 0.65",
     "16.01 16.74 18.05 17.19 0.41 0.65",
     lambda: [_real_psnr("real_camopt", "StreetNeRF"), _real_psnr("real_camopt", "StreetNeRF", "bev_1"), _real_psnr("real_run6", "StreetNeRF"),
              _real_psnr("real_run6", "StreetNeRF", "bev_1"), _real("real_camopt")["gain_ratio"]["bev_1"], _real("real_camopt")["gain_ratio"]["bev_2"]]),
    ("masks (sky 0.827, ground 0.789, bit for bit): gain ratio 0.92 / 1.20 and 0.42 / 0.39", "0.827 0.789 0.92 1.20 0.42 0.39",
     lambda: [_real("real_reg1b")["mask_iou"]["sky"], _real("real_reg1b_seed43")["mask_iou"]["ground"]]
     + [_real(st)["gain_ratio"][s] for st in ("real_reg1b", "real_reg1b_seed43") for s in ("bev_1", "bev_2")]),
    ("gain with everything estimated is 0.79 / 0.82 dB against 1.20 / 1.06 with ground\ntruth, a ratio of 0.66 / 0.78",
     "0.79 0.82 1.20 1.06 0.66 0.78",
     lambda: [_two_seed_gain("estimated", s, ("real_reg1b", "real_reg1b_seed43")) for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("ground_truth", s, ("real_reg1b", "real_reg1b_seed43")) for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("estimated", s, ("real_reg1b", "real_reg1b_seed43")) / _two_seed_gain("ground_truth", s, ("real_reg1b", "real_reg1b_seed43")) for s in ("bev_1", "bev_2")]),
    ("0.61 / 0.95 and 0.67 / 0.93; over the two seeds the bird's-eye gain with everything estimated is\n0.76 / 0.89 dB "
     "against 1.19 / 0.95 with ground truth, a ratio of 0.64 / 0.94", "0.61 0.95 0.67 0.93 0.76 0.89 1.19 0.95 0.64 0.94",
     lambda: [_real(st)["gain_ratio"][s] for st in RUN7 for s in ("bev_1", "bev_2")]
     + [_two_seed_gain(side, s, RUN7) for side in ("estimated", "ground_truth") for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("estimated", s, RUN7) / _two_seed_gain("ground_truth", s, RUN7) for s in ("bev_1", "bev_2")]),
    ("StreetNeRF 18.09 / 17.20 / 16.52 dB\n(street / bev_1 / bev_2), Splatfacto 16.20 / 15.93 / 15.55, + NeRF views 15.77 / 16.69 / 16.49",
     "18.09 17.20 16.52 16.20 15.93 15.55 15.77 16.69 16.49",
     lambda: [_real_psnr("real_run7", lab, sp) for lab in ("StreetNeRF", "splatfacto", "splatfacto + NeRF views") for sp in ("street", "bev_1", "bev_2")]),
    ("estimated target at street level (0.43 dB) and not the true one (+0.18)", "0.43 0.18",
     lambda: [_real_psnr("real_run7", "splatfacto") - _real_psnr("real_run7", "splatfacto + NeRF views"),
              _real_psnr("real_run7", "splatfacto + NeRF views", side="ground_truth") - _real_psnr("real_run7", "splatfacto", side="ground_truth")]),
    ("gain ratio\n0.67 / 0.83 and 1.07 / 1.22; over the two seeds the bird's-eye gain with everything estimated is\n"
     "1.15 / 1.09 dB against 1.36 / 1.10 with ground truth, a ratio of 0.85 / 0.99", "0.67 0.83 1.07 1.22 1.15 1.09 1.36 1.10 0.85 0.99",
     lambda: [_real(st)["gain_ratio"][s] for st in RUN8 for s in ("bev_1", "bev_2")]
     + [_two_seed_gain(side, s, RUN8) for side in ("estimated", "ground_truth") for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("estimated", s, RUN8) / _two_seed_gain("ground_truth", s, RUN8) for s in ("bev_1", "bev_2")]),
    ("0.53 / 0.68 and 1.02 / 1.32,\ntwo-seed ratio 0.75 / 0.95; ground IoU 0.798 -> 0.7997", "0.53 0.68 1.02 1.32 0.75 0.95 0.798 0.7997",
     lambda: [_real(st)["gain_ratio"][s] for st in GE_OFF for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("estimated", s, GE_OFF) / _two_seed_gain("ground_truth", s, GE_OFF) for s in ("bev_1", "bev_2")]
     + [_real(GE_OFF[0])["mask_iou"]["ground"], _real("real_run8")["mask_iou"]["ground"]]),
    ("ATE\n0.32%, scale +4.13%, and a different 1000-step mask reference, sky 0.745 instead of 0.827", "0.32 4.13 0.745 0.827",
     lambda: [_real("real_run8")["ate_percent"], _real("real_run8")["scale_error_percent"], _real("real_run8")["mask_iou"]["sky"], _real("real_run7")["mask_iou"]["sky"]]),
    ("Splatfacto 16.22 / 15.83 / 15.56, + NeRF views 16.08 / 16.83 / 16.63: the NeRF views cost the estimated\n"
     "target 0.14 dB at street level, and give the true one +0.30 (18.62 vs 18.31)",
     "16.22 15.83 15.56 16.08 16.83 16.63 0.14 0.30 18.62 18.31",
     lambda: [_real_psnr("real_run8", lab, sp) for lab in ("splatfacto", "splatfacto + NeRF views") for sp in ("street", "bev_1", "bev_2")]
     + [_real_psnr("real_run8", "splatfacto") - _real_psnr("real_run8", "splatfacto + NeRF views"),
        _real_psnr("real_run8", "splatfacto + NeRF views", side="ground_truth") - _real_psnr("real_run8", "splatfacto", side="ground_truth"),
        _real_psnr("real_run8", "splatfacto + NeRF views", side="ground_truth"), _real_psnr("real_run8", "splatfacto", side="ground_truth")]),
    ("Everything estimated, seed 42: StreetNeRF 18.22 / 16.84 / 16.34 dB", "18.22 16.84 16.34",
     lambda: [_real_psnr("real_run8", "StreetNeRF", sp) for sp in ("street", "bev_1", "bev_2")]),
    ("| bench street, seed 0 (camera 3 m, 80 deg FOV, 6 cars; `real_depth_loss.json`) | 0.745 | 0.7997 | 0.798 (`real_ground_empty_off.json`) | 0.375 |",
     "0.745 0.7997 0.798 0.375",
     lambda: [_real("real_depth_loss")["mask_iou"]["sky"], _real("real_depth_loss")["mask_iou"]["ground"],
              _real(GE_OFF[0])["mask_iou"]["ground"], _real("real_depth_loss")["mask_iou"]["transient"]]),
    ("| bench street, the video at 800x448 (`real.json`) | 0.921 | 0.820 | | 0.247 |", "0.921 0.820 0.247",
     lambda: [_real("real")["mask_iou"][k] for k in ("sky", "ground", "transient")]),
    ("sky\nand ground rise on every street, sky by 0.06-0.18 and ground by 0.02-0.10", "0.06 0.18 0.02 0.10",
     lambda: [f(_video4_mask_rises(k)) for k in ("sky", "ground") for f in (min, max)]),
    ("transient\nrises on seeds 7 / 3 (+0.14 / +0.05) and falls on the bench street (-0.13)", "0.14 0.05 -0.13",
     lambda: _video4_mask_rises("transient")[1:] + _video4_mask_rises("transient")[:1]),
    *[(f"`auto_masks_seed{seed}.json`) | {sky} | {g} | {g_off} | {tr} |", f"{sky} {g} {g_off} {tr}",
       (lambda seed=seed: [_auto_masks(seed)["mask_iou"][k] for k in ("sky", "ground")] + [
           _auto_masks(seed)["without_ground_empty"]["mask_iou"]["ground"], _auto_masks(seed)["mask_iou"]["transient"]]))
      for seed, sky, g, g_off, tr in ((0, "0.677", "0.762", "0.751", "0.165"), (7, "0.649", "0.723", "0.596", "0.050"),
                                      ("7_video4", "0.705", "0.822", "0.792", "0.194"), ("3_video4", "0.722", "0.758", "0.747", "0.196"),
                                      (3, "0.549", "0.684", "0.605", "0.149"))],
    ("ground recall 0.79 -> 0.95 on seed 7, 0.81 ->\n0.91 on seed 3; precision 0.71 -> 0.75 / 0.73", "0.79 0.95 0.81 0.91 0.71 0.75 0.73",
     lambda: [_auto_masks(7)["without_ground_empty"]["stats"]["ground"]["recall"], _auto_masks(7)["stats"]["ground"]["recall"],
              _auto_masks(3)["without_ground_empty"]["stats"]["ground"]["recall"], _auto_masks(3)["stats"]["ground"]["recall"],
              _auto_masks(7)["without_ground_empty"]["stats"]["ground"]["precision"], _auto_masks(7)["stats"]["ground"]["precision"],
              _auto_masks(3)["stats"]["ground"]["precision"]]),
    ("The AMD runs before the rule (`real_run7.json`):\nsky 0.827, ground 0.789, transient 0.320", "0.827 0.789 0.320",
     lambda: [_real("real_run7")["mask_iou"][k] for k in ("sky", "ground", "transient")]),
    ("on the validation views it moves\nnothing, 22.52 -> 22.55 dB (embedded street, mean of val_street and val_bev) and 22.41 -> 22.40",
     "22.52 22.55 22.41 22.40",
     lambda: [_aug_app("street (embedded)", v) for v in (APP_MEAN, APP_NEAR)] + [_aug_app("street-seed7", v) for v in (APP_MEAN, APP_NEAR)]),
    ("others held out) 23.87 -> 22.25, against Splatfacto's 23.16", "23.87 22.25 23.16",
     lambda: [_aug_app(CASTLE_VAL, v) for v in (APP_MEAN, APP_NEAR, "splatfacto")]),
    ("confidence as well: 23.89); on the bench's test photos (reported, not chosen on) 24.47 -> 24.79 and, at\n"
     "seed 2, 22.13 -> 23.44 (Splatfacto 25.43 / 25.69)", "23.89 24.47 24.79 22.13 23.44 25.43 25.69",
     lambda: [_aug_app(CASTLE_VAL, "splatfacto + NeRF views, appearance nearest + consistency confidence")]
     + [_aug_app(CASTLE_TEST, v) for v in (APP_MEAN, APP_NEAR)] + [_aug_app(CASTLE_TEST + ", seed 2", v) for v in (APP_MEAN, APP_NEAR)]
     + [_aug_app(CASTLE_TEST, "splatfacto"), _aug_app(CASTLE_TEST + ", seed 2", "splatfacto")]),
    ("sequential matching (the default for an ordered set) registers 120 of\n120 in 90 s of SfM (features 48 s, 713 pairs matched in 9 s, mapping 33 s; 108 s for the whole `process`),\n"
     "ATE 0.045% of the trajectory, 0.13 deg, scale +2.8% from the 3 m camera height; exhaustive matching\n(7140 pairs) takes 263 s",
     "120 120 90 48 713 9 33 108 0.045 0.13 2.8 7140 263",
     lambda: [_sfm120("sequential", "registered"), _sfm120("sequential", "frames"), _sfm120("sequential", "sfm"),
              _sfm120("sequential", "features"), _sfm120("sequential", "matched_pairs"), _sfm120("sequential", "matching"),
              _sfm120("sequential", "mapping"), _sfm120("sequential", "wall_seconds"), _sfm120("sequential", "ate_percent"),
              _sfm120("sequential", "rotation_error_deg"), _sfm120("sequential", "scale_error_percent"),
              _sfm120("exhaustive", "matched_pairs"), _sfm120("exhaustive", "sfm")]),
    ("the embedded street 21.43 -> 21.58 dB and\n  the second street 20.98 -> 21.37 (mean of val_street and val_bev), castle-P30's validation photos\n"
     "  (its test photos removed, every 8th of the rest held out) 24.02 -> 25.36: the photo that one seed lost\n"
     "  to a veil (16.60 dB) scores 24.61; 0.2 gave 25.05 there.",
     "21.43 21.58 20.98 21.37 24.02 25.36 16.60 24.61 0.2 25.05",
     lambda: [_depth_two_seeds(sc, v) for sc in (STREET_E, STREET_7, CASTLE_VAL) for v in (NO_DEPTH, DEPTH_01)]
     + [_table_row("depth_loss", NO_DEPTH, CASTLE_VAL, exact=True)["psnr_per_view"]["test"][3],
        _table_row("depth_loss", DEPTH_01, CASTLE_VAL, exact=True)["psnr_per_view"]["test"][3], 0.2,
        _table_row("depth_loss", "splatfacto, depth loss 0.2", CASTLE_VAL, exact=True)["mean"]]),
    ("Reported, not chosen on: castle-P30's\n  test photos 25.43 -> 26.10 (Splatfacto alone), at seed 2 25.69 -> 25.54; + NeRF views 24.47 -> 25.12\n"
     "  and, at seed 2, 22.13 -> 24.91 (the veiled photo 15.17 -> 25.13)", "25.43 26.10 2 25.69 25.54 24.47 25.12 2 22.13 24.91 15.17 25.13",
     lambda: [_table_row("depth_loss", v, CASTLE_TEST, exact=True)["mean"] for v in (NO_DEPTH, DEPTH_01)] + [2]
     + [_table_row("depth_loss", v, CASTLE_TEST + ", seed 2", exact=True)["mean"] for v in (NO_DEPTH, DEPTH_01)]
     + [_table_row("depth_loss", f"splatfacto + NeRF views, {v}", CASTLE_TEST, exact=True)["mean"] for v in ("no depth loss", "depth loss 0.1 (default)")]
     + [2] + [_table_row("depth_loss", f"splatfacto + NeRF views, {v}", CASTLE_TEST + ", seed 2", exact=True)["mean"]
              for v in ("no depth loss", "depth loss 0.1 (default)")]
     + [_table_row("depth_loss", f"splatfacto + NeRF views, {v}", CASTLE_TEST + ", seed 2", exact=True)["psnr_per_view"]["test"][1]
        for v in ("no depth loss", "depth loss 0.1 (default)")]),
    ("registered 120 of 120 with each pass within 0.04% ATE but 12.66% for the whole, the\nsecond pass at 25x the first's scale: "
     "height 25.28x apart from the second pass's first frame, path\njump 18.77x at the join; matched exhaustively instead it registered "
     "120 of 120 again and was wrong\nagain (ATE 14.16%): height 1.37x (not caught), path jump 55.05x (caught); an earlier mapping once\n"
     "joined the forward pass as two halves 13% apart in scale (ATE 14.20%): height 1.14x (not caught),\npath jump 6.17x (caught).",
     "0.04 12.66 25 25.28 18.77 14.16 1.37 55.05 13 14.20 1.14 6.17",
     lambda: [max(_scale_check(DAB)["ate_percent"][k] for k in ("before split", "from split")), _scale_check(DAB)["ate_percent"]["whole"],
              _scale_check(DAB)["sim3_scale"]["before split"] / _scale_check(DAB)["sim3_scale"]["from split"], _scale_check(DAB)["ratio"],
              _scale_check(DAB)["path_jump"]["ratio"], _scale_check(DAB_EXH)["ate_percent"]["whole"], _scale_check(DAB_EXH)["ratio"],
              _scale_check(DAB_EXH)["path_jump"]["ratio"],
              100 * (_scale_check(FWD_EARLY)["sim3_scale"]["before split"] / _scale_check(FWD_EARLY)["sim3_scale"]["from split"] - 1),
              _scale_check(FWD_EARLY)["ate_percent"]["whole"], _scale_check(FWD_EARLY)["ratio"], _scale_check(FWD_EARLY)["path_jump"]["ratio"]]),
    ("sequential down-and-back drive keeps its first pass (60 of 120 frames, one cut): ATE 0.04%, scale +1.8%",
     "60 120 0.04 1.8", lambda: [_scale_check(DAB_KEPT)["frames"], _scale_check(DAB)["frames"], _scale_check(DAB_KEPT)["ate_percent"]["whole"],
                                 _scale_check(DAB_KEPT)["scale_error_percent"]]),
    ("stay within 1.10x in height and 1.40x in path\nsteps (castle-P30 5.73x against its 10x)", "1.10 1.40 5.73 10",
     lambda: [max(_scale_check(g)["ratio"] for g in GOOD_CAPTURES),  # the kept stretch of the down-and-back drive is a good capture too
              max(_scale_check(g)["path_jump"]["ratio"] for g in GOOD_CAPTURES if g != "castle-P30"),
              _scale_check("castle-P30")["path_jump"]["ratio"], _scale_check("castle-P30")["path_jump"]["max_ratio"]]),
    ("Splatfacto + NeRF views on the streets'\n  validation views (one seed): 22.52 -> 22.73 and 22.41 -> 22.52", "22.52 22.73 22.41 22.52",
     lambda: [_table_row("depth_loss", f"splatfacto + NeRF views, {v}", sc, exact=True)["mean"]
              for sc in (STREET_E, STREET_7) for v in ("no depth loss", "depth loss 0.1 (default)")]),
    ("A third seed (`real_depth_loss_seed44.md`): 0.05 / 0.11; over the three seeds the gain with everything estimated is\n"
     "0.40 / 0.38 dB against 1.08 / 0.86 with ground truth, a ratio of 0.37 / 0.45", "0.05 0.11 0.40 0.38 1.08 0.86 0.37 0.45",
     lambda: [_real("real_depth_loss_seed44")["gain_ratio"][s] for s in ("bev_1", "bev_2")]
     + [_two_seed_gain(side, s, SEEDS3) for side in ("estimated", "ground_truth") for s in ("bev_1", "bev_2")]
     + [_two_seed_gain("estimated", s, SEEDS3) / _two_seed_gain("ground_truth", s, SEEDS3) for s in ("bev_1", "bev_2")]),
    ("every variant on both renders registers 30/30 within ATE 0.10% and 0.23 deg\n(the second render 0.08% / 0.23 deg sequentially, "
     "0.08% / 0.16 deg exhaustively; the bench video exhaustively 0.10%)", "0.10 0.23 0.08 0.23 0.08 0.16 0.10",
     lambda: [max(r["ate_percent"] for r in _frag_rows("sfm_fragility_video4")), max(r["rotation_error_deg"] for r in _frag_rows("sfm_fragility_video4")),
              _frag("second render", "sequential (bench)", "ate_percent", "sfm_fragility_video4"),
              _frag("second render", "sequential (bench)", "rotation_error_deg", "sfm_fragility_video4"),
              _frag("second render", "exhaustive", "ate_percent", "sfm_fragility_video4"),
              _frag("second render", "exhaustive", "rotation_error_deg", "sfm_fragility_video4"),
              _frag("bench video", "exhaustive", "ate_percent", "sfm_fragility_video4")]),
    ("at 3 m up and 30 deg down\n(the bench's) the target scores 23.75 dB, at 3 m / 50 deg 23.77, at 6 m / 60 deg 23.30 and at 1.5 m / 45 deg 20.72\n"
     "(one photo at 11.52 dB: a veil across it); none comes back to Splatfacto's 24.67", "23.75 23.77 23.30 20.72 11.52 24.67",
     lambda: [_table_row("castle_bev_geometry_val", f"splatfacto + NeRF views, {v}")["mean"] for v in ("3 m up, 30", "3 m up, 50", "6 m", "1.5 m")]
     + [min(_table_row("castle_bev_geometry_val", "splatfacto + NeRF views, 1.5 m")["psnr_per_view"]["test"]),
        _table_row("castle_bev_geometry_val", "splatfacto (no NeRF views)")["mean"]]),
    ("length (700 / 1000 / 1500 / 3000 steps: 23.69 / 24.67 / 25.73 / 26.25 dB). But the gap stays at every length (+ NeRF\n"
     "views 23.75 / 24.04 / 25.45 dB at 1000 / 1500 / 3000 steps), with the input views given their 1000 steps (1430 in\n"
     "all: 24.23), and without the weight prune (both ~22k Gaussians: 24.71 against 25.27)",
     "700 1000 1500 3000 23.69 24.67 25.73 26.25 23.75 24.04 25.45 1000 1500 3000 1000 1430 24.23 22 24.71 25.27",
     lambda: [_table_row("castle_steps_capacity_val", f"splatfacto, {n} steps")["steps"] for n in (700, 1000, 1500, 3000)]
     + [_table_row("castle_steps_capacity_val", f"splatfacto, {n} steps")["mean"] for n in (700, 1000, 1500, 3000)]
     + [_table_row("castle_steps_capacity_val", f"splatfacto + NeRF views, {n} steps")["mean"] for n in (1000, 1500, 3000)]
     + [_table_row("castle_steps_capacity_val", f"splatfacto + NeRF views, {n} steps")["steps"] for n in (1000, 1500, 3000)]
     + [1000, _table_row("castle_steps_capacity_val", "splatfacto + NeRF views, 1430 steps")["steps"],
        _table_row("castle_steps_capacity_val", "splatfacto + NeRF views, 1430 steps (")["mean"],
        min(_table_row("castle_steps_capacity_val", v)["primitives"] for v in ("splatfacto, 1000 steps, no", "splatfacto + NeRF views, 1000 steps, no")) / 1000,
        _table_row("castle_steps_capacity_val", "splatfacto + NeRF views, 1000 steps, no")["mean"],
        _table_row("castle_steps_capacity_val", "splatfacto, 1000 steps, no")["mean"]]),
    ("the same drive at 800x448: 0.06% and 0.08%", "0.06 0.08",
     lambda: [_frag(d, "sequential (bench)", "ate_percent", "sfm_fragility_video4") for d in ("bench video", "second render")]),
    ("the sky\nIoU fell to 0.765 and ground to 0.780", "0.765 0.780",
     lambda: [_real("real_reg1")["mask_iou"]["sky"], _real("real_reg1")["mask_iou"]["ground"]]),
    ("a held-out training camera misses its estimated pose by 0.26 deg", "0.26", lambda: [_real("real_run7")["eval_mapping_rotation_deg"]]),
    ("NeRF views cost the\nestimated target 0.32 dB at street level (16.29 vs 16.60", "0.32 16.29 16.60",
     lambda: [_real_psnr("real_run6", "splatfacto") - _real_psnr("real_run6", "splatfacto + NeRF views"),
              _real_psnr("real_run6", "splatfacto + NeRF views"), _real_psnr("real_run6", "splatfacto")]),
    ("run scores 23.07 dB on the held-out photos instead of 21.25, and 23.35 dB on their right halves", "23.07 21.25 23.35",
     lambda: [_appearance(CASTLE_SN, "nearest"), _appearance(CASTLE_SN, "mean"), _appearance(CASTLE_SN, "nearest", "psnr_right")]),
    ("left half (NeRF-W's protocol, which looks at the photo) gives 23.30", "23.30",
     lambda: [_appearance(CASTLE_SN, "fit on left half", "psnr_right")]),
    ("the second held-out photo renders nearly black (8.9 dB) behind 12 Gaussians that sit within 0.02 world\nunits (~0.5 m) in front "
     "of its camera, 3.7 m from the nearest training camera; muted, the photo scores\n25.76 dB", "8.9 12 0.02 0.5 3.7 25.76",
     lambda: [_floaters()["psnr"], _floaters()["rows"][0]["gaussians"], _floaters()["rows"][0]["within_world"],
              _floaters()["rows"][0]["within_m"], _floaters()["camera_to_nearest_training_camera_m"], _floaters()["rows"][0]["psnr_muted"]]),
    ("their blending weight in those views is\n0-18, in the real training photos 15-383", "0 18 15 383",
     lambda: [min(_floaters()["rows"][0]["weight_bev"]), max(_floaters()["rows"][0]["weight_bev"]),
              min(_floaters()["rows"][0]["weight_real"]), max(_floaters()["rows"][0]["weight_real"])]),
    ("the 3.6 dB left to that run's Splatfacto (26.66 dB)", "3.6 26.66", lambda: [26.66 - _appearance(CASTLE_SN, "nearest"), 26.66]),
    ("StreetNeRF at 3000 steps (5x,\n512 s, on the code before the up change) scores 21.07 dB (23.28 with the nearest camera's colour\n"
     "transform), SSIM 0.756 and LPIPS 0.193 against 0.671 / 0.372", "3000 512 21.07 23.28 0.756 0.193 0.671 0.372",
     lambda: [3000, _c3000("train_seconds"), _c3000("mean"), _c3000("nearest"), _c3000("ssim"), _c3000("lpips"),
              _psnr(_r(RP3), "StreetNeRF", "test", "ssim"), _psnr(_r(RP3), "StreetNeRF", "test", "lpips")]),
    ("nearest transform costs 0.22 dB (25.70 -> 25.48 street)", "0.22 25.70 25.48",
     lambda: [_appearance(STREET_SN, "mean") - _appearance(STREET_SN, "nearest"), _appearance(STREET_SN, "mean"),
              _appearance(STREET_SN, "nearest")]),
    ("colour transforms to the identity, on the validation views of both streets (25.46 -> 25.49 and\n  25.17 -> 25.34 dB",
     "25.46 25.49 25.17 25.34", lambda: [_app_reg("street (embedded)", "affine, reg 1e-3"), _app_reg("street (embedded)", "affine, reg 1.0"),
                                        _app_reg("street-seed7", "affine, reg 1e-3"), _app_reg("street-seed7", "affine, reg 1.0")]),
    ("castle-P30's held-out photos 21.77 -> 22.61 dB at 600 steps", "21.77 22.61 600",
     lambda: [_app_reg("castle", "affine, reg 1e-3"), _app_reg("castle", "affine, reg 1.0", 600), 600]),
    ("exposure stress 21.36 -> 21.52 / 19.71 -> 19.97 dB", "21.36 21.52 19.71 19.97",
     lambda: [_app_reg("street, exposure +-1", "affine, reg 1e-3"), _app_reg("street, exposure +-1", "affine, reg 1.0"),
              _app_reg("street, exposure +-2", "affine, reg 1e-3"), _app_reg("street, exposure +-2", "affine, reg 1.0")]),
    ("Without any appearance model: 25.31 / 25.41\n  on the streets' validation views, 22.84 on castle-P30", "25.31 25.41 22.84",
     lambda: [_app_reg("street (embedded)", "no appearance"), _app_reg("street-seed7", "no appearance"), _app_reg("castle", "no appearance", 600)]),
    ("validation views of two streets (quick Splatfacto, off vs on): 21.56 -> 21.34 and\n  20.92 -> 21.07 dB",
     "21.56 21.34 20.92 21.07", lambda: [_clear("street (", "splatfacto, no clearance"), _clear("street (", "splatfacto, 1 m clearance (default)"),
                                        _clear("street-seed7", "splatfacto, no clearance"), _clear("street-seed7", "splatfacto, 1 m clearance (default)")]),
    ("Splatfacto 25.98 -> 26.19 dB, + NeRF views 20.53 -> 22.88 (that photo 8.61 -> 17.23) and, at seed 2,\n  21.73 -> 24.86 (13.24 -> 24.95)",
     "25.98 26.19 20.53 22.88 8.61 17.23 21.73 24.86 13.24 24.95",
     lambda: [_clear("castle", "splatfacto, no clearance (the bench's run)"), _clear("castle", "splatfacto, 1 m clearance"),
              _clear("castle", "splatfacto + NeRF views, no clearance (the bench's run)"), _clear("castle", "splatfacto + NeRF views, 1 m clearance"),
              _clear("castle", "splatfacto + NeRF views, no clearance (the bench's run)", 1), _clear("castle", "splatfacto + NeRF views, 1 m clearance", 1),
              _clear("castle", "splatfacto + NeRF views, no clearance, seed 2"), _clear("castle", "splatfacto + NeRF views, 1 m clearance, seed 2"),
              _clear("castle", "splatfacto + NeRF views, no clearance, seed 2", 1), _clear("castle", "splatfacto + NeRF views, 1 m clearance, seed 2", 1)]),
    ("at +-2 stops (street 3.37 dB below\nits seeds, against 4.16 for Splatfacto alone in `stability_fixed_cap.md`; +-1 stop costs 1.74 / 0.75 dB street / BEV)",
     "2 3.37 4.16 1 1.74 0.75",
     lambda: [2, _stab_view(AUG_TARGET, "exposure +-2 stop", "stability_augmented_views_exposure/stability", "street"), _stab_view("splatfacto", "exposure +-2 stop", "stability_fixed_cap", "street"), 1,
              _stab_view(AUG_TARGET, "exposure +-1 stop", "stability_augmented_views_exposure/stability", "street"), _stab_view(AUG_TARGET, "exposure +-1 stop", "stability_augmented_views_exposure/stability", "bev")]),
    ("fewer views do not break it down to 12% (0.37 / 1.10 dB below: from above it pays more than Splatfacto alone,\n0.58", "12 0.37 1.10 0.58",
     lambda: [12, _stab_view(AUG_TARGET, "views kept 12%", "stability_augmented_views_exposure/stability", "street"), _stab_view(AUG_TARGET, "views kept 12%", "stability_augmented_views_exposure/stability", "bev"),
              _stab_view("splatfacto", "views kept 12%", "stability_fixed_cap", "bev")]),
    ("cost the target 1.34 dB at\nstreet level and nothing from above (0.05 dB above its seeds); without masks at all it ends 0.40 dB below\n"
     "at street level and 0.06 above from above, where Splatfacto alone loses 0.35 dB", "1.34 0.05 0.40 0.06 0.35",
     lambda: [_stab_view(AUG_TARGET, "mask dilation 12px", "stability_augmented_masks/stability", "street"), -_stab_view(AUG_TARGET, "mask dilation 12px", "stability_augmented_masks/stability", "bev"),
              _stab_view(AUG_TARGET, "no masks", "stability_augmented_masks/stability", "street"), -_stab_view(AUG_TARGET, "no masks", "stability_augmented_masks/stability", "bev"),
              _stab_view("splatfacto", "no masks", "stability_masks/stability", "bev")]),
    ("the fixed caps the models hold 2-42% fewer primitives (Splatfacto 3,793 Gaussians against 6,512) for -0.10 to\n"
     "+0.36 dB from above and -0.35 to +0.12 dB at street level", "2 42 3,793 6,512 -0.10 0.36 -0.35 0.12",
     lambda: [*(100 * x for x in _min_max(1 - _r(Q)[k]["size"]["primitives"] / _r("paper_table_fixed_cap.json")[k]["size"]["primitives"]
                                          for k in _r(Q) if k != "StreetNeRF")),
              _r(Q)["splatfacto"]["size"]["primitives"], _r("paper_table_fixed_cap.json")["splatfacto"]["size"]["primitives"],
              *_min_max(_psnr(_r(Q), k, sp) - _psnr(_r("paper_table_fixed_cap.json"), k, sp) for k in _r(Q) if k != "StreetNeRF" for sp in BEV),
              *_min_max(_psnr(_r(Q), k, "street") - _psnr(_r("paper_table_fixed_cap.json"), k, "street") for k in _r(Q) if k != "StreetNeRF")]),
    ("4,448\nanchors where the fixed 20k cap let 8,762 grow, for -0.27 / -0.09 / -0.22 dB street / bev_1 / bev_2 alone",
     "4,448 20 8,762 -0.27 -0.09 -0.22",
     lambda: [_r(D)["scaffold-gs"]["size"]["primitives"], 20, _r("default/paper_table_fixed_cap.json")["scaffold-gs"]["size"]["primitives"]]
     + [_psnr(_r(D), "scaffold-gs", sp) - _psnr(_r("default/paper_table_fixed_cap.json"), "scaffold-gs", sp) for sp in ("street",) + BEV]),
    ("views term: 6,712 anchors against 8,679 with the fixed cap, for -0.17 / -0.02 / -0.09 dB, and +0.44 / +0.26 / +0.07\n"
     "against the growth term alone (4,451 anchors", "6,712 8,679 -0.17 -0.02 -0.09 0.44 0.26 0.07 4,451",
     lambda: [_r(D)[AUG_SC]["size"]["primitives"], _r("default/paper_table_fixed_cap.json")[AUG_SC]["size"]["primitives"]]
     + [_psnr(_r(D), AUG_SC, sp) - _psnr(_r(other), AUG_SC, sp) for other in ("default/paper_table_fixed_cap.json", "default/paper_table_scaffold_growth_only.json")
        for sp in ("street",) + BEV] + [_r("default/paper_table_scaffold_growth_only.json")[AUG_SC]["size"]["primitives"]]),
    ("matches 188 pairs where exhaustive matches 435", "188 435",
     lambda: [_sfm("sequential + loop pairs", "pairs"), _sfm("exhaustive", "pairs")]),
]


@pytest.mark.parametrize("text,printed,values", PROSE, ids=[p[0].splitlines()[0][:40] for p in PROSE])
def test_prose_figure_matches_results(text, printed, values):
    assert text in README, f"README no longer says: {text!r} (update this test with the sentence)"
    got = values()
    printed = printed.split()
    assert len(printed) == len(got)
    for cell, value in zip(printed, got):
        assert cell.lstrip("-") in text and _matches(cell, value), f"{text!r}: prints {cell}, results say {value:.4f}"


def test_prose_within_bound():
    """"within 0.5 dB of the NeRF at the default scale for Splatfacto (Scaffold-GS above it; 2DGS ... below)"."""
    flat = " ".join(README.split())
    assert "within 0.5 dB of the NeRF at the default scale for Splatfacto (Scaffold-GS above it; 2DGS" in flat
    assert max(_below_nerf(_r(D), ("splatfacto",))) <= 0.5 and max(_below_nerf(_r(D), ("scaffold-gs",))) < 0
    below = _below_nerf(_r(D), ("2dgs",))
    assert f"2DGS {below[0]:.2f} / {below[1]:.2f} dB below on bev_1 / bev_2" in flat, below
    conf = [_psnr(_r(D), "StreetNeRF", s) - _psnr(_r(D), "2dgs + NeRF views (consistency confidence)", s) for s in BEV]
    assert f"within {max(conf):.2f} dB with consistency confidence" in flat, conf


def test_dist_models_equal_to_the_bit():
    """"The 2-rank model equalled the one-process model to the bit after 100 steps"."""
    assert "equalled the one-process model to the bit after 100 steps" in README
    assert _dist(2, "max_param_diff") == 0 and _dist(2, "steps") == 100


def test_second_street_road_from_above():
    """"On the road from above 2DGS + NeRF views is now above its reference (...) and Splatfacto and Scaffold-GS below it"."""
    flat = " ".join(README.split())
    assert "On the road from above 2DGS + NeRF views is now above its reference" in flat
    assert "and Splatfacto and Scaffold-GS below it" in flat
    refs = [_second("StreetNeRF", s, "psnr_ground") for s in BEV]
    ours = [_second("2dgs + NeRF views", s, "psnr_ground") for s in BEV]
    assert f"({ours[0]:.2f} / {ours[1]:.2f} dB bev_1 / bev_2 against {refs[0]:.2f} / {refs[1]:.2f})" in flat
    for split in BEV:
        ref = _second("StreetNeRF", split, "psnr_ground")
        assert _second("2dgs + NeRF views", split, "psnr_ground") > ref
        assert all(_second(f"{t} + NeRF views", split, "psnr_ground") < ref for t in ("splatfacto", "scaffold-gs"))


def test_conditioned_enhancer_claims():
    """"moves val_bev by -0.01 dB on both" and "within 0.2 dB of those trained through the unconditioned enhancer on val_bev"."""
    assert "within 0.2 dB of those trained through the unconditioned enhancer on val_bev" in README
    assert round(_enh_cond("street-seed7", "warped", "val_bev"), 2) == -0.01
    assert _enh_targets_gap() <= 0.2


def test_model_size_target_claims():
    """"issue 20's target (at most 1.5x) is missed" (Splatfacto) and "2DGS's default is itself the smallest inside the band"."""
    assert "issue 20's target (at most 1.5x) is missed" in README and "2DGS's default is itself the smallest inside the band" in README
    assert _size_pick("splatfacto")["target_met"] is False and _size_pick("splatfacto")["chosen_on"] == "validation views"
    assert _size_pick("2dgs")["smallest"] == _size_pick("2dgs")["default"]["label"] and _size_pick("2dgs")["target_met"] is True


def test_model_size_second_street_and_augmented_claims():
    """Second street: "Splatfacto misses again (5,138 Gaussians, 1.64x ...: the 0.0016 threshold's 3,129), and 2DGS
    misses too (5,834 surfels, 1.80x the 8,000 budget's 3,243, which is 0.45 dB below the best"; with NeRF views "both
    defaults are the smallest configuration inside the band (Splatfacto 7,168, 2DGS 8,644)"; "a harder prune (0.2: 0.65 / 0.68 dB"."""
    assert ("Splatfacto misses again (5,138 Gaussians, 1.64x the smallest in the\nband: the 0.0016 threshold's 3,129), and 2DGS "
            "misses too (5,834 surfels, 1.80x the 8,000 budget's\n3,243, which is 0.45 dB below the best") in README
    second = json.loads((RESULTS / "second_scene" / "model_size.json").read_text())["picks"]
    sf, tw = second["splatfacto"], second["2dgs"]
    assert not sf["target_met"] and sf["default"]["primitives"] == 5138 and sf["smallest_primitives"] == 3129
    assert round(sf["default_over_smallest"], 2) == 1.64 and not tw["target_met"] and tw["default"]["primitives"] == 5834
    assert tw["smallest_primitives"] == 3243 and round(tw["default_over_smallest"], 2) == 1.80
    assert round(tw["best_quality"] - tw["smallest_quality"], 2) == 0.45
    assert "never a harder prune (0.2: 0.65 / 0.68 dB below the best)" in README
    rows = {r["label"]: r for r in _r("model_size_fixed_cap.json", "rows")}
    for m, printed in (("splatfacto", 0.65), ("2dgs", 0.68)):
        assert round(_size_pick(m)["best_quality"] - rows[f"{m} prune_weight_fraction=0.2"]["val_quality"], 2) == printed
    assert "(Splatfacto 7,168, 2DGS 8,644)" in README
    aug = json.loads((RESULTS / "model_size_augmented" / "model_size.json").read_text())["picks"]
    assert [aug[m]["default"]["primitives"] for m in ("splatfacto", "2dgs")] == [7168, 8644]
    assert all(aug[m]["target_met"] and aug[m]["smallest"] == aug[m]["default"]["label"] for m in ("splatfacto", "2dgs"))


def test_views_budget_summary_is_the_committed_sweeps():
    """views_budget/summary.{json,md} are what benchmarks/size_summary.py makes of the committed sweeps."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("size_summary", RESULTS.parent / "size_summary.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = mod.summary()
    saved = json.loads((RESULTS / "views_budget" / "summary.json").read_text())
    assert saved["rows"] == rows and saved["met"] == sum(r["target_met"] for r in rows) and saved["of"] == len(rows) == 15
    assert mod.markdown(rows) in (RESULTS / "views_budget" / "summary.md").read_text()


SB = "scene_budget/"


def _castle_scene(variant: str, seed2: bool = False) -> dict:
    scene = "castle-P30, validation photos" + (", seed 2" if seed2 else "")
    return next(r for r in _r(SB + "castle_val.json", "rows") if r["scene"] == scene and r["variant"].startswith(variant))


def _size_summary(name: str):
    """benchmarks/size_summary.py as a module, the rows it makes of the committed sweeps of set ``name`` and the
    committed summary.json, checked equal (15 cases; today's set 18, with NeRF views at the default scale too) and its
    Markdown in summary.md."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("size_summary", RESULTS.parent / "size_summary.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = mod.summary(name)
    saved = json.loads((RESULTS / name / "summary.json").read_text())
    cases = 18 if name == "prune_margin" else 15
    assert saved["rows"] == rows and saved["met"] == sum(r["target_met"] for r in rows) and saved["of"] == len(rows) == cases
    assert mod.markdown(rows, with_file=True) in (RESULTS / name / "summary.md").read_text()
    return mod, rows, saved


def test_scene_budget_claims():
    """The budget read from the scene: the defaults in code are the README's, its castle-P30 figures are
    scene_budget/castle_val.json's, its count of met targets is scene_budget/summary.json's (which is what
    benchmarks/size_summary.py makes of the committed sweeps)."""
    from nerf2gs_plugin.methods.scaffold_gs.model import ScaffoldGSModelConfig
    from nerf2gs_plugin.methods.splatfacto.model import SplatfactoModelConfig
    from nerf2gs_plugin.methods.two_dgs.model import TwoDGSModelConfig

    sf, tg = SplatfactoModelConfig().strategy, TwoDGSModelConfig().strategy
    assert (sf.pixel_steps_per_gaussian, tg.pixel_steps_per_gaussian, sf.gaussians_per_sparse_point, tg.gaussians_per_sparse_point) == (54000, 36000, 2.0, 2.0)
    assert (ScaffoldGSModelConfig().anchor_growth, ScaffoldGSModelConfig().pixel_steps_per_anchor) == (1.25, 540000)
    assert "and 2 Gaussians per SfM point, at most 60k" in README and "anchors grow to at most the larger of 1.25x its initial ones" in README
    assert "views term with 540,000 pixel-steps per anchor" in " ".join(README.split())
    figures = [("splatfacto, scene, 1.5", False), ("splatfacto, scene, 2", False), ("splatfacto, scene, 3", False),
               ("splatfacto, fixed", False), ("splatfacto, views", False)]
    text = ("1.5 per point {} dB ({} Gaussians), 2 per point {} ({}), 3 per point {}\n({}), against {} with the fixed 60k ({}) "
            "and {} with the views term alone ({})").format(*[x for v, s in figures for x in (f"{_castle_scene(v, s)['mean']:.2f}", f"{_castle_scene(v, s)['primitives']:,}")])
    assert text in README, text
    s2 = f"2 per point {_castle_scene('splatfacto, scene, 2', True)['mean']:.2f} against {_castle_scene('splatfacto, fixed', True)['mean']:.2f} for the fixed budget"
    assert s2 in README, s2
    d2, df = _castle_scene("2dgs, scene"), _castle_scene("2dgs, fixed")
    assert f"2DGS there: {d2['mean']:.2f} dB with {d2['primitives']:,} surfels against {df['mean']:.2f} with {df['primitives']:,}" in README
    mod, rows, saved = _size_summary("scene_budget")
    assert f"is met in {saved['met']} of {saved['of']} cases" in README


def _three_seeds(stems: list[str]) -> list[dict]:
    """The real bench's runs at seeds 42 (the default) / 43 / 44: one capture and one set of masks."""
    runs = [_real(st) for st in stems]
    assert [r["options"]["seed"] for r in runs] == [None, 43, 44]
    assert all(r["mask_iou"] == runs[0]["mask_iou"] and r["ate_percent"] == runs[0]["ate_percent"] for r in runs)
    return runs


def test_real_bench_with_todays_size_defaults():
    """The real bench's three seeds with the budget read from the scene: the README's figures are
    real_scene_budget{,_seed43,_seed44}.json's."""
    stems = [f"real_scene_budget{x}" for x in ("", "_seed43", "_seed44")]
    runs = _three_seeds(stems)
    d = runs[0]
    est, gt = d["results"]["estimated"], d["results"]["ground_truth"]
    psnrs = lambda r: " / ".join(f"{r['results'][s]['psnr']:.2f}" for s in ("street", "bev_1", "bev_2"))
    ratios = ", ".join(f"{r['gain_ratio']['bev_1']:.2f} / {r['gain_ratio']['bev_2']:.2f}" for r in runs[1:])
    text = (f"{d['registered_fraction'] * 30:.0f}/30 registered ({d['process']['points']} SfM points), ATE {d['ate_percent']:.2f}%, "
            f"scale {d['scale_error_percent']:+.2f}%, sky IoU {d['mask_iou']['sky']:.3f},\nground {d['mask_iou']['ground']:.3f}; "
            f"gain ratio {d['gain_ratio']['bev_1']:.2f} / {d['gain_ratio']['bev_2']:.2f} (bev_1 / bev_2), {ratios.replace(', ', ' and ')} at seeds 42 / 43 / 44")
    assert text in README, text
    gain = lambda st, side, s: _real_psnr(st, "splatfacto + NeRF views", s, side) - _real_psnr(st, "splatfacto", s, side)
    mean = lambda side, s: sum(gain(st, side, s) for st in stems) / 3
    flat = " ".join(README.split())
    three = (f"over the three seeds the bird's-eye gain with everything estimated is {mean('estimated', 'bev_1'):.2f} / {mean('estimated', 'bev_2'):.2f} dB "
             f"against {mean('ground_truth', 'bev_1'):.2f} / {mean('ground_truth', 'bev_2'):.2f} with ground truth, a ratio of "
             f"{mean('estimated', 'bev_1') / mean('ground_truth', 'bev_1'):.2f} / {mean('estimated', 'bev_2') / mean('ground_truth', 'bev_2'):.2f}")
    assert three in flat, three
    sizes = (f"Splatfacto ends with {est['splatfacto']['size']['primitives']:,}\nGaussians on the estimated capture and "
             f"{gt['splatfacto']['size']['primitives']:,} on the true one (+ NeRF views {est['splatfacto + NeRF views']['size']['primitives']:,} / "
             f"{gt['splatfacto + NeRF views']['size']['primitives']:,})")
    assert sizes in README, sizes
    for label, r in (("StreetNeRF", est["StreetNeRF"]), ("Splatfacto", est["splatfacto"]), ("+ NeRF views", est["splatfacto + NeRF views"])):
        assert f"{label} {psnrs(r)}" in flat, (label, psnrs(r))
    assert f"with ground truth: Splatfacto {psnrs(gt['splatfacto'])}, + NeRF views {psnrs(gt['splatfacto + NeRF views'])}" in flat
    above = lambda side: ", ".join(" / ".join(f"{_real_psnr(st, 'StreetNeRF', s, side) - _real_psnr(st, 'splatfacto', s, side):.2f}"
                                              for s in ("bev_1", "bev_2")) for st in stems)
    for side in ("estimated", "ground_truth"):
        parts = above(side).split(", ")
        assert f"{parts[0]}, {parts[1]} and {parts[2]}" in flat, (side, parts)
    drop = [_real_psnr(st, "StreetNeRF", "bev_1", "ground_truth") - _real_psnr(st, "StreetNeRF", "bev_1", "estimated") for st in stems]
    assert f"The estimated StreetNeRF is {min(drop):.1f}-{max(drop):.1f} dB below the true one from above" in flat, drop
    # "the 1,500 Gaussians of the estimated Splatfacto ... score within 0.5 dB of it" (from above, every seed)
    assert "score within 0.5 dB of it" in flat
    assert all(abs(float(x)) <= 0.5 for x in above("estimated").replace(",", " /").split(" / "))
    assert all(1400 <= r["results"]["estimated"]["splatfacto"]["size"]["primitives"] <= 1600 for r in runs)


def test_prune_margin_claims():
    """2DGS's weight prune read from the fit: the default in code is the README's, the summary's rows are what
    benchmarks/size_summary.py makes of the committed sweeps, each relabelled sweep's picks are the bench's own
    picks of its rows, and the README's count of met targets and its figures are theirs."""
    from nerf2gs_plugin.eval.bench_size import smallest_within
    from nerf2gs_plugin.methods.splatfacto.model import SplatfactoModelConfig
    from nerf2gs_plugin.methods.two_dgs.model import TwoDGSModelConfig

    assert (TwoDGSModelConfig().strategy.prune_margin_db, SplatfactoModelConfig().strategy.prune_margin_db) == (2.0, 0.0)
    assert "2DGS `strategy.prune-margin-db 2`" in README
    mod, rows, saved = _size_summary("prune_margin")
    assert f"in {saved['met']} of {saved['of']} with Scaffold-GS's views term as well" in " ".join(README.split())
    assert mod.markdown(rows) in README  # the README's table is the summary's
    for street in ("street_default", "second_street_default"):
        sweep = json.loads((RESULTS / "prune_margin" / street / "model_size.json").read_text())
        assert sweep["picks"] == json.loads(json.dumps(smallest_within(sweep["rows"])))
        by = {r["label"]: r for r in sweep["rows"]}
        for label in ("2dgs default", "2dgs prune_margin_db=0", "2dgs prune_margin_db=3", "2dgs prune_weight_fraction=0"):
            r = by[label]
            assert f"{r['val_quality']:.2f} ({r['primitives']:,})" in README, (street, label)
    flat = " ".join(README.split())
    row = {(r["sweep"], r["method"]): r for r in rows}
    d1, d2 = row["embedded street, default", "2dgs"], row["second street, default", "2dgs"]
    assert (f"keeps {d1['primitives']:,} / {d2['primitives']:,} surfels there, {d1['below_best_db']:.2f} / {d2['below_best_db']:.2f} dB "
            f"below today's best and {d1['default_over_smallest']:.2f}x / {d2['default_over_smallest']:.2f}x today's smallest model in the band "
            f"(the fixed 10%), {d1['earlier_over_smallest']:.2f}x / {d2['earlier_over_smallest']:.2f}x the earlier sweeps'") in flat
    quick = []
    for street in ("street_quick", "second_street_quick", "street_nerf_views_quick"):
        by = {r["label"]: r for r in json.loads((RESULTS / "prune_margin" / street / "model_size.json").read_text())["rows"]}
        assert by["2dgs default"]["primitives"] == by["2dgs prune_margin_db=0"]["primitives"]  # the whole 10% passed
        quick.append(f"{by['2dgs default']['primitives']:,}")
    assert f"as `prune-margin-db 0` ({' / '.join(quick)})" in flat
    fixed = [json.loads((RESULTS / "prune_margin" / st / "model_size.json").read_text()) for st in ("street_default", "second_street_default")]
    below = [f["picks"]["2dgs"]["best_quality"] - {r["label"]: r for r in f["rows"]}["2dgs prune_margin_db=0"]["val_quality"] for f in fixed]
    assert f"0.43 / 0.43 dB in today's" in flat and [round(b, 2) for b in below] == [0.43, 0.43]


def test_second_street_table_today():
    """The second street's default-scale table is second_scene/paper_table.json's (its 2DGS and StreetNeRF rows the
    runs of twodgs_today/), and the README's comparison with the fixed caps' table is theirs."""
    r = json.loads((RESULTS / "second_scene" / "paper_table.json").read_text())["results"]
    today = json.loads((RESULTS / "second_scene" / "twodgs_today" / "paper_table.json").read_text())["results"]
    old = json.loads((RESULTS / "second_scene" / "paper_table_fixed_cap.json").read_text())["results"]
    for lab in ("StreetNeRF", "2dgs", "2dgs + NeRF views"):
        assert r[lab]["results"] == today[lab]["results"], lab
    p = lambda rows, lab, s: rows[lab]["results"][s]["psnr"]
    names = {"StreetNeRF": "StreetNeRF", "splatfacto": "Splatfacto", "scaffold-gs": "Scaffold-GS", "2dgs": "2DGS"}
    for lab, row in r.items():
        base, _, aug = lab.partition(" + ")
        name = names[base] + (" + " + aug if aug else "")
        prims = "(hash grid)" if base == "StreetNeRF" else f"{row['size']['primitives']:,}"
        cells = [f"{p(r, lab, s):.2f}" for s in ("street", "bev_1", "bev_2")] + [f"{row['results']['bev_1']['lpips']:.3f}",
                                                                                 f"{row['results']['bev_1']['psnr_ground']:.2f}", prims]
        assert f"| {name} | " + " | ".join(cells) + " |" in README, name
    d = lambda lab, s: p(r, lab, s) - p(old, lab, s)
    flat = " ".join(README.split())
    alone = [d(t, "bev_1") for t in TARGETS3]
    assert f"every target alone gains from above (+{min(alone):.2f} to +{max(alone):.2f} dB bev_1)" in flat
    assert (f"Splatfacto + NeRF views {d('splatfacto + NeRF views', 'bev_1'):+.2f} / {d('splatfacto + NeRF views', 'bev_2'):+.2f} dB bev_1 / bev_2, "
            f"Scaffold-GS + NeRF views {d('scaffold-gs + NeRF views', 'bev_1'):+.2f} / {d('scaffold-gs + NeRF views', 'bev_2'):+.2f} from above and "
            f"{-d('scaffold-gs + NeRF views', 'street'):.2f} dB less at street level, 2DGS + NeRF views {d('2dgs + NeRF views', 'bev_1'):+.2f} / "
            f"{d('2dgs + NeRF views', 'bev_2'):+.2f} from above") in flat
    assert (f"{r['2dgs + NeRF views']['size']['primitives']:,} against {old['2dgs + NeRF views']['size']['primitives']:,}" in flat
            and f"{r['scaffold-gs + NeRF views']['size']['primitives']:,} against {old['scaffold-gs + NeRF views']['size']['primitives']:,}" in flat)


def test_default_table_2dgs_rows_against_the_fixed_prune():
    """The default-scale table's 2DGS rows (prune read from the fit) against the table before them."""
    new, old = _r(D), _r("default/paper_table_2dgs_fixed_prune.json")
    diffs = lambda lab: " / ".join(f"{_psnr(new, lab, s) - _psnr(old, lab, s):+.2f}" for s in ("street",) + BEV)
    text = (f"{new['2dgs']['size']['primitives']:,} surfels where the fixed 10% kept {old['2dgs']['size']['primitives']:,}, "
            f"{diffs('2dgs')} dB alone and {diffs('2dgs + NeRF views')} with NeRF views")
    assert text in " ".join(README.split()), text


def test_model_size_verdict():
    """benchmarks/results/model_size.json (issue 20's committed keys) is what size_summary.py makes of today's set:
    per method and scene `default` and `smallest_within_0_5dB` (primitives, mean PSNR) and `default_over_smallest`,
    each the sweep's own pick; the target held wherever it says met."""
    mod, rows, saved = _size_summary("prune_margin")
    assert mod.CURRENT == "prune_margin"
    top = json.loads((RESULTS / "model_size.json").read_text())
    assert (top["met"], top["of"]) == (saved["met"], saved["of"])
    assert sum(len(scenes) for scenes in top["methods"].values()) == len(rows)
    for r in rows:
        e = top["methods"][r["method"]][r["sweep"]]
        sweep = json.loads((RESULTS / "prune_margin" / r["file"]).read_text())["picks"][r["method"]]
        assert e["default"]["primitives"] == sweep["default"]["primitives"] == r["primitives"]
        assert e["smallest_within_0_5dB"]["primitives"] == sweep["smallest_primitives"]
        assert abs(e["smallest_within_0_5dB"]["mean_psnr"] - sweep["smallest_quality"]) < 1e-3
        assert e["default_over_smallest"] == round(e["default"]["primitives"] / e["smallest_within_0_5dB"]["primitives"], 2)
        assert e["target_met"] == r["target_met"]
        if e["target_met"]:
            assert e["default_over_smallest"] <= 1.5 and e["default_below_best_db"] <= 0.5
        assert e["default"]["megabytes"] > 0 and e["default"]["fps"] > 0
    assert "benchmarks/results/model_size.png" in README and (RESULTS / "model_size.png").stat().st_size > 10_000


def test_prune_margin_on_castle():
    """castle-P30's validation photos, 2DGS with the fixed 10% and with the prune read from the fit."""
    rows = {r["variant"]: r for r in json.loads((RESULTS / "prune_margin" / "castle_val.json").read_text())["rows"]}
    new, old = rows["2dgs, prune-margin-db 2 (default)"], rows["2dgs, fixed 10% (prune-margin-db 0)"]
    text = f"{new['mean']:.2f} dB with {new['primitives']:,}\n  surfels against {old['mean']:.2f} with {old['primitives']:,} for the fixed 10%"
    assert text in README, text
    views = list(new["psnr_per_view"].values())[0], list(old["psnr_per_view"].values())[0]
    assert len(views[0]) == 4 and all(a > b for a, b in zip(*views))  # "every one of the 4 held-out photos better"


def test_real_bench_with_the_video_at_800x448():
    """The real bench's three seeds with the video at 4x the street's size: the README's table row
    and paragraph are real{,_seed43,_seed44}.json's (the small video's figures: real_scene_budget.json)."""
    stems = ["real", "real_seed43", "real_seed44"]
    runs = _three_seeds(stems)
    d, small = runs[0], _real("real_scene_budget")
    assert all(r["options"]["video_scale"] == 4 for r in runs)
    flat = " ".join(README.split())

    def row(label: str, r: dict, ratio: str = "gain_ratio") -> str:  # a row of the capture-figures table
        return (f"| {label} | local | {r['registered_fraction']:.3f} | {r['ate_percent']:.2f} | {r['scale_error_percent']:+.1f} | "
                f"{r['rotation_error_deg']:.1f} | {r['up_error_deg']:.1f} | {r['mask_iou']['sky']:.3f} | {r['mask_iou']['ground']:.3f} | "
                f"{r['mask_iou']['transient']:.3f} | {r[ratio]['bev_1']:.2f} | {r[ratio]['bev_2']:.2f} |")

    for text in (row("this run, Intel host, the video at 800x448, against the true capture with its SfM points (`real.json`)", d),
                 row("the same run against the true capture with the generator's points (`gain_ratio_generator_points`)", d,
                     "gain_ratio_generator_points"),
                 row("Intel host, the video at 200x112, today's size defaults (`real_scene_budget.json`)", small)):
        assert text in README, text
    capture = (f"30/30 registered with {d['process']['points']:,} points ({small['process']['points']} from 200x112), ATE "
               f"{d['ate_percent']:.2f}% ({small['ate_percent']:.2f}%), rotation error {d['rotation_error_deg']:.2f} deg "
               f"({small['rotation_error_deg']:.2f}), up {d['up_error_deg']:.2f} deg ({small['up_error_deg']:.2f}), scale "
               f"{d['scale_error_percent']:+.2f}% ({small['scale_error_percent']:+.2f}%), and an eval camera mapped from its neighbours "
               f"misses its estimated pose by {d['eval_mapping_rotation_deg']:.2f} deg ({small['eval_mapping_rotation_deg']:.2f})")
    assert capture in flat, capture
    masks = (f"sky IoU {d['mask_iou']['sky']:.3f} ({small['mask_iou']['sky']:.3f}), ground {d['mask_iou']['ground']:.3f} "
             f"({small['mask_iou']['ground']:.3f}), transient {d['mask_iou']['transient']:.3f} ({small['mask_iou']['transient']:.3f})")
    assert masks in flat, masks
    assert d["mask_iou"]["sky"] >= 0.8 and d["mask_iou"]["ground"] >= 0.8  # "sky and ground meet the 0.8 target"
    per_seed = lambda key: ", ".join(f"{r[key]['bev_1']:.2f} / {r[key]['bev_2']:.2f}" for r in runs).split(", ")
    parts = per_seed("gain_ratio_generator_points")
    assert f"ratio is {parts[0]}, {parts[1]} and {parts[2]} (bev_1 / bev_2, seeds 42 / 43 / 44; `gain_ratio_generator_points`)" in flat
    gain = lambda st, side, s: _real_psnr(st, "splatfacto + NeRF views", s, side) - _real_psnr(st, "splatfacto", s, side)
    mean = lambda sts, side, s: sum(gain(st, side, s) for st in sts) / len(sts)
    ratio = lambda sts, s, side="ground_truth": mean(sts, "estimated", s) / mean(sts, side, s)
    smalls = ["real_scene_budget", "real_scene_budget_seed43", "real_scene_budget_seed44"]
    three = (f"over the three seeds the bird's-eye gain with everything estimated is {mean(stems, 'estimated', 'bev_1'):.2f} / "
             f"{mean(stems, 'estimated', 'bev_2'):.2f} dB against {mean(stems, 'ground_truth', 'bev_1'):.2f} / "
             f"{mean(stems, 'ground_truth', 'bev_2'):.2f} with ground truth, a ratio of {ratio(stems, 'bev_1'):.2f} / "
             f"{ratio(stems, 'bev_2'):.2f} ({ratio(smalls, 'bev_1'):.2f} / {ratio(smalls, 'bev_2'):.2f} from the 200x112 video)")
    assert three in flat, three
    cap, parts = "ground_truth_capture_points", per_seed("gain_ratio")
    assert all(r["gain_ratio"][s] == pytest.approx(gain(st, "estimated", s) / gain(st, cap, s)) for st, r in zip(stems, runs) for s in BEV)
    met = (f"differ in nothing else): {parts[0]}, {parts[1]} and {parts[2]}, over the three seeds {mean(stems, 'estimated', 'bev_1'):.2f} / "
           f"{mean(stems, 'estimated', 'bev_2'):.2f} dB against {mean(stems, cap, 'bev_1'):.2f} / {mean(stems, cap, 'bev_2'):.2f}, a ratio of "
           f"**{ratio(stems, 'bev_1', cap):.2f} / {ratio(stems, 'bev_2', cap):.2f}: the 0.8 target is met** on this street (not on a second one")
    assert met in flat, met
    assert min(ratio(stems, s, cap) for s in BEV) >= 0.8
    psnrs = lambda st, label, side="estimated": " / ".join(f"{_real_psnr(st, label, s, side):.2f}" for s in ("street", "bev_1", "bev_2"))
    assert psnrs("real", "StreetNeRF", cap) in flat and psnrs("real", "splatfacto", cap) in flat
    assert f"The generator's column retrained to the digit (StreetNeRF {psnrs('real', 'StreetNeRF', 'ground_truth')} dB, seed 42, as in `real_depth_loss.md`" in flat
    seed43 = {side: _real_psnr("real_seed43", "StreetNeRF", "bev_1", side) for side in ("estimated", cap)}
    assert seed43[cap] < seed43["estimated"]  # "on seed 43 the true column's own reference is below the estimated one"
    assert psnrs("real", "StreetNeRF", "ground_truth") == psnrs("real_depth_loss", "StreetNeRF", "ground_truth")
    est = d["results"]["estimated"]
    text = (f"StreetNeRF {psnrs('real', 'StreetNeRF')} dB ({_real_psnr('real_scene_budget', 'StreetNeRF', 'bev_1'):.2f} bev_1 from the small "
            f"video; the true capture's {_real_psnr('real', 'StreetNeRF', 'bev_1', 'ground_truth'):.2f}), Splatfacto {psnrs('real', 'splatfacto')} "
            f"({est['splatfacto']['size']['primitives']:,} Gaussians; {d['results']['ground_truth']['splatfacto']['size']['primitives']:,} on the "
            f"true capture), + NeRF views {psnrs('real', 'splatfacto + NeRF views')}")
    assert text in flat, text
    above = lambda sts: [" / ".join(f"{_real_psnr(st, 'StreetNeRF', s) - _real_psnr(st, 'splatfacto', s):.2f}" for s in ("bev_1", "bev_2"))
                         for st in sts]
    a, b = above(stems), above(smalls)
    assert f"({a[0]}, {a[1]}, {a[2]} dB; from the small video {b[0]}, {b[1]}, {b[2]})" in flat, (a, b)
    assert all(float(x) > 0 for x in " / ".join(a).split(" / "))  # "above Splatfacto from above on every seed"
    drop = [_real_psnr(st, "StreetNeRF", "bev_1", "ground_truth") - _real_psnr(st, "StreetNeRF", "bev_1") for st in stems]
    assert f"{min(drop):.2f}-{max(drop):.2f} dB below the true reference (bev_1, the three seeds)" in flat, drop
    street = lambda side: mean(stems, side, "street")
    assert f"the NeRF views cost the estimated target {-street('estimated'):.2f} dB (three-seed mean; the true one gains {street('ground_truth'):.2f})" in flat


def _decomposition(variant: str, label: str) -> str:
    """A row of benchmarks/results/real_decomposition.json as the README prints it: street / bev_1 / bev_2."""
    row = json.loads((RESULTS / "real_decomposition.json").read_text())["rows"][variant][label]
    return " / ".join(f"{row[s]:.2f}" for s in ("street", "bev_1", "bev_2"))


def test_real_decomposition():
    """What separates the real bench's columns: the README's figures are real_decomposition.json's and real.json's."""
    flat = " ".join(README.split())
    cap = "ground_truth_capture_points"
    psnrs = lambda label, side: " / ".join(f"{_real_psnr('real', label, s, side):.2f}" for s in ("street", "bev_1", "bev_2"))
    text = (f"trains a reference of {_decomposition('estimated, true transient masks', 'StreetNeRF')} and "
            f"{_decomposition('estimated, true masks', 'StreetNeRF')} dB (street / bev_1 / bev_2; the estimated masks "
            f"{psnrs('StreetNeRF', 'estimated')}); the true column trained on the video's frames {_decomposition('true, video images', 'StreetNeRF')} "
            f"(its own {psnrs('StreetNeRF', 'ground_truth')}); the true column with the capture's {_real('real')['process']['points']:,} SfM points")
    assert text in flat, text
    assert (f"{_decomposition(CAPTURE_POINTS, 'StreetNeRF')}, Splatfacto there {_decomposition(CAPTURE_POINTS, 'splatfacto')} against "
            f"the estimated capture's {psnrs('splatfacto', 'estimated')}") in flat
    # the decomposition's column is the bench's third column, retrained: to the digit
    assert _decomposition(CAPTURE_POINTS, "StreetNeRF") == psnrs("StreetNeRF", cap)
    street = lambda label: json.loads((RESULTS / "real_decomposition.json").read_text())["rows"]["estimated, true transient masks"][label]["street"]
    assert (f"with the true car masks the NeRF views no longer cost the estimated target there ({street('splatfacto + NeRF views'):.2f} "
            f"against {street('splatfacto'):.2f} dB; with the estimated masks {_real_psnr('real', 'splatfacto + NeRF views'):.2f} against "
            f"{_real_psnr('real', 'splatfacto'):.2f})") in flat
    assert street("splatfacto + NeRF views") >= street("splatfacto")


CAPTURE_POINTS = "true, capture's points"


def test_real_bench_on_a_second_street():
    """ns2gs-bench real --street-seed 7, three training seeds: the README's figures are real_street7/*.json's."""
    stems = ["real_street7/real", "real_street7/real_seed43", "real_street7/real_seed44"]
    runs = _three_seeds(stems)
    d = runs[0]
    assert all(r["options"]["street_seed"] == 7 for r in runs)
    flat = " ".join(README.split())
    cap = "ground_truth_capture_points"
    gain = lambda st, side, s: _real_psnr(st, "splatfacto + NeRF views", s, side) - _real_psnr(st, "splatfacto", s, side)
    mean = lambda side, s: sum(gain(st, side, s) for st in stems) / 3
    per = lambda key: ", ".join(f"{r[key]['bev_1']:.2f} / {r[key]['bev_2']:.2f}" for r in runs)
    above = lambda side: ", ".join(" / ".join(f"{_real_psnr(st, 'StreetNeRF', s, side) - _real_psnr(st, 'splatfacto', s, side):.2f}"
                                              for s in BEV) for st in stems)
    text = (f"30/30 registered ({d['process']['points']:,} points), ATE {d['ate_percent']:.2f}%, rotation {d['rotation_error_deg']:.2f} deg, "
            f"scale {d['scale_error_percent']:+.2f}%; sky IoU {d['mask_iou']['sky']:.3f}, ground {d['mask_iou']['ground']:.3f}, transient "
            f"{d['mask_iou']['transient']:.3f}. Gain ratio {per('gain_ratio')} (seeds 42 / 43 / 44; against the generator's points "
            f"{per('gain_ratio_generator_points')}); over the three seeds the bird's-eye gain with everything estimated is "
            f"{mean('estimated', 'bev_1'):.2f} / {mean('estimated', 'bev_2'):.2f} dB against {mean(cap, 'bev_1'):.2f} / {mean(cap, 'bev_2'):.2f} "
            f"with the true capture and its points, a ratio of {mean('estimated', 'bev_1') / mean(cap, 'bev_1'):.2f} / "
            f"{mean('estimated', 'bev_2') / mean(cap, 'bev_2'):.2f} ({mean('estimated', 'bev_1') / mean('ground_truth', 'bev_1'):.2f} / "
            f"{mean('estimated', 'bev_2') / mean('ground_truth', 'bev_2'):.2f} against the generator's points). StreetNeRF above Splatfacto "
            f"from above, estimated: {above('estimated')}; the true capture with its points: {above(cap)} dB.")
    assert text in flat, text
    assert d["registered_fraction"] == 1.0 and max(mean("estimated", s) / mean(cap, s) for s in BEV) < 0.8  # "missed on the second one"
    above_on = lambda splits: sum(all(_real_psnr(st, "StreetNeRF", s) > _real_psnr(st, "splatfacto", s) for s in splits) for st in stems)
    assert "Splatfacto on both views from above on one seed of three (on bev_1 on two)" in flat
    assert above_on(BEV) == 1 and above_on(("bev_1",)) == 2


def test_real_bench_at_the_default_lengths():
    """ns2gs-bench real at StreetNeRF / Splatfacto 3000 steps on both streets: the README's figures are
    real_default_length/*.json's."""
    stems = {"embedded": "real_default_length/real", "second": "real_default_length/real_street7"}
    cap = "ground_truth_capture_points"
    for name, street_seed in (("embedded", 0), ("second", 7)):
        o = _real(stems[name])["options"]
        assert (o["streetnerf_steps"], o["splatfacto_steps"], o["street_seed"]) == (3000, 3000, street_seed)
    gain = lambda st, s, side="estimated": _real_psnr(st, "splatfacto + NeRF views", s, side) - _real_psnr(st, "splatfacto", s, side)
    pair = lambda f: f"{f('bev_1'):.2f} / {f('bev_2'):.2f}"
    e, t = stems["embedded"], stems["second"]
    flat = " ".join(README.split())
    text = (f"On the embedded street the estimated target gains {pair(lambda s: gain(e, s))} dB from above against "
            f"{pair(lambda s: gain(e, s, cap))} with the true capture and its points, a ratio of "
            f"{pair(lambda s: _real(e)['gain_ratio'][s])}; on the second street {pair(lambda s: gain(t, s))} against "
            f"{pair(lambda s: gain(t, s, cap))}, a ratio of {pair(lambda s: _real(t)['gain_ratio'][s])}: still missed. There the "
            f"estimated capture's own Splatfacto is the stronger start from above ({pair(lambda s: _real_psnr(t, 'splatfacto', s))} dB "
            f"against {pair(lambda s: _real_psnr(t, 'splatfacto', s, cap))} on the true capture) and its augmented target ends "
            f"{pair(lambda s: _real_psnr(t, 'splatfacto + NeRF views', s, cap) - _real_psnr(t, 'splatfacto + NeRF views', s))} dB "
            f"below the true one ({pair(lambda s: _real_psnr(t, 'splatfacto + NeRF views', s))} against "
            f"{pair(lambda s: _real_psnr(t, 'splatfacto + NeRF views', s, cap))})")
    assert text in flat, text
    street = lambda st, side="estimated": gain(st, "street", side)
    assert (f"the NeRF views cost the estimated target {-street(e):.2f} / {-street(t):.2f} dB (embedded / second street) where "
            f"the true capture gains {street(e, cap):.2f} / {street(t, cap):.2f}") in flat
    assert min(_real(e)["gain_ratio"].values()) >= 0.8 > max(_real(t)["gain_ratio"].values())  # "still missed" on the second


def test_sky_fill_holes_claims():
    """The --auto.sky-fill-holes figures are the auto_masks_seed{7,3}_video4.json's (the same renders, the option off / on)."""
    flat = " ".join(README.split())
    r = {k: json.loads((RESULTS / f"auto_masks_seed{k}_video4.json").read_text()) for k in (7, 3)}
    off = lambda k, what="iou": r[k]["stats"]["sky"][what]
    on = lambda k, what="iou": r[k]["with_sky_fill_holes"]["stats"]["sky"][what]
    text = (f"sky {off(7):.3f} -> {on(7):.3f} on seed 7 (recall {off(7, 'recall'):.3f} -> {on(7, 'recall'):.3f}), {off(3):.3f} -> "
            f"{on(3):.3f} on seed 3 (its error is false sky on facades: precision {off(3, 'precision'):.3f} -> {on(3, 'precision'):.3f})")
    assert text in flat, text
    assert on(7) > off(7) and on(3) < off(3)  # "moves one validation street up and one down"
    assert not r[7]["options"]["sky_fill_holes"]  # off by default

