"""The embedded default dataset: a procedural street, ray-cast exactly, written as a nerfstudio
dataset that :func:`nerf2gs_plugin.data.parse_dataset` reads.

Why it exists: the paper's effect (a street-level capture leaves the road unseen from above, so a
splatting model trained on it breaks in bird's-eye views, and NeRF-rendered views fix that) needs
street data with bird's-eye ground truth, exact transient masks and metric poses. This scene has
all of it and is made in seconds on a CPU. See :mod:`nerf2gs_plugin.data.synthetic` for the parts.

Output folder::

    transforms.json        PINHOLE intrinsics, train frames, eval_splits {street, bev_1, bev_2,
                           val_street, val_bev, lane_1, lane_2, lane_4, val_lane},
                           metres_per_unit = 1, up = +z, ply_file_path
    images/<name>.png      train_XXXX (with cars, +-exposure), street_XXXX / bev1_XXXX / bev2_XXXX (no cars),
                           valstreet_XXXX / valbev_XXXX, lane1_XXXX / lane2_XXXX / lane4_XXXX /
                           vallane_XXXX (no cars)
    masks/{sky,ground,transient}/<name>.png   exact masks (ground = road + sidewalk)
    depth/<name>.npy       z-depth in metres, 0 = sky
    sparse_pc.ply          SfM-like points: static surfaces seen by the training views, with noise
    synth_stats.json       generation time, and how much BEV ground no training view saw
                           (the only file that differs between two runs with the same seed)

Validation splits: ``val_street`` (street-level views between the test street views) and
``val_bev`` (bird's-eye views at other heights, pitches and circle phases than bev_1/bev_2) are
for choosing defaults; ``street``/``bev_1``/``bev_2`` are the reported test views and tune nothing.
The validation poses come from their own random generator and are rendered last, so adding them
left every train/test image and the sparse points byte-identical (generator version 2 vs 1).

Lane-shift splits (the XLD benchmark's cross-lane views): ``lane_1``, ``lane_2``, ``lane_4`` are level
cameras at the training height 1, 2 and 4 m across the road from the driven lanes, half to each side
where the road allows (else toward the other lane); ``val_lane`` (1.5 and 3 m) chooses defaults for
them. Their poses come from a third generator and are rendered after everything else, so every
earlier file is byte-identical (generator version 3 vs 2; only transforms.json grows).
"""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
import tyro

from nerf2gs_plugin.data.images import write_depth_atomic, write_image_atomic, write_mask_atomic
from nerf2gs_plugin.data.ply import write_ply_points
from nerf2gs_plugin.data.synthetic.coverage import ground_coverage
from nerf2gs_plugin.data.synthetic.layout import ROAD_HALF, SKY, TRANSIENT_MATERIALS, Boxes, build_layout, empty_boxes
from nerf2gs_plugin.data.synthetic.movers import build_movers, frame_boxes
from nerf2gs_plugin.data.synthetic.poses import bev_poses, street_poses, train_poses
from nerf2gs_plugin.data.synthetic.raycast import Pinhole, ShadowMap, render_view
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.utils.io import atomic_write_text

GENERATOR_VERSION = 3  # 2: val_street, val_bev added; 3: lane_* and val_lane added (earlier files unchanged)


