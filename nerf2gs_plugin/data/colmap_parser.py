"""COLMAP sparse-model parser (binary or text, read with pycolmap).

Layout: ``<data>/sparse/0`` (or ``<data>/sparse``, or ``<data>/colmap/sparse/0``), images in
``<data>/images/<image name>``, optional masks ``<data>/masks/{sky,ground,transient}/<image stem>.png``
(nonzero = inside). Cameras SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV become our
OPENCV (k1, k2, p1, p2) and are undistorted (see :mod:`undistort`). ``points3D`` initialise splats.

Splits: ``<data>/splits.json`` = ``{"train": [image names], "<split>": [image names], ...}``
(without "train", train = the images in no other split); without the file, every
``holdout_every``-th image sorted by name (the 0th, 8th, ...) is the "test" split, as the
mip-NeRF 360 / nerfstudio convention. Metric scale: ``--pipeline.datamanager.dataparser.metres-per-unit``, or
``--pipeline.datamanager.dataparser.camera-height`` (ground plane, see :mod:`nerf2gs_plugin.data.ground`), or the
older ``<data>/scene.json`` (``metres_per_unit`` and ``up`` for the COLMAP world); ``ns2gs-data process``
writes a transforms.json with both instead.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from nerf2gs_plugin.cameras import opencv_w2c_to_opengl_c2w
from nerf2gs_plugin.data.colmap_binary import check_intrinsics_inside, check_model_dir
from nerf2gs_plugin.data.base import RawFrame, build_outputs, check_split, find_folder_mask
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS, DataparserOutputs
from nerf2gs_plugin.data.normalize import NormalizeOptions
from nerf2gs_plugin.data.registry import DataParserSpecification
from nerf2gs_plugin.data.undistort import Intrinsics
from nerf2gs_plugin.errors import DataError

MODEL_DIRS = ("sparse/0", "sparse", "colmap/sparse/0")


def find_model_dir(root: Path) -> Optional[Path]:
    """The first folder under ``root`` holding ``cameras.bin`` or ``cameras.txt``."""
    for d in MODEL_DIRS:
        p = root / d
        if (p / "cameras.bin").is_file() or (p / "cameras.txt").is_file():
            return p
    return None


@dataclass
class ColmapDataParserConfig:
    """Read a COLMAP sparse reconstruction with its images (see the module docstring)."""

    data: Path = Path("data/colmap")
    downscale: float = 1.0
    """Shrink images by this factor; resized (and undistorted) copies are cached in the dataset."""
    images_dir: str = "images"
    normalize: NormalizeOptions = field(default_factory=NormalizeOptions)
    metres_per_unit: Optional[float] = None
    """Metres per COLMAP unit (overrides scene.json; default 1)."""
    holdout_every: int = 8
    """Without splits.json, every N-th image is the "test" split (0: none)."""
    camera_height: Optional[float] = None
    """Metric scale and up from the ground plane under the cameras at this height (m); see data/ground.py."""
    cache_dir: Optional[Path] = None
    """Where undistorted / resized copies go (None: in the dataset; see data/undistort.py)."""

    def splits(self) -> list[str]:
        return list(self.raw_frames())

    def parse(self, split: str = "train") -> DataparserOutputs:
        groups, rec, model_dir = self._groups()
        check_split(split, groups.get(split, []), list(groups), model_dir)
        if not groups["train"]:
            raise DataError("split 'train' is empty", model_dir)
        for frame in (f for fs in groups.values() for f in fs):
            if not bool(torch.isfinite(frame.c2w.float()).all()):  # beyond float32 counts too
                posed_in = model_dir / ("frames.bin" if (model_dir / "frames.bin").is_file() else "images.bin")
                raise DataError(f"image {frame.image.name}: non-finite camera pose", posed_in)
        pts = rec.points3D
        with np.errstate(over="ignore"):  # a float64 beyond float32 becomes inf: reported below
            xyz = np.array([p.xyz for p in pts.values()], dtype=np.float32).reshape(-1, 3) if len(pts) else None
        rgb = np.array([p.color for p in pts.values()], dtype=np.uint8).reshape(-1, 3) if len(pts) else None
        if xyz is not None and not np.isfinite(xyz).all():
            bad = int((~np.isfinite(xyz).all(axis=1)).sum())
            raise DataError(f"{bad} of {len(xyz)} points have non-finite (or beyond float32) coordinates", model_dir / "points3D.bin")
        scene = self._scene_meta()
        up = torch.tensor(scene["up"], dtype=torch.float32) if scene.get("up") is not None else None
        mpu = float(self.metres_per_unit if self.metres_per_unit is not None else scene.get("metres_per_unit", 1.0))
        if not mpu > 0:
            raise DataError(f"metres_per_unit must be positive, got {mpu}", Path(self.data) / "scene.json")
        if self.camera_height is not None and self.metres_per_unit is None:
            from nerf2gs_plugin.data.ground import scale_from_frames

            mpu, up_np = scale_from_frames(torch.stack([f.c2w for f in groups["train"]]).numpy(), xyz, self.camera_height, model_dir)
            up = torch.tensor(up_np, dtype=torch.float32)
        return build_outputs(split, groups[split], groups["train"], Path(self.data), self.normalize, float(self.downscale),
                             up, mpu, xyz, rgb, self.cache_dir)

    # ------------------------------------------------------------------ reading
    def _scene_meta(self) -> dict:
        p = Path(self.data) / "scene.json"
        if not p.is_file():
            return {}
        try:
            meta = json.loads(p.read_text())
            assert isinstance(meta, dict)
            return meta
        except (json.JSONDecodeError, AssertionError) as e:
            raise DataError(f"malformed JSON ({e})", p) from None

    def _read_model(self):
        import pycolmap

        root = Path(self.data)
        model_dir = find_model_dir(root)
        if model_dir is None:
            raise DataError(f"no COLMAP model (cameras.bin/.txt in one of {', '.join(MODEL_DIRS)})", root)
        check_model_dir(model_dir)  # counts vs file sizes before pycolmap allocates anything
        try:
            rec = pycolmap.Reconstruction(str(model_dir))
        except Exception as e:  # pycolmap raises ValueError/RuntimeError with a C++ message
            raise DataError(f"cannot read COLMAP model ({str(e).splitlines()[0]})", model_dir) from None
        return rec, model_dir

    def raw_frames(self) -> dict[str, list[RawFrame]]:
        """Every split's registered frames as the model lists them (original image paths, intrinsics),
        before any normalisation: for tools that work on the files themselves."""
        return self._groups()[0]

    def _groups(self):
        rec, model_dir = self._read_model()
        root = Path(self.data)
        img_dir = root / self.images_dir
        if not img_dir.is_dir():
            raise DataError(f"COLMAP model has no '{self.images_dir}/' folder next to it", root)
        frames: dict[str, RawFrame] = {}
        for image in sorted(rec.images.values(), key=lambda i: i.name):
            if not image.has_pose:
                continue
            cam = rec.cameras[image.camera_id]
            intr = _intrinsics(cam, model_dir, image.name)
            check_intrinsics_inside(intr, f"camera {cam.camera_id} of image '{image.name}'", model_dir)
            w2c = torch.eye(4, dtype=torch.float64)
            w2c[:3] = torch.from_numpy(np.asarray(image.cam_from_world().matrix(), dtype=np.float64))
            c2w = opencv_w2c_to_opengl_c2w(w2c[None])[0].float()
            path = img_dir / image.name
            if not path.is_file():
                raise DataError(f"image '{image.name}' of the COLMAP model does not exist", path)
            masks = {k: find_folder_mask(root, k, path) for k in MASK_KINDS}
            frames[image.name] = RawFrame(path, c2w, intr, masks)
        names = list(frames)
        split_file = root / "splits.json"
        groups: dict[str, list[RawFrame]] = {}
        if split_file.is_file():
            try:
                spec = json.loads(split_file.read_text())
                assert isinstance(spec, dict) and all(isinstance(v, list) for v in spec.values())
            except (json.JSONDecodeError, AssertionError):
                raise DataError("malformed split file (expected {split: [image names]})", split_file) from None
            for name, items in spec.items():
                missing = [n for n in items if n not in frames]
                if missing:
                    raise DataError(f"split '{name}' names images not in the COLMAP model: {', '.join(map(str, missing[:3]))}", split_file)
                groups[name] = [frames[n] for n in items]
            if "train" not in groups:
                used = {n for items in spec.values() for n in items}
                groups["train"] = [frames[n] for n in names if n not in used]
        elif self.holdout_every > 0 and len(names) > 1:
            groups["train"] = [frames[n] for i, n in enumerate(names) if i % self.holdout_every != 0]
            groups["test"] = [frames[n] for i, n in enumerate(names) if i % self.holdout_every == 0]
        else:
            groups["train"] = [frames[n] for n in names]
        groups = {"train": groups.pop("train"), **groups}
        return groups, rec, model_dir


def _intrinsics(cam, model_dir: Path, image_name: str) -> Intrinsics:
    """COLMAP camera -> our Intrinsics (pixel centre at +0.5 in both conventions)."""
    model, p = cam.model.name, [float(v) for v in cam.params]
    w, h = int(cam.width), int(cam.height)
    if model == "SIMPLE_PINHOLE":
        return Intrinsics(p[0], p[0], p[1], p[2], w, h)
    if model == "PINHOLE":
        return Intrinsics(p[0], p[1], p[2], p[3], w, h)
    if model == "SIMPLE_RADIAL":
        return Intrinsics(p[0], p[0], p[1], p[2], w, h, (p[3], 0.0, 0.0, 0.0, 0.0))
    if model == "RADIAL":
        return Intrinsics(p[0], p[0], p[1], p[2], w, h, (p[3], p[4], 0.0, 0.0, 0.0))
    if model == "OPENCV":
        return Intrinsics(p[0], p[1], p[2], p[3], w, h, (p[4], p[5], p[6], p[7], 0.0))
    raise DataError(
        f"camera {cam.camera_id} of image '{image_name}' uses model {model}; supported: "
        "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV",
        model_dir,
    )


colmap_dataparser = DataParserSpecification(
    detect=lambda data: data.is_dir() and find_model_dir(data) is not None,
    config=ColmapDataParserConfig,
    description="COLMAP sparse model (binary or text, via pycolmap) with its images")
