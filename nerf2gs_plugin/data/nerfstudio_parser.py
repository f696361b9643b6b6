"""nerfstudio ``transforms.json`` parser (also instant-ngp / blender style files).

Supported keys (top level = shared, or per frame = overrides):
  * intrinsics ``fl_x, fl_y, cx, cy, w, h`` or ``camera_angle_x`` (and ``camera_angle_y``); ``w, h``
    default to the image's size, ``cx, cy`` to the centre; ``camera_model`` PINHOLE, SIMPLE_PINHOLE,
    OPENCV (``k1, k2, p1, p2``, also ``k3``) or absent (OPENCV when distortion keys are nonzero);
  * frames ``file_path`` (relative to the file; a missing extension tries .png/.jpg),
    ``transform_matrix`` (4x4 or 3x4, OpenGL camera-to-world, must be rigid);
  * masks ``sky_mask_path``, ``ground_mask_path``, ``transient_mask_path`` per frame, else the folder
    convention ``masks/{sky,ground,transient}/<image stem>.png``; ``depth_file_path`` (``.npy`` metres,
    or 16-bit PNG times ``depth_unit_scale_factor``, default 1e-3);
  * ``ply_file_path`` (points in the same frame as the poses); ``metres_per_unit`` or ``scale_metric``;
    ``up`` (the data's up vector).
Splits:
  * ``eval_splits``: ``{name: [frame dict | file_path of an entry of frames, ...]}``; referenced
    entries of ``frames`` leave the train split;
  * ``train_filenames`` / ``val_filenames`` / ``test_filenames`` (nerfstudio): split names train/val/test;
  * with neither, every ``holdout_every``-th frame (sorted by file name) is the "test" split
    (0 disables: all frames train, no eval split).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import torch

from nerf2gs_plugin.data.base import RawFrame, build_outputs, check_split, find_folder_mask
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.images import image_size
from nerf2gs_plugin.data.normalize import NormalizeOptions, check_rigid, orthonormalize
from nerf2gs_plugin.data.ply import read_ply_points
from nerf2gs_plugin.data.registry import DataParserSpecification
from nerf2gs_plugin.data.undistort import Intrinsics
from nerf2gs_plugin.errors import DataError

_MODELS = ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV")


_WARNED_DUPLICATES: set[Path] = set()


def warn_duplicate_frames(path: Path, extra: int) -> None:
    """Usable input, worth one line: the same image listed twice is trained (and weighted) twice."""
    key = Path(path).resolve()
    if key not in _WARNED_DUPLICATES:
        _WARNED_DUPLICATES.add(key)
        print(f"warning: {path}: {extra} frame(s) repeat the file_path of an earlier frame; each entry is used as given",
              file=sys.stderr)


@dataclass
class NerfstudioDataParserConfig:
    """Read a nerfstudio ``transforms.json`` dataset (see the module docstring for the keys)."""

    data: Path = Path("data/street")
    """Dataset folder (holding transforms.json) or the JSON file itself."""
    downscale: float = 1.0
    """Shrink images by this factor (2 = half size); resized copies are cached in the dataset."""
    normalize: NormalizeOptions = field(default_factory=NormalizeOptions)
    metres_per_unit: Optional[float] = None
    """Override the file's metres_per_unit/scale_metric (metres per unit of the data frame)."""
    holdout_every: int = 8
    """Without split keys in the file, every N-th frame is the "test" split (0: none)."""
    camera_height: Optional[float] = None
    """Metric scale and up from the ground plane under the cameras at this height (m); see data/ground.py."""
    cache_dir: Optional[Path] = None
    """Where undistorted / resized copies go (None: in the dataset; see data/undistort.py)."""

    @property
    def json_path(self) -> Path:
        d = Path(self.data)
        return d if d.suffix.lower() == ".json" else d / "transforms.json"

    def splits(self) -> list[str]:
        """Split names this dataset has: "train" first."""
        return list(self.raw_frames())

    def raw_frames(self) -> dict[str, list[RawFrame]]:
        """Every split's frames as the file lists them (original image paths, c2w in the file's frame,
        intrinsics, masks), before any normalisation: for tools that work on the files themselves."""
        return self._frames()[1]

    def parse(self, split: str = "train") -> DataparserOutputs:
        meta, groups = self._frames()
        path = self.json_path
        check_split(split, groups.get(split, []), list(groups), path)
        if not groups["train"]:
            raise DataError("split 'train' is empty", path)
        xyz = rgb = None
        if meta.get("ply_file_path"):
            xyz, rgb = read_ply_points(path.parent / str(meta["ply_file_path"]))
        up = meta.get("up")
        if up is not None:
            try:
                up = torch.tensor([float(v) for v in up])
                assert up.shape == (3,) and float(up.norm()) > 0
            except (TypeError, ValueError, AssertionError):
                raise DataError(f"'up' must be a nonzero 3-vector, got {meta.get('up')!r}", path) from None
        mpu = self.metres_per_unit if self.metres_per_unit is not None else meta.get("metres_per_unit", meta.get("scale_metric", 1.0))
        mpu = _positive(mpu, "metres_per_unit", path)
        if self.camera_height is not None and self.metres_per_unit is None:
            from nerf2gs_plugin.data.ground import scale_from_frames

            mpu, up_np = scale_from_frames(torch.stack([f.c2w for f in groups["train"]]).numpy(), xyz, self.camera_height, path)
            up = torch.tensor(up_np, dtype=torch.float32)
        return build_outputs(split, groups[split], groups["train"], path.parent, self.normalize, float(self.downscale),
                             up, mpu, xyz, rgb, self.cache_dir)

    # ------------------------------------------------------------------ reading
    def _frames(self) -> tuple[dict[str, Any], dict[str, list[RawFrame]]]:
        path = self.json_path
        meta = _read_json(path)
        frames_raw = meta.get("frames")
        if not isinstance(frames_raw, list):
            raise DataError("no 'frames' list", path)
        root = path.parent
        frames = [self._frame(meta, fr, i, root, path, "frames") for i, fr in enumerate(frames_raw)]
        missing = {f.image.resolve() for f in frames if not f.image.is_file()}
        if missing:  # instant-ngp's own samples list absent images: skip them, as instant-ngp does
            import warnings

            warnings.warn(f"{path}: {len(missing)} of {len(frames)} frames list an image that does not exist; skipped", stacklevel=2)
            frames = [f for f in frames if f.image.resolve() not in missing]
        by_path = {f.image.resolve(): f for f in frames}
        if len(by_path) < len(frames):
            warn_duplicate_frames(path, len(frames) - len(by_path))

        def lookup(name: Any, where: str) -> Optional[RawFrame]:
            if not isinstance(name, str):
                raise DataError(f"{where}: expected a frame dict or a file path, got {type(name).__name__}", path)
            p = _image_path(root, name)
            if p.resolve() in missing:
                return None
            if p.resolve() not in by_path:
                raise DataError(f"{where}: '{name}' is not the file_path of any entry of 'frames'", path)
            return by_path[p.resolve()]

        groups: dict[str, list[RawFrame]] = {}
        used: set[int] = set()
        ev = meta.get("eval_splits")
        if ev is not None and not isinstance(ev, dict):
            raise DataError("'eval_splits' must be a dict of split name -> list of frames", path)
        if "train_filenames" in meta:
            groups["train"] = _present(lookup(n, f"train_filenames[{i}]") for i, n in enumerate(_list(meta, "train_filenames", path)))
        for key, name in (("val_filenames", "val"), ("test_filenames", "test")):
            if key in meta:
                groups[name] = _present(lookup(n, f"{key}[{i}]") for i, n in enumerate(_list(meta, key, path)))
                used.update(id(f) for f in groups[name])
        for name, entries in (ev or {}).items():
            if name == "train" or not isinstance(entries, list):
                raise DataError(f"eval_splits['{name}'] must be a list of frames (and not named 'train')", path)
            items = []
            for i, e in enumerate(entries):
                where = f"eval_splits['{name}'][{i}]"
                item = self._frame(meta, e, i, root, path, f"eval_splits['{name}']") if isinstance(e, dict) else lookup(e, where)
                if item is not None:
                    items.append(item)
            used.update(id(f) for f in items)
            groups[name] = items
        if "train" not in groups:
            rest = [f for f in frames if id(f) not in used]
            if not groups and self.holdout_every > 0 and len(rest) > 1:
                order = sorted(range(len(rest)), key=lambda i: str(rest[i].image))
                hold = {order[i] for i in range(0, len(order), self.holdout_every)}
                groups["test"] = [rest[i] for i in sorted(hold)]
                rest = [f for i, f in enumerate(rest) if i not in hold]
            groups = {"train": rest, **groups}
        else:
            groups = {"train": groups.pop("train"), **groups}
        return meta, groups

    def _frame(self, meta: dict, fr: Any, idx: int, root: Path, path: Path, where: str) -> RawFrame:
        where = f"{where}[{idx}]"
        if not isinstance(fr, dict) or "file_path" not in fr or "transform_matrix" not in fr:
            raise DataError(f"{where}: a frame needs 'file_path' and 'transform_matrix'", path)
        image = _image_path(root, str(fr["file_path"]))
        where = f"{where} ({fr['file_path']})"
        try:
            m = torch.tensor(fr["transform_matrix"], dtype=torch.float64)
        except (TypeError, ValueError):
            raise DataError(f"{where}: transform_matrix is not a numeric matrix", path) from None
        if m.shape not in ((4, 4), (3, 4)):
            raise DataError(f"{where}: transform_matrix has shape {tuple(m.shape)}, expected 4x4", path)
        check_rigid(m, where, path)
        c2w = torch.cat([orthonormalize(m[:3, :3]), m[:3, 3:]], dim=1).float()
        intr = self._intrinsics(meta, fr, image, where, path)
        masks = {}
        for kind in MASK_KINDS:
            key = f"{kind}_mask_path"
            masks[kind] = (root / str(fr[key])) if fr.get(key) else find_folder_mask(root, kind, image)
        depth = root / str(fr["depth_file_path"]) if fr.get("depth_file_path") else None
        scale = float(fr.get("depth_unit_scale_factor", meta.get("depth_unit_scale_factor", 1e-3)))
        return RawFrame(image, c2w, intr, masks, depth, scale)

    def _intrinsics(self, meta: dict, fr: dict, image: Path, where: str, path: Path) -> Intrinsics:
        def get(key: str, default: Any = None) -> Any:
            return fr.get(key, meta.get(key, default))

        model = get("camera_model")
        if model is not None and model not in _MODELS:
            raise DataError(f"{where}: camera_model '{model}' is not supported (use one of {', '.join(_MODELS)})", path)
        try:
            w, h = get("w"), get("h")
            if w is None or h is None:
                w, h = image_size(image)
            w, h = int(w), int(h)
            fx, fy = get("fl_x"), get("fl_y")
            if fx is None and get("camera_angle_x") is not None:
                fx = 0.5 * w / math.tan(0.5 * float(get("camera_angle_x")))
                fy = 0.5 * h / math.tan(0.5 * float(get("camera_angle_y"))) if get("camera_angle_y") is not None else fx
            if fx is None:
                raise DataError(f"{where}: no focal length (fl_x or camera_angle_x)", path)
            fy = fx if fy is None else fy
            dist = tuple(float(get(k, 0.0)) for k in ("k1", "k2", "p1", "p2", "k3"))
            vals = [float(fx), float(fy), float(get("cx", w / 2.0)), float(get("cy", h / 2.0))]
        except (TypeError, ValueError) as e:
            raise DataError(f"{where}: bad intrinsics ({e})", path) from None
        if model in ("PINHOLE", "SIMPLE_PINHOLE"):
            dist = (0.0,) * 5
        if not all(math.isfinite(v) for v in vals + list(dist)) or vals[0] <= 0 or vals[1] <= 0 or w <= 0 or h <= 0:
            raise DataError(f"{where}: intrinsics must be finite with positive focal length and size", path)
        return Intrinsics(*vals, w, h, dist)