@dataclass
class SynthStreetConfig:
    """Generate the synthetic street dataset (``ns2gs-data synth-street OUT``)."""

    out: tyro.conf.Positional[Path] = Path("data/street")
    """Output dataset folder."""
    seed: int = 0
    """Layout, colours, cars, poses and exposures all follow from the seed."""
    width: int = 200
    """Image width in pixels (every camera)."""
    height: int = 112
    """Image height in pixels."""
    fov_deg: float = 80.0
    """Horizontal field of view of every camera."""
    num_train: int = 60
    """Training views (half driving toward +x, half back)."""
    num_street: int = 8
    """Held-out street-level eval views (no cars)."""
    num_bev: int = 12
    """Views per bird's-eye eval split (bev_1, bev_2; no cars)."""
    num_cars: int = 6
    """Moving cars (transients, training views only)."""
    cam_height: float = 3.0
    """Training camera height (m)."""
    drive_half_len: float = 24.0
    """The training camera drives x in [-L, L] (m); the street is 72 m between its end blocks."""
    bev_1: tuple[float, float] = (10.0, 25.0)
    """bev_1: (metres above the training height, pitch down in degrees)."""
    bev_2: tuple[float, float] = (13.0, 30.0)
    num_val_street: int = 6
    """Validation street-level views (val_street; distinct from the street test views)."""
    num_val_bev: int = 8
    """Validation bird's-eye views (val_bev): half at val_bev_a, half at val_bev_b, other circle phases."""
    val_bev_a: tuple[float, float] = (11.5, 27.5)
    """val_bev first half: (metres above the training height, pitch down in degrees)."""
    val_bev_b: tuple[float, float] = (8.0, 22.0)
    num_lane: int = 8
    """Views per lane-shift eval split (one split ``lane_<d>`` per offset in lane_offsets; 0: none)."""
    lane_offsets: tuple[float, ...] = (1.0, 2.0, 4.0)
    """Lane-shift eval offsets: metres across the road from the driven lane, at the training height."""
    num_val_lane: int = 6
    """Validation lane-shift views (val_lane), alternating over val_lane_offsets."""
    val_lane_offsets: tuple[float, ...] = (1.5, 3.0)
    spp: int = 5
    """Rays per pixel (1 = pixel centre only; up to 5, rotated grid) for anti-aliasing."""
    exposure_jitter: float = 0.05
    """Training images get a per-image exposure in 1 +- this (appearance variation)."""
    num_points: int = 4000
    """Sparse SfM-like points written to sparse_pc.ply."""
    point_noise: float = 0.03
    """Sparse point noise (m), plus 0.4% of the depth, like triangulation error."""
    movers: bool = False
    """Also a car and a cyclist riding ahead of the training camera at its speed, pedestrians crossing
    and parked cars (static) on the sidewalks (``data/synthetic/movers.py``), for the motion masks.
    Off: the street as before, byte-identical."""
    coverage_angle_deg: float = 15.0
    """A BEV ground point counts as seen when a training view saw it within this angle."""
    overwrite: bool = False
    """Replace an existing dataset in OUT."""
    progress: bool = True
    """Show a progress bar on stderr."""


def _check(cfg: SynthStreetConfig) -> None:
    problems = []
    if cfg.width < 8 or cfg.height < 8:
        problems.append(f"image size must be at least 8x8, got {cfg.width}x{cfg.height}")
    if cfg.num_train < 2:
        problems.append(f"num_train must be at least 2, got {cfg.num_train}")
    if cfg.num_street < 1 or cfg.num_bev < 1:
        problems.append("num_street and num_bev must be at least 1")
    if cfg.num_val_street < 0 or cfg.num_val_bev < 0 or cfg.num_lane < 0 or cfg.num_val_lane < 0:
        problems.append("num_val_street, num_val_bev, num_lane and num_val_lane must be >= 0")
    if not all(0 < d <= 2 * ROAD_HALF for d in (*cfg.lane_offsets, *cfg.val_lane_offsets)):
        problems.append(f"lane offsets must be within (0, {2 * ROAD_HALF:g}] m (the road's width)")
    if cfg.num_val_lane and not cfg.val_lane_offsets:
        problems.append("num_val_lane needs at least one val_lane_offsets entry")
    if not 10.0 <= cfg.fov_deg <= 150.0:
        problems.append(f"fov_deg must be within [10, 150], got {cfg.fov_deg}")
    if cfg.num_cars < 0 or cfg.num_points < 0 or cfg.spp < 1:
        problems.append("num_cars and num_points must be >= 0 and spp >= 1")
    if not 0 < cfg.drive_half_len <= 30.0:
        problems.append(f"drive_half_len must be within (0, 30] m, got {cfg.drive_half_len}")
    if problems:
        raise ConfigError("synth-street: " + "; ".join(problems))


