"""The augment cache's on-disk format, defined once: where each rendered image lives in a cache
entry, the manifest that describes the entry, and its one reader (:func:`read_manifest`), which the
AugmentedDataManager, the viewer and export-augmented all use.

An entry ``<reference run>/augment_cache/<key>/`` holds ``composites/00007.png`` (input view 7 with
its transient pixels from the reference), ``extra_raw/00003.png`` (+ ``_depth.npy``: bird's-eye
view 3 as rendered), ``extra/00003.png`` (after the enhancer) and ``manifest.json``; with
``--augment.confidence`` also ``composites/00007_conf.npy`` and ``extra/00003_conf.npy`` (float16
``[H, W]`` per-pixel confidence, :func:`load_confidence`). An entry is
written under a temporary name and renamed into place, so a present manifest means a whole entry.

Every bird's-eye render is also kept on its own key (:class:`ViewStore`, ``augment_cache/views/``):
the reference, the view's own camera and the render settings, nothing of the rest of the entry. A
run that changes what does not change that view (``--augment.composites``, the enhancer, the
confidence, ``min-coverage``, more or fewer views) reuses it, and a render cut short keeps the views it
finished. Entries written before the view store are read as such a store too (:meth:`ViewStore.add_entries`).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np
import torch
from torch import Tensor

from nerf2gs_plugin.augment.config import FAMILY_FIELDS
from nerf2gs_plugin.augment.geometry import ViewGeometry
from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.utils.io import atomic_write_text, temp_beside

CACHE_FORMAT_VERSION = 1
CACHE_DIR_NAME = "augment_cache"
MANIFEST_NAME = "manifest.json"
# AugmentConfig fields that do not change a rendered image (so not in the key)
UNKEYED_FIELDS = ("extra_prob", "extra_weight", "use_cache", "enhancer", "real_only_from", "birds_eye_share", "seed_points", "extra_decay", "extra_decay_floor",
                  "seed_points_per_family", "reference_sky", "step_factor", "composite_loss",
                  "composite_loss_margin")
UNKEYED_FAMILY_FIELDS = ("share",)
"""A view family's parameters that do not change its views (how often they are sampled)."""


def family_params(config: dict[str, Any], name: str) -> Optional[dict[str, Any]]:
    """A family's parameters in a plain AugmentConfig (its field ``name``), without the unkeyed ones."""
    params = config.get(name)
    return {k: v for k, v in params.items() if k not in UNKEYED_FAMILY_FIELDS} if isinstance(params, dict) else params


@dataclass
class CacheManifest:
    """What one cache entry holds; ``config`` is the AugmentConfig as a plain dict."""

    reference: str
    dataset: str
    config: dict[str, Any]
    enhancer: str
    composited_images: list[int]
    num_extra: int
    extra_camera_to_worlds: list = field(default_factory=list)  # [num_extra][3][4]
    extra_indices: list = field(default_factory=list)  # which input poses' views were kept (the rest dropped)
    # per kept view: its family and the input view it was made from (empty: an entry of birds-eye
    # views only, written before the families, whose sources follow from every_n)
    extra_families: list = field(default_factory=list)
    extra_sources: list = field(default_factory=list)
    dropped_outside_box: int = 0
    dropped_empty: int = 0
    render_seconds: float = 0.0  # the reference's render time for this entry
    format_version: int = CACHE_FORMAT_VERSION
    path: Optional[Path] = None  # where it was read from (not written)

    @property
    def entry(self) -> Path:
        assert self.path is not None, "manifest was not read from disk"
        return self.path.parent

    def composite_png(self, i: int) -> Path:
        return self.entry / "composites" / f"{i:05d}.png"

    def extra_png(self, j: int, raw: bool = False) -> Path:
        return self.entry / ("extra_raw" if raw else "extra") / f"{j:05d}.png"

    def extra_poses(self, dtype: torch.dtype = torch.float32) -> Tensor:
        """``[num_extra, 3, 4]`` camera-to-world poses of the bird's-eye views, as they were rendered."""
        return torch.tensor(self.extra_camera_to_worlds, dtype=dtype).reshape(-1, 3, 4)

    @property
    def geometry(self) -> ViewGeometry:
        """Where this entry's bird's-eye views are (the poses themselves: :meth:`extra_poses`)."""
        return ViewGeometry.recorded(self.config)

    def write(self, entry: Path) -> None:
        doc = {k: v for k, v in asdict(self).items() if k != "path"}
        (Path(entry) / MANIFEST_NAME).write_text(json.dumps(doc, indent=1, default=str))  # str: a pose file's path