def _read_json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise DataError("file does not exist", path)
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise DataError(f"malformed JSON: {e.msg} at line {e.lineno} column {e.colno}", path) from None
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(f"cannot read ({e})", path) from None
    if not isinstance(meta, dict):
        raise DataError("top level must be a JSON object", path)
    return meta


def _present(frames) -> list[RawFrame]:
    return [f for f in frames if f is not None]


def _list(meta: dict, key: str, path: Path) -> list:
    v = meta[key]
    if not isinstance(v, list):
        raise DataError(f"'{key}' must be a list of file paths", path)
    return v


def _image_path(root: Path, name: str) -> Path:
    p = root / name
    if p.suffix == "" and not p.exists():
        for ext in (".png", ".jpg", ".jpeg"):
            if p.with_suffix(ext).exists():
                return p.with_suffix(ext)
    return p


def _positive(v: Any, key: str, path: Path) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        f = float("nan")
    if not math.isfinite(f) or f <= 0:
        raise DataError(f"'{key}' must be a positive number, got {v!r}", path)
    return f


def _detect(data: Path) -> bool:
    return (data.is_file() and data.suffix.lower() == ".json") or (data / "transforms.json").is_file()


nerfstudio_dataparser = DataParserSpecification(
    detect=_detect, config=NerfstudioDataParserConfig,
    description="nerfstudio transforms.json (PINHOLE/OPENCV, instant-ngp keys, masks, eval splits)")