def _prepare_out(cfg: SynthStreetConfig) -> Path:
    out = Path(cfg.out)
    if out.exists() and not out.is_dir():
        raise ConfigError("output exists and is not a folder", out)
    if (out / "transforms.json").exists():
        if not cfg.overwrite:
            raise ConfigError("a dataset already exists here (pass --overwrite to replace it)", out)
        for sub in ("images", "masks", "depth", ".ns2gs_cache"):
            shutil.rmtree(out / sub, ignore_errors=True)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _round(m: torch.Tensor) -> list[list[float]]:
    full = torch.cat([m.double(), torch.tensor([[0.0, 0.0, 0.0, 1.0]], dtype=torch.float64)])
    return [[round(float(v), 7) + 0.0 for v in row] for row in full]


def generate_street(cfg: SynthStreetConfig) -> dict[str, Any]:
    """Write the dataset to ``cfg.out``; returns the statistics also saved in ``synth_stats.json``.

    Runs single-threaded: the work is many small tensor ops, which intra-op threads slow down on
    a shared CPU."""
    _check(cfg)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _generate(cfg)
    finally:
        torch.set_num_threads(threads)


def _generate(cfg: SynthStreetConfig) -> dict[str, Any]:
    t_start, cpu_start = time.perf_counter(), time.process_time()
    out = _prepare_out(cfg)
    layout = build_layout(cfg.seed, cfg.num_cars)
    movers = build_movers(layout) if cfg.movers else None
    if movers is not None:  # parked cars are static: they cast shadows and enter the sparse points
        layout.static = Boxes.cat([layout.static, movers.parked])
    shadows = ShadowMap(layout)
    gen = torch.Generator().manual_seed(cfg.seed * 7919 + 17)
    intr = Pinhole.from_fov(cfg.width, cfg.height, cfg.fov_deg)
    L, h0 = cfg.drive_half_len, cfg.cam_height
    tr_c2w, tr_times = train_poses(cfg.num_train, L, h0, gen)
    splits = {
        "street": ("street", street_poses(cfg.num_street, L, h0, gen)),
        "bev_1": ("bev1", bev_poses(cfg.num_bev, L, h0 + cfg.bev_1[0], cfg.bev_1[1], 0.0, gen)),
        "bev_2": ("bev2", bev_poses(cfg.num_bev, L, h0 + cfg.bev_2[0], cfg.bev_2[1], 0.5, gen)),
    }
    val_splits = {**_val_splits(cfg), **_lane_splits(cfg)}  # rendered after train/test: those stay byte-identical
    exposure = 1.0 + (torch.rand(cfg.num_train, generator=gen) * 2 - 1) * cfg.exposure_jitter
    tint = 1.0 + (torch.rand(cfg.num_train, 3, generator=gen) * 2 - 1) * 0.015

    def write(name: str, view, gain: torch.Tensor) -> dict[str, Any]:
        rgb = (view.rgb * gain).clamp(0, 1)
        write_image_atomic(out / "images" / f"{name}.png", rgb)
        for kind in ("sky", "ground", "transient"):
            write_mask_atomic(out / "masks" / kind / f"{name}.png", getattr(view, kind))
        write_depth_atomic(out / "depth" / f"{name}.npy", view.depth)
        return {
            "file_path": f"images/{name}.png",
            "sky_mask_path": f"masks/sky/{name}.png",
            "ground_mask_path": f"masks/ground/{name}.png",
            "transient_mask_path": f"masks/transient/{name}.png",
            "depth_file_path": f"depth/{name}.npy",
        }

    total = cfg.num_train + cfg.num_street + 2 * cfg.num_bev + sum(p.shape[0] for _, p in val_splits.values())
    frames: list[dict[str, Any]] = []
    eval_frames: dict[str, list[dict[str, Any]]] = {k: [] for k in (*splits, *val_splits)}
    depths, pts, cols, keep = [], [], [], []
    coverage: dict[str, list[int]] = {k: [0, 0, 0] for k in (*splits, *val_splits)}
    no_cars = empty_boxes()
    with make_progress(cfg.progress) as prog:
        task = prog.add_task("synth-street", total=total, stats="")
        for i in range(cfg.num_train):
            c2w = tr_c2w[i]
            cars = frame_boxes(layout, movers, float(tr_times[i]), c2w)
            view = render_view(layout, c2w, intr, cars, shadows, cfg.spp)
            gain = exposure[i] * tint[i]
            fr = write(f"train_{i:04d}", view, gain)
            fr.update(transform_matrix=_round(c2w), time=round(float(tr_times[i]), 4), exposure=round(float(exposure[i]), 5))
            frames.append(fr)
            depths.append(view.depth)
            static_hit = (view.material != SKY) & ~torch.isin(view.material, torch.tensor(TRANSIENT_MATERIALS))
            keep.append(static_hit)
            pts.append(view.points)
            cols.append((view.rgb * gain).clamp(0, 1).reshape(-1, 3))
            prog.advance(task)
        train_depth = torch.stack(depths)
        for split, (prefix, poses) in {**splits, **val_splits}.items():
            for i in range(poses.shape[0]):
                view = render_view(layout, poses[i], intr, no_cars, shadows, cfg.spp)
                fr = write(f"{prefix}_{i:04d}", view, torch.ones(3))
                fr["transform_matrix"] = _round(poses[i])
                eval_frames[split].append(fr)
                g = view.ground.reshape(-1)
                m, a, b = ground_coverage(view.points[g], poses[i][:, 3], tr_c2w, train_depth, intr, cfg.coverage_angle_deg)
                for k, v in enumerate((m, a, b)):
                    coverage[split][k] += v
                prog.advance(task)

    # SfM-like sparse points: static surfaces seen by the training views, noisy, a few outliers
    P, C, K = torch.cat(pts), torch.cat(cols), torch.cat(keep)
    depth_all = train_depth.reshape(-1)
    idx = K.nonzero()[:, 0]
    n_pts = min(cfg.num_points, len(idx))
    idx = idx[torch.randperm(len(idx), generator=gen)[:n_pts]]
    sigma = (cfg.point_noise + 0.004 * depth_all[idx])[:, None]
    xyz = P[idx] + torch.randn(n_pts, 3, generator=gen) * sigma
    rgb = (C[idx] * 255 + 0.5).clamp(0, 255).to(torch.uint8)
    n_out = n_pts // 200
    if n_out:
        lo, hi = torch.tensor([-36.0, -6.0, 0.0]), torch.tensor([36.0, 6.0, 12.0])
        xyz[:n_out] = lo + torch.rand(n_out, 3, generator=gen) * (hi - lo)
    write_ply_points(out / "sparse_pc.ply", xyz.numpy(), rgb.numpy())

    meta = {
        "camera_model": "PINHOLE",
        "fl_x": intr.fx, "fl_y": intr.fy, "cx": intr.cx, "cy": intr.cy, "w": intr.width, "h": intr.height,
        "metres_per_unit": 1.0,
        "up": [0.0, 0.0, 1.0],
        "ply_file_path": "sparse_pc.ply",
        "synthetic_street": {"generator_version": GENERATOR_VERSION, "seed": cfg.seed,
                             "bev_1": {"delta_h_m": cfg.bev_1[0], "pitch_deg": cfg.bev_1[1]},
                             "bev_2": {"delta_h_m": cfg.bev_2[0], "pitch_deg": cfg.bev_2[1]},
                             "val_bev": [{"delta_h_m": h, "pitch_deg": p} for h, p in (cfg.val_bev_a, cfg.val_bev_b)],
                             "cam_height_m": cfg.cam_height, **({"movers": True} if cfg.movers else {})},
        "frames": frames,
        "eval_splits": eval_frames,
    }
    meta["synthetic_street"]["lane"] = {"offsets_m": list(cfg.lane_offsets), "val_offsets_m": list(cfg.val_lane_offsets)}
    atomic_write_text(out / "transforms.json", json.dumps(meta, indent=1))
    seconds = time.perf_counter() - t_start
    stats: dict[str, Any] = {
        "out": str(out),
        "seconds": round(seconds, 2),
        "cpu_seconds": round(time.process_time() - cpu_start, 2),
        "images": total,
        "size": [cfg.width, cfg.height],
        "points": int(n_pts),
        "coverage_angle_deg": cfg.coverage_angle_deg,
        "ground_coverage": {
            split: {
                "ground_pixels": m,
                "unseen_at_similar_angle": round(a / m, 4) if m else None,
                "unseen_at_all": round(b / m, 4) if m else None,
            }
            for split, (m, a, b) in coverage.items()
        },
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
    }
    atomic_write_text(out / "synth_stats.json", json.dumps(stats, indent=2))
    return stats


