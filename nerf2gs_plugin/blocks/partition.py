"""``ns2gs-data partition DATA --blocks KxL --overlap 0.2 --out DIR``: a capture split into
overlapping blocks, each an ordinary nerfstudio dataset folder (``DIR/block_<i>_<j>/``) that every
``ns2gs-*`` command reads, plus ``DIR/partition.json`` naming each block's cell.

A block holds the train frames whose camera stands in its expanded cell (:mod:`.cells`; with
``--visibility``, also those looking into its cell), the held-out frames of every eval split standing there (split names kept; a split with none there is
left out), their masks and depth maps, and the sparse points inside the expanded cell. Images,
masks and depth maps are linked (relative symlinks mirroring the source's layout), never copied;
the points are cropped into a new PLY. Each block's ``transforms.json`` keeps the source's
intrinsics and metadata, states the source's ``up`` (so every block shares one ground plane), and
names its block under ``partition`` (what ``ns2gs-export merge`` reads back).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import torch
import tyro

from nerf2gs_plugin.blocks.cells import Cell, ground_axes, inside, make_cells, to_uv
from nerf2gs_plugin.data import NerfstudioDataParserConfig, dataparser_config
from nerf2gs_plugin.data.base import RawFrame
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.data.fingerprint import dataset_fingerprint
from nerf2gs_plugin.data.normalize import DataparserTransform
from nerf2gs_plugin.data.ply import read_ply_points, write_ply_points
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_plugin.utils.io import atomic_write_text

FORMAT = "nerf2gs-partition/1"
PARTITION_FILE = "partition.json"
_SPLIT_KEYS = ("frames", "eval_splits", "train_filenames", "val_filenames", "test_filenames", "ply_file_path")


@dataclass
class PartitionConfig:
    """Split a capture into overlapping blocks by camera position (each block a dataset folder)."""

    data: tyro.conf.Positional[Path]
    """Source dataset folder (nerfstudio transforms.json; `ns2gs-data process` writes one)."""
    out: Path
    """Output folder: one dataset folder per block and partition.json."""
    blocks: str = "2x1"
    """Grid KxL: K blocks along the street's main axis, L across it."""
    overlap: float = 0.2
    """Each block also trains on cameras within this fraction of its cell's size beyond its edges (0 to 1)."""
    visibility: float = 0.0
    """Also train a block on outside cameras whose sparse points in view lie in its cell for at least this fraction (0: off)."""
    min_cameras: int = 3
    """A block needs at least this many training cameras."""
    overwrite: bool = False
    """Replace a partition already in OUT."""


