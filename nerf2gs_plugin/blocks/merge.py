"""``ns2gs-export merge RUN... --out RUN_DIR``: the block runs of one partition as one run.

Each block run's primitives are moved from the block's normalised frame to the source dataset's
(:mod:`.reframe`), and only those inside the block's own cell (not the expanded one it trained
on) are kept; the sky background is the mean of the blocks' (weighted by their train images).
The result is an ordinary run folder of the same method, on the source dataset: ``config.yml``
(the first block's settings, ``data`` = the source), ``dataparser_transforms.json`` and
``train_cameras.json`` of the source, ``checkpoints/step-*.ckpt`` (model state only: a merged run
is evaluated, viewed and exported, not resumed) and ``merge.json`` (which run filled which cell,
primitives kept). Any per-primitive splatting method merges (state ``gauss.*``: Splatfacto, 2DGS);
Scaffold-GS and NeRFs hold networks that cannot be cut by cell.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
import tyro

from nerf2gs_plugin.blocks.cells import Cell, inside, to_uv
from nerf2gs_plugin.blocks.partition import block_of, read_partition
from nerf2gs_plugin.blocks.reframe import PREFIX, means_to_data, reframe_state, select
from nerf2gs_plugin.data import DataParserConfig, load_dataparser_transform, save_dataparser_transform
from nerf2gs_plugin.data.fingerprint import dataset_fingerprint
from nerf2gs_plugin.data.normalize import DataparserTransform
from nerf2gs_plugin.engine.checkpoints import checkpoint_path, list_checkpoints, load_checkpoint, resolve_checkpoint, save_checkpoint
from nerf2gs_plugin.engine.config import load_config, read_config_doc, save_config
from nerf2gs_plugin.runs.load import find_dataset
from nerf2gs_plugin.engine.run_cameras import save_train_cameras
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.registry import get_method
from nerf2gs_plugin.utils.io import atomic_write_text

MERGE_FILE = "merge.json"


@dataclass
class MergeConfig:
    """Merge the block runs of one partition into one run (each block's primitives inside its own cell)."""

    runs: tyro.conf.Positional[list[Path]]
    """One run directory (or .ckpt) per block of the partition, all of one method."""
    out: Path
    """The merged run folder (viewer, ns2gs-eval and ns2gs-export read it)."""
    overwrite: bool = False
    """Replace a merged run already in OUT."""


@dataclass
class BlockRun:
    run_dir: Path
    checkpoint: Path
    method: str
    config: Any
    partition: Path
    block: str


def _block_run(path: Path) -> BlockRun:
    run_dir, ckpt = resolve_checkpoint(path)
    doc = read_config_doc(run_dir / "config.yml")
    config = load_config(run_dir / "config.yml", get_method(doc["method_name"]).config)
    data = find_dataset(Path(config.data), run_dir)
    found = block_of(data)
    if found is None:
        raise ConfigError(f"not trained on a block of a partition (its dataset {data} has no 'partition' entry; "
                          "make blocks with ns2gs-data partition)", run_dir)
    return BlockRun(run_dir, ckpt, doc["method_name"], config, found[0], found[1])


def _check(runs: list[BlockRun], doc: dict) -> None:
    methods = sorted({r.method for r in runs})
    if len(methods) > 1:
        which = ", ".join(f"{r.run_dir} ({r.method})" for r in runs)
        raise ConfigError(f"runs of different methods cannot be merged: {which}")
    parts = sorted({str(r.partition) for r in runs})
    if len(parts) > 1:
        raise ConfigError(f"runs come from different partitions: {', '.join(parts)}")
    seen: dict[str, Path] = {}
    for r in runs:
        if r.block in seen:
            raise ConfigError(f"two runs of block {r.block}: {seen[r.block]} and {r.run_dir}")
        seen[r.block] = r.run_dir
    missing = [b["name"] for b in doc["blocks"] if b["name"] not in seen]
    if missing:
        raise ConfigError(f"no run for block(s) {', '.join(missing)} of {runs[0].partition} (every cell needs its run)")


def _source_outputs(config: Any, source: Path):
    """The source dataset's train split parsed as the blocks' runs parse theirs (same options)."""
    # a plugin's datamanager config may have no dataparser: the defaults then
    parser = getattr(config.pipeline.datamanager, "dataparser", None) or DataParserConfig()
    return parser.setup(source).parse("train")


def merge(cfg: MergeConfig) -> Path:
    """Write the merged run folder ``cfg.out``; returns it."""
    if not cfg.runs:
        raise ConfigError("merge needs the block runs (one run directory per block)")
    runs = [_block_run(p) for p in cfg.runs]
    doc = read_partition(runs[0].partition)
    _check(runs, doc)
    source = Path(doc["source"])
    if not source.exists():
        raise ConfigError(f"the partition's source dataset {source} does not exist", runs[0].partition)
    out = _prepare_out(Path(cfg.out), cfg.overwrite)
    by_block = {r.block: r for r in runs}
    part_tf = DataparserTransform(torch.tensor(doc["transform"]), float(doc["scale"]))
    axes = torch.tensor(doc["axes"], dtype=torch.float64)
    target = _source_outputs(runs[0].config, source)
    dst = DataparserTransform(target.dataparser_transform, target.dataparser_scale, target.up, target.metres_per_unit, target.scene_box)
    states, report, weights = [], [], []
    step, seconds = 0, 0.0
    for b in doc["blocks"]:
        r, cell = by_block[b["name"]], Cell.from_json(b)
        ckpt = load_checkpoint(r.checkpoint, expected_method=r.method)
        state = ckpt["model"]
        if PREFIX + "means" not in state:
            raise ConfigError(f"method '{r.method}' cannot be merged by cell: its model has no per-primitive "
                              "gauss.* parameters (Splatfacto and 2DGS have)", r.checkpoint)
        src = load_dataparser_transform(r.run_dir / "dataparser_transforms.json")
        uv = to_uv(part_tf.apply_points(means_to_data(state[PREFIX + "means"], src).float()), axes)
        keep = inside(uv, cell.u, cell.v)
        states.append(select(reframe_state(state, src, dst), keep))
        weights.append(float(b.get("train_images", 1)))
        step, seconds = max(step, int(ckpt["step"])), seconds + float(ckpt.get("train_seconds", 0.0))
        report.append({"block": b["name"], "run": str(r.run_dir), "checkpoint": str(r.checkpoint), "step": int(ckpt["step"]),
                       "primitives": int(keep.numel()), "kept": int(keep.sum())})
    merged = _combine(states, weights)
    config = dataclasses.replace(runs[0].config, data=source, load_checkpoint=None, augment_from=None,
                                 experiment_name=None, timestamp=out.name, run_dir=None)
    save_config(out / "config.yml", runs[0].method, config)
    save_dataparser_transform(out / "dataparser_transforms.json", target)
    save_train_cameras(out, target.cameras)
    ckpt_file = checkpoint_path(out, step)
    save_checkpoint(ckpt_file, {"method_name": runs[0].method, "step": step, "model": merged,
                                "dataset": dataset_fingerprint(target.image_filenames), "train_seconds": seconds,
                                "merged_from": [x["run"] for x in report]})
    atomic_write_text(out / MERGE_FILE, json.dumps({"format": "nerf2gs-merge/1", "partition": str(runs[0].partition),
                                                   "method": runs[0].method, "step": step, "blocks": report,
                                                   "primitives": sum(x["kept"] for x in report)}, indent=1))
    from nerf2gs_plugin.runs.model import load_run_model

    load_run_model(out)  # the model must take the merged state (a clear error here, not in the viewer)
    return out


def _combine(states: list[dict], weights: list[float]) -> dict:
    """One state: ``gauss.*`` concatenated in block order, the sky background averaged by
    ``weights``, the step the latest, anything else the first block's."""
    out = dict(states[0])
    for key in states[0]:
        if key.startswith(PREFIX):
            out[key] = torch.cat([s[key] for s in states])
    if "background.coeffs" in out:
        w = torch.tensor(weights, dtype=torch.float64)
        stacked = torch.stack([s["background.coeffs"].double() for s in states])
        out["background.coeffs"] = (stacked * (w / w.sum())[:, None, None]).sum(0).to(states[0]["background.coeffs"].dtype)
    if "step" in out:
        out["step"] = torch.stack([s["step"] for s in states]).max()
    return out


def _prepare_out(out: Path, overwrite: bool) -> Path:
    if out.exists() and not out.is_dir():
        raise ConfigError("output exists and is not a folder", out)
    old = list_checkpoints(out)
    if old and not overwrite:
        raise ConfigError("a run already exists here (pass --overwrite to replace it)", out)
    for p in old:
        p.unlink()
    out.mkdir(parents=True, exist_ok=True)
    return out