def _val_splits(cfg: SynthStreetConfig) -> dict[str, tuple[str, torch.Tensor]]:
    """Validation poses, from a generator of their own (the train/test draws stay as they were)."""
    from nerf2gs_plugin.data.synthetic.poses import street_poses_between

    vgen = torch.Generator().manual_seed(cfg.seed * 7919 + 29)
    L, h0 = cfg.drive_half_len, cfg.cam_height
    na = (cfg.num_val_bev + 1) // 2
    bev = [bev_poses(na, L, h0 + cfg.val_bev_a[0], cfg.val_bev_a[1], 0.25, vgen),
           bev_poses(cfg.num_val_bev - na, L, h0 + cfg.val_bev_b[0], cfg.val_bev_b[1], 0.75, vgen)]
    out = {}
    if cfg.num_val_street:
        out["val_street"] = ("valstreet", street_poses_between(cfg.num_val_street, L, h0, vgen))
    if cfg.num_val_bev:
        out["val_bev"] = ("valbev", torch.cat([b for b in bev if b.shape[0]]))
    return out


def lane_split_name(offset: float) -> str:
    """The eval split of the lane-shift views ``offset`` metres to the side: ``lane_1``, ``lane_2.5``."""
    return f"lane_{offset:g}"


def _lane_splits(cfg: SynthStreetConfig) -> dict[str, tuple[str, torch.Tensor]]:
    """Lane-shift poses (test splits, then val_lane), from a generator of their own."""
    from nerf2gs_plugin.data.synthetic.poses import lane_shift_poses

    lgen = torch.Generator().manual_seed(cfg.seed * 7919 + 43)
    L, h0 = cfg.drive_half_len, cfg.cam_height
    out = {}
    if cfg.num_lane:
        for d in cfg.lane_offsets:
            out[lane_split_name(d)] = (lane_split_name(d).replace("_", ""), lane_shift_poses(cfg.num_lane, L, h0, d, lgen))
    if cfg.num_val_lane:
        offs = cfg.val_lane_offsets
        parts = [lane_shift_poses(cfg.num_val_lane, L, h0, d, lgen) for d in offs]
        # view i at offset i mod len(offs): the offsets interleave along the street
        poses = torch.stack([parts[i % len(offs)][i] for i in range(cfg.num_val_lane)])
        out["val_lane"] = ("vallane", poses)
    return out


def read_generator_version(data: Path) -> int | None:
    """The synthetic-street generator version a dataset was written by (None: not a synthetic street)."""
    try:
        meta = json.loads((Path(data) / "transforms.json").read_text())
    except (OSError, ValueError):
        return None
    info = meta.get("synthetic_street") if isinstance(meta, dict) else None
    return int(info.get("generator_version", 1)) if isinstance(info, dict) else None


def summary_lines(stats: dict[str, Any]) -> list[str]:
    """Human-readable lines for a :func:`generate_street` result."""
    lines = [f"wrote {stats['out']}: {stats['images']} images of {stats['size'][0]}x{stats['size'][1]}, "
             f"{stats['points']} sparse points, in {stats['seconds']:.1f} s ({stats['cpu_seconds']:.1f} s CPU)"]
    ang = stats["coverage_angle_deg"]
    for split, c in stats["ground_coverage"].items():
        if c["ground_pixels"]:
            lines.append(f"  {split:7s} ground pixels seen by no training view within {ang:g} deg: "
                         f"{100 * c['unseen_at_similar_angle']:5.1f}%  (by no training view at all: {100 * c['unseen_at_all']:5.1f}%)")
    return lines