def parse_grid(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise ConfigError(f"--blocks must be KxL with K, L >= 1 (e.g. 2x1), got '{text}'")
    return int(m.group(1)), int(m.group(2))


def check_config(cfg: PartitionConfig) -> tuple[int, int]:
    grid = parse_grid(cfg.blocks)
    if not (math.isfinite(cfg.overlap) and 0.0 <= cfg.overlap <= 1.0):
        raise ConfigError(f"--overlap must be within [0, 1] (a fraction of the cell size), got {cfg.overlap}")
    if not (math.isfinite(cfg.visibility) and 0.0 <= cfg.visibility <= 1.0):
        raise ConfigError(f"--visibility must be within [0, 1] (a fraction of the points in view), got {cfg.visibility}")
    if cfg.min_cameras < 1:
        raise ConfigError(f"--min-cameras must be at least 1, got {cfg.min_cameras}")
    return grid


def _source(data: Path) -> NerfstudioDataParserConfig:
    parser = dataparser_config(data)
    if not isinstance(parser, NerfstudioDataParserConfig):
        raise DataError("partition reads nerfstudio transforms.json datasets (ns2gs-data process writes one); "
                        "this folder is another format", data)
    return parser


def _entries_by_image(meta: dict, root: Path) -> dict[Path, dict]:
    """The file's frame dicts (``frames`` and dicts inside ``eval_splits``) by resolved image path."""
    found: dict[Path, dict] = {}
    entries = list(meta.get("frames") or [])
    for items in (meta.get("eval_splits") or {}).values():
        entries += [e for e in items if isinstance(e, dict)]
    for e in entries:
        p = root / str(e["file_path"])
        if p.suffix == "" and not p.exists():
            p = next((p.with_suffix(x) for x in (".png", ".jpg", ".jpeg") if p.with_suffix(x).exists()), p)
        found.setdefault(p.resolve(), e)
    return found


class _Linker:
    """Links the source's files into a block folder at the same relative path (absolute path
    when the file lies outside the source folder); returns the path to write in transforms.json."""

    def __init__(self, src_root: Path, block: Path) -> None:
        self.src_root, self.block = src_root.absolute(), block

    def __call__(self, path: Optional[Path]) -> Optional[str]:
        if path is None:
            return None
        full = Path(path).absolute()
        try:
            rel = full.relative_to(self.src_root)
        except ValueError:
            return str(full)
        dst = self.block / rel
        if not dst.is_symlink():
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(os.path.relpath(full, dst.parent), dst)
        return rel.as_posix()


def _block_entry(frame: RawFrame, raw: dict, link: _Linker) -> dict:
    entry = {k: v for k, v in raw.items() if not k.endswith("_mask_path") and k != "depth_file_path"}
    entry["file_path"] = link(frame.image)
    for kind in MASK_KINDS:
        if frame.masks.get(kind) is not None:
            entry[f"{kind}_mask_path"] = link(frame.masks[kind])
    if frame.depth is not None:
        entry["depth_file_path"] = link(frame.depth)
    return entry


def _positions(frames: list[RawFrame], tf: DataparserTransform) -> torch.Tensor:
    if not frames:
        return torch.zeros(0, 3)
    return tf.apply_poses(torch.stack([f.c2w for f in frames]))[:, :, 3]


def _prepare_out(cfg: PartitionConfig) -> Path:
    out = Path(cfg.out)
    if (out / PARTITION_FILE).exists():
        if not cfg.overwrite:
            raise ConfigError("a partition already exists here (pass --overwrite to replace it)", out)
        for old in json.loads((out / PARTITION_FILE).read_text()).get("blocks", []):
            shutil.rmtree(out / old["folder"], ignore_errors=True)
    if out.exists() and not out.is_dir():
        raise ConfigError("output exists and is not a folder", out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def partition(cfg: PartitionConfig) -> dict[str, Any]:
    """Write the block datasets and ``partition.json``; returns the partition document."""
    k, l = check_config(cfg)
    parser = _source(Path(cfg.data))
    meta = json.loads(parser.json_path.read_text())
    src_root = parser.json_path.parent
    groups = parser.raw_frames()  # the parser's own split rules (eval_splits, *_filenames, holdout_every)
    train_out = parser.parse("train")
    tf = DataparserTransform(train_out.dataparser_transform, train_out.dataparser_scale, train_out.up,
                             train_out.metres_per_unit, train_out.scene_box)
    axes = ground_axes(train_out.cameras.camera_to_worlds[:, :2, 3])
    uv = {name: to_uv(_positions(frames, tf), axes) for name, frames in groups.items()}
    cells = make_cells(uv["train"], k, l, cfg.overlap)
    points = None
    if meta.get("ply_file_path"):
        xyz, rgb = read_ply_points(src_root / str(meta["ply_file_path"]))
        points = (xyz, rgb, to_uv(tf.apply_points(torch.as_tensor(xyz, dtype=torch.float32)), axes))
    train_sel = [inside(uv["train"], c.expanded_u, c.expanded_v) for c in cells]
    if cfg.visibility > 0 and points is not None:
        norm_xyz = train_out.points3D_xyz.float() if train_out.points3D_xyz is not None else torch.zeros(0, 3)
        train_sel = [sel | (looking_into(train_out.cameras, norm_xyz, to_uv(norm_xyz, axes), c) >= cfg.visibility)
                     for sel, c in zip(train_sel, cells)]
    counts = [int(sel.sum()) for sel in train_sel]
    if min(counts) < cfg.min_cameras:
        few = ", ".join(f"{c.name} {n}" for c, n in zip(cells, counts) if n < cfg.min_cameras)
        raise ConfigError(f"--blocks {cfg.blocks}: too few training cameras in {few} (need {cfg.min_cameras}); "
                          "use fewer blocks or more --overlap")
    out = _prepare_out(cfg)
    raw = _entries_by_image(meta, src_root)
    up_data = tf.transform[:, :3].double().T @ torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    blocks = []
    for cell, sel in zip(cells, train_sel):
        blocks.append(_write_block(out, cell, sel, groups, uv, raw, meta, src_root, points, up_data))
    doc = {
        "format": FORMAT,
        "source": str(Path(cfg.data).absolute()),
        "source_fingerprint": dataset_fingerprint(train_out.image_filenames),
        "grid": [k, l],
        "overlap": cfg.overlap,
        "visibility": cfg.visibility,
        "frame": "the source's normalised frame: x_n = scale * (R x_data + t), z up; u, v = axes @ (x_n, y_n)",
        "transform": tf.transform.tolist(),
        "scale": tf.scale,
        "axes": axes.tolist(),
        "blocks": blocks,
    }
    atomic_write_text(out / PARTITION_FILE, json.dumps(doc, indent=1))
    return doc


def looking_into(cameras, xyz: torch.Tensor, uv: torch.Tensor, cell: Cell) -> torch.Tensor:
    """``[N]``: per camera, the fraction of the points ``xyz`` (normalised frame) in its view that
    lie in ``cell`` (ground coordinates ``uv``); 0 for a camera that sees none."""
    in_cell = inside(uv, cell.u, cell.v)
    out = torch.zeros(len(cameras))
    for i in range(len(cameras)):
        pix, z = cameras.project(xyz, i)
        seen = (z > 0) & (pix[:, 0] >= 0) & (pix[:, 0] < cameras.width[i]) & (pix[:, 1] >= 0) & (pix[:, 1] < cameras.height[i])
        if bool(seen.any()):
            out[i] = float((seen & in_cell).sum()) / float(seen.sum())
    return out


def _write_block(out: Path, cell: Cell, train_sel: torch.Tensor, groups: dict[str, list[RawFrame]], uv: dict[str, torch.Tensor], raw: dict,
                 meta: dict, src_root: Path, points, up_data: torch.Tensor) -> dict:
    folder = out / cell.name
    folder.mkdir(parents=True, exist_ok=True)
    link = _Linker(src_root, folder)
    chosen = {}
    for split, frames in groups.items():
        keep = train_sel if split == "train" else inside(uv[split], cell.expanded_u, cell.expanded_v)
        chosen[split] = [_block_entry(f, raw[f.image.resolve()], link) for f, m in zip(frames, keep.tolist()) if m]
    block_meta = {k: v for k, v in meta.items() if k not in _SPLIT_KEYS}
    block_meta.setdefault("up", [float(x) for x in up_data])
    block_meta["frames"] = chosen["train"]
    evals = {s: e for s, e in chosen.items() if s != "train" and e}
    if evals:
        block_meta["eval_splits"] = evals
    n_points = 0
    if points is not None:
        xyz, rgb, puv = points
        keep = inside(puv, cell.expanded_u, cell.expanded_v).numpy()
        n_points = int(keep.sum())
        if n_points:
            name = Path(str(meta["ply_file_path"])).name
            write_ply_points(folder / name, xyz[keep], rgb[keep])
            block_meta["ply_file_path"] = name
    block_meta["partition"] = {"file": f"../{PARTITION_FILE}", "block": cell.name}
    atomic_write_text(folder / "transforms.json", json.dumps(block_meta, indent=1))
    return {**cell.to_json(), "folder": cell.name, "train_images": len(chosen["train"]),
            "eval_images": {s: len(e) for s, e in evals.items()}, "points": n_points}


def read_partition(path: Path) -> dict:
    """``partition.json`` (a file or the folder holding it), validated."""
    path = Path(path)
    if path.is_dir():
        path = path / PARTITION_FILE
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise DataError("no partition.json (not made by ns2gs-data partition)", path) from None
    except (OSError, ValueError) as e:
        raise DataError(f"malformed partition file ({e})", path) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("blocks"), list):
        raise DataError(f"not a partition file of format {FORMAT}", path)
    return doc


def block_of(data: Path) -> Optional[tuple[Path, str]]:
    """(partition.json, block name) for a block dataset folder; None for any other dataset."""
    meta_path = Path(data) / "transforms.json" if Path(data).is_dir() else Path(data)
    try:
        info = json.loads(meta_path.read_text()).get("partition")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(info, dict) or not isinstance(info.get("block"), str):
        return None
    return (meta_path.parent / str(info.get("file", f"../{PARTITION_FILE}"))).resolve(), info["block"]