def read_manifest(path: Path) -> CacheManifest:
    """The manifest of a cache entry (its folder or its ``manifest.json``). Raises ``ValueError``
    on a malformed or other-version manifest, ``OSError`` when it cannot be read."""
    path = Path(path)
    if path.is_dir():
        path = path / MANIFEST_NAME
    try:
        doc = json.loads(path.read_text())
        version = int(doc.get("format_version", -1))
        if version != CACHE_FORMAT_VERSION:
            raise ValueError(f"cache format {version}, expected {CACHE_FORMAT_VERSION}")
        manifest = CacheManifest(
            reference=str(doc["reference"]), dataset=str(doc["dataset"]), config=dict(doc["config"]),
            enhancer=str(doc["enhancer"]), composited_images=[int(i) for i in doc["composited_images"]],
            num_extra=int(doc["num_extra"]), extra_camera_to_worlds=list(doc["extra_camera_to_worlds"]),
            extra_indices=[int(i) for i in doc.get("extra_indices", range(int(doc["num_extra"])))],
            dropped_outside_box=int(doc.get("dropped_outside_box", 0)), dropped_empty=int(doc.get("dropped_empty", 0)),
            render_seconds=float(doc.get("render_seconds", 0.0)), path=path,
            extra_families=[str(f) for f in doc.get("extra_families", [])],
            extra_sources=[int(i) for i in doc.get("extra_sources", [])],
        )
        if manifest.num_extra and manifest.extra_poses().shape[0] != manifest.num_extra:
            raise ValueError("extra_camera_to_worlds does not match num_extra")
        if any(len(x) not in (0, manifest.num_extra) for x in (manifest.extra_families, manifest.extra_sources)):
            raise ValueError("extra_families / extra_sources do not match num_extra")
    except (KeyError, TypeError, RuntimeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: malformed augment cache manifest ({e})") from None
    return manifest


def cache_manifests(cache_root: Path) -> list[CacheManifest]:
    """Every readable manifest under ``<cache_root>/augment_cache``, newest first."""
    paths = sorted(Path(cache_root).glob(f"{CACHE_DIR_NAME}/*/{MANIFEST_NAME}"), key=lambda p: p.stat().st_mtime, reverse=True)
    found = []
    for p in paths:
        try:
            found.append(read_manifest(p))
        except (OSError, ValueError):
            continue
    return found


def cache_key(ref_key: str, dataset: str, config: dict[str, Any], bev: Optional[Cameras], train: Cameras, enhancer_key: str) -> str:
    """The entry name: everything that changes a rendered image (``config`` is the plain AugmentConfig)."""
    relevant = {k: v for k, v in config.items() if k not in UNKEYED_FIELDS}
    views = list(relevant.pop("views", ["birds-eye"]))
    for family, name in FAMILY_FIELDS.items():  # a family's parameters key the entry only when it is used
        if family not in views:
            relevant.pop(name, None)
        elif name in relevant:
            relevant[name] = family_params(relevant, name)
    if views != ["birds-eye"]:  # the bird's-eye views alone: the entries of runs before the families
        relevant["views"] = views
    if relevant.get("confidence", "none") == "none":  # no confidence maps: the entries of runs before the option
        relevant = {k: v for k, v in relevant.items() if not k.startswith("confidence")}
    if relevant.get("confidence") != "footprint":  # its ratio: the entries of the other confidences before it
        relevant.pop("confidence_footprint_ratio", None)
    if relevant.get("view_downscale", 1) == 1:  # the input views' size: the entries of runs before the option
        relevant.pop("view_downscale", None)
    for off in ("delta_h_spread", "theta_pitch_spread", "drop_outside_box"):  # off: the entries of runs before the option
        if not relevant.get(off):
            relevant.pop(off, None)
    h = hashlib.sha1()
    h.update(json.dumps({"v": CACHE_FORMAT_VERSION, "ref": ref_key, "data": dataset, "cfg": relevant, "enh": enhancer_key}, sort_keys=True, default=str).encode())
    for cams in (train, bev):
        if cams is not None:
            h.update(np.round(cams.camera_to_worlds.cpu().numpy(), 5).tobytes())
            h.update(cams.Ks().cpu().numpy().round(3).tobytes())
    return h.hexdigest()[:16]


def save_png(path: Path, img: Tensor) -> None:
    """``[H, W, 3]`` float image in [0, 1] -> 8-bit PNG, atomically."""
    import cv2

    arr = (img.clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)
    tmp = temp_beside(path)
    cv2.imwrite(str(tmp), arr[..., ::-1])
    os.replace(tmp, path)


def confidence_path(png: Path) -> Path:
    """The confidence map beside a cached render's PNG."""
    return Path(png).with_name(Path(png).stem + "_conf.npy")


def load_confidence(png: Path) -> Tensor:
    """``[H, W, 1]`` float confidence of the cached render ``png`` (see the module docstring)."""
    path = confidence_path(png)
    try:
        return torch.from_numpy(np.load(path).astype(np.float32))[..., None]
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: unreadable confidence map ({e})") from None


def load_png(path: Path) -> Tensor:
    import cv2

    arr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if arr is None:
        raise FileNotFoundError(path)
    return torch.from_numpy(arr[..., ::-1].copy()).float() / 255.0


VIEWS_DIR_NAME = "views"
VIEW_KEY_VERSION = 1


def view_key(ref_key: str, appearance: str, camera: Cameras) -> str:
    """The key of one render: the reference, how it colours novel views, the camera (pose, intrinsics, size)."""
    h = hashlib.sha1()
    h.update(json.dumps({"v": VIEW_KEY_VERSION, "ref": ref_key, "appearance": appearance}, sort_keys=True).encode())
    h.update(np.round(camera.camera_to_worlds.cpu().numpy(), 5).tobytes())
    h.update(camera.Ks().cpu().numpy().round(3).tobytes())
    h.update(np.asarray([int(camera.width[0]), int(camera.height[0])], dtype=np.int64).tobytes())
    return h.hexdigest()[:20]


@dataclass
class StoredView:
    """One render as the store gives it back: ``rgb`` (8-bit, as every cached PNG), ``depth`` and
    ``accumulation`` (float16) when the reference rendered them, and its coverage (share of pixels with
    accumulation > 0.5; None: the reference renders no accumulation)."""

    out: dict[str, Tensor]
    coverage: Optional[float]
    kept_at: Optional[float] = None
    """A view of an entry written before the store: no accumulation kept, only that it passed this ``min_coverage``."""

    def usable(self, min_coverage: float, needs_accumulation: bool) -> bool:
        """Whether it stands for a new render under these settings (else render it again)."""
        if self.kept_at is None:
            return True
        return min_coverage <= self.kept_at and not needs_accumulation

    def dropped(self, min_coverage: float) -> bool:
        """A mostly empty render: too few pixels with accumulation > 0.5."""
        return self.coverage is not None and self.coverage < min_coverage


class ViewStore:
    """Bird's-eye renders of one reference, one file set per :func:`view_key` under ``augment_cache/views``."""

    def __init__(self, cache_root: Path, ref_key: str, appearance: str, read: bool = True) -> None:
        self.dir = Path(cache_root) / CACHE_DIR_NAME / VIEWS_DIR_NAME
        self.ref_key, self.appearance, self.read = ref_key, appearance, read
        self.legacy: dict[str, tuple[Path, float]] = {}  # key -> (extra_raw PNG of an older entry, its min_coverage)

    def key(self, camera: Cameras) -> str:
        return view_key(self.ref_key, self.appearance, camera)

    def add_entries(self, dataset: str, cameras: Cameras, view_downscale: int = 1) -> None:
        """Make the kept views of older entries (same reference, dataset, appearance and view size) findable:
        their manifests hold each view's pose; its intrinsics are those of ``cameras`` (same dataset), matched by pose."""
        poses = np.round(cameras.camera_to_worlds.cpu().numpy(), 5)
        for m in cache_manifests(self.dir.parent.parent):
            if m.reference != self.ref_key or m.dataset != dataset or m.config.get("appearance", "mean") != self.appearance:
                continue
            if int(m.config.get("view_downscale", 1)) != view_downscale:  # a pose match of another size is another render
                continue
            for k, pose in enumerate(np.round(m.extra_poses().numpy(), 5)):
                hit = np.flatnonzero(np.abs(poses - pose).reshape(len(poses), -1).max(-1) < 1e-5)
                if len(hit):
                    self.legacy.setdefault(self.key(cameras[int(hit[0])]), (m.extra_png(k, raw=True), float(m.config.get("min_coverage", 0.5))))

    def get(self, camera: Cameras) -> Optional[StoredView]:
        """The stored render of ``camera``, or None (none stored, or the store is write-only: ``read=False``)."""
        if not self.read:
            return None
        key = self.key(camera)
        png = self.dir / f"{key}.png"
        if png.is_file() and (self.dir / f"{key}.json").is_file():
            try:
                meta = json.loads((self.dir / f"{key}.json").read_text())
                out = {"rgb": load_png(png)}
                for name in ("depth", "accumulation"):
                    if meta.get(name):
                        out[name] = torch.from_numpy(np.load(self.dir / f"{key}_{name}.npy").astype(np.float32))
                return StoredView(out, meta.get("coverage"))
            except (OSError, ValueError, KeyError):
                return None
        if key in self.legacy:
            raw, kept_at = self.legacy[key]
            depth = raw.with_name(raw.stem + "_depth.npy")
            try:
                out = {"rgb": load_png(raw)}
                if depth.is_file():
                    out["depth"] = torch.from_numpy(np.load(depth).astype(np.float32))
                return StoredView(out, None, kept_at)
            except (OSError, ValueError):
                return None
        return None

    def put(self, camera: Cameras, out: dict[str, Tensor]) -> None:
        """Keep one render (each file written whole, the ``.json`` last: it marks the view as complete)."""
        self.dir.mkdir(parents=True, exist_ok=True)
        key = self.key(camera)
        meta: dict[str, Any] = {"coverage": None}
        if "accumulation" in out:
            meta["coverage"] = float((out["accumulation"] > 0.5).float().mean())
        for name in ("depth", "accumulation"):
            if name in out:
                tmp = temp_beside(self.dir / f"{key}_{name}.npy")
                np.save(tmp, out[name].cpu().numpy().astype(np.float16))
                os.replace(tmp, self.dir / f"{key}_{name}.npy")
                meta[name] = True
        save_png(self.dir / f"{key}.png", out["rgb"])
        atomic_write_text(self.dir / f"{key}.json", json.dumps(meta))
