"""Stressed copies of a nerfstudio dataset for the stability bench: pose noise, fewer training
views, no masks, no sparse points, mask errors (eroded, dilated, dropped) and per-frame exposure.

A copy is a new ``transforms.json`` (plus ``perturbation.json``) whose image, mask, depth and
point paths point back at the original files, so it costs no disk; only the masks and images a
stress changes (eroded/dilated masks, re-exposed images) are written into the copy. Only training frames are
changed; eval splits keep their exact poses and images. The folder name carries a hash of the
source file and the parameters, so a changed perturbation never reuses a stale copy (or the runs
trained on it: bench runs are filed under the dataset folder's name).
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from nerf2gs_plugin.data.base import find_folder_mask
from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.errors import DataError


@dataclass(frozen=True)
class Perturbation:
    """What to change in the training frames (all defaults: an identical copy)."""

    rotation_deg: float = 0.0
    """Each training camera is rotated by exactly this angle about a random axis through its centre."""
    translation_m: float = 0.0
    """... and moved by exactly this many metres in a random direction (``metres_per_unit`` applied)."""
    keep_every: int = 1
    """Keep every N-th training frame (2 = half the views)."""
    drop_masks: bool = False
    """Remove sky/ground/transient masks (training and eval frames)."""
    drop_points: bool = False
    """Remove the sparse points (methods fall back to random initialisation)."""
    mask_erode_px: int = 0
    """Shrink every training mask (sky, ground, transient) by this many pixels (square kernel)."""
    mask_dilate_px: int = 0
    """Grow every training mask by this many pixels (after any erosion)."""
    mask_drop_fraction: float = 0.0
    """Remove all masks of this fraction of the training frames (which ones: by ``seed``)."""
    exposure_spread: float = 0.0
    """Per-frame exposure change of each training image, in stops: gain ``2**u`` and offset
    ``EXPOSURE_OFFSET_PER_STOP * v`` with ``u, v`` uniform in ``[-spread, spread]`` (by ``seed``)."""
    seed: int = 0

    def tag(self) -> str:
        parts = []
        if self.rotation_deg or self.translation_m:
            parts.append(f"pose{self.rotation_deg:g}deg{self.translation_m * 100:g}cm")
        if self.keep_every > 1:
            parts.append(f"every{self.keep_every}")
        if self.drop_masks:
            parts.append("nomasks")
        if self.drop_points:
            parts.append("nopoints")
        if self.mask_erode_px:
            parts.append(f"erode{self.mask_erode_px}")
        if self.mask_dilate_px:
            parts.append(f"dilate{self.mask_dilate_px}")
        if self.mask_drop_fraction:
            parts.append(f"maskdrop{self.mask_drop_fraction:g}")
        if self.exposure_spread:
            parts.append(f"exposure{self.exposure_spread:g}")
        return "-".join(parts) or "copy"


EXPOSURE_OFFSET_PER_STOP = 0.05  # offset spread (in [0, 1] intensity) per stop of gain spread


def random_rotation(angle_rad: float, rng: np.random.Generator) -> np.ndarray:
    """A 3x3 rotation by ``angle_rad`` about a uniformly random axis (Rodrigues)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1 - math.cos(angle_rad)) * (k @ k)


def perturb_pose(c2w: Any, rotation_deg: float, translation_units: float, rng: np.random.Generator) -> list[list[float]]:
    """Camera-to-world (3x4 or 4x4) with its orientation rotated in place and its centre moved."""
    m = np.asarray(c2w, dtype=np.float64)
    out = np.eye(4)
    out[: m.shape[0], :4] = m[:, :4]
    out[:3, :3] = random_rotation(math.radians(rotation_deg), rng) @ out[:3, :3]
    d = rng.normal(size=3)
    out[:3, 3] += translation_units * d / np.linalg.norm(d)
    return out[: m.shape[0]].tolist()


def _absolute(root: Path, value: Any) -> str:
    p = Path(str(value))
    return str(p if p.is_absolute() else (root / p).resolve())


def _eval_names(meta: dict) -> set[str]:
    names = set()
    for key in ("val_filenames", "test_filenames"):
        names.update(str(n) for n in meta.get(key) or [])
    for entries in (meta.get("eval_splits") or {}).values():
        names.update(str(e) for e in entries if isinstance(e, str))
    return names


def _rewrite_frame(frame: dict, root: Path, drop_masks: bool) -> dict:
    fr = dict(frame)
    image = Path(_absolute(root, fr["file_path"]))
    fr["file_path"] = str(image)
    for kind in MASK_KINDS:
        key = f"{kind}_mask_path"
        if drop_masks:
            fr.pop(key, None)
        elif fr.get(key):
            fr[key] = _absolute(root, fr[key])
        else:
            found = find_folder_mask(root, kind, image)
            if found is None and image.suffix == "":
                found = next((find_folder_mask(root, kind, image.with_suffix(e)) for e in (".png", ".jpg") if image.with_suffix(e).exists()), None)
            if found is not None:
                fr[key] = str(found.resolve())
    if fr.get("depth_file_path"):
        fr["depth_file_path"] = _absolute(root, fr["depth_file_path"])
    return fr


def morph_mask(mask: np.ndarray, erode_px: int = 0, dilate_px: int = 0) -> np.ndarray:
    """Bool ``[H, W]`` mask shrunk by ``erode_px`` then grown by ``dilate_px`` pixels (square kernel)."""
    import cv2

    out = mask.astype(np.uint8)
    if erode_px:
        out = cv2.erode(out, np.ones((2 * erode_px + 1,) * 2, np.uint8), borderType=cv2.BORDER_REPLICATE)
    if dilate_px:
        out = cv2.dilate(out, np.ones((2 * dilate_px + 1,) * 2, np.uint8), borderType=cv2.BORDER_REPLICATE)
    return out > 0


def exposure_draws(pert: Perturbation, n: int) -> list[tuple[float, float]]:
    """(gain, offset) of each of ``n`` training frames, deterministic by ``pert.seed``."""
    if not pert.exposure_spread:
        return [(1.0, 0.0)] * n
    rng = np.random.default_rng([pert.seed, 2])  # its own stream: the pose noise of a seed is unchanged
    u = rng.uniform(-pert.exposure_spread, pert.exposure_spread, size=(n, 2))
    return [(float(2.0 ** a), float(EXPOSURE_OFFSET_PER_STOP * b)) for a, b in u]


def _stress_masks(frame: dict, dst: Path, pert: Perturbation, drop: bool) -> None:
    """Drop the frame's masks, or write its eroded/dilated masks into the copy and point at them."""
    from nerf2gs_plugin.data.images import load_mask, write_mask_atomic

    for kind in MASK_KINDS:
        key = f"{kind}_mask_path"
        if not frame.get(key):
            continue
        if drop:
            frame.pop(key)
        elif pert.mask_erode_px or pert.mask_dilate_px:
            src = Path(frame[key])
            out = dst / "masks" / kind / f"{Path(frame['file_path']).stem}.png"
            write_mask_atomic(out, morph_mask(load_mask(src).numpy(), pert.mask_erode_px, pert.mask_dilate_px))
            frame[key] = str(out.resolve())


def _stress_exposure(frame: dict, dst: Path, gain: float, offset: float) -> None:
    """Write the frame's image with ``gain * rgb + offset`` (clipped) into the copy and point at it."""
    from nerf2gs_plugin.data.images import load_image, write_image_atomic

    src = Path(frame["file_path"])
    out = dst / "images" / f"{src.stem}.png"
    write_image_atomic(out, (load_image(src).numpy() * gain + offset).clip(0.0, 1.0))
    frame["file_path"] = str(out.resolve())


def perturbed_copy(src: Path, dst_root: Path, pert: Perturbation) -> Path:
    """Write (or reuse) the stressed copy of the dataset at ``src`` under ``dst_root``; returns its folder."""
    src = Path(src)
    path = src / "transforms.json" if src.is_dir() else src
    if not path.is_file():
        raise DataError("stability perturbations need a nerfstudio transforms.json dataset", path)
    raw = path.read_bytes()
    try:
        meta = json.loads(raw)
        frames = meta["frames"]
        assert isinstance(frames, list)
    except (json.JSONDecodeError, KeyError, AssertionError, TypeError):
        raise DataError("not a transforms.json with a 'frames' list", path) from None
    root = path.parent
    digest = hashlib.sha1(raw + json.dumps(asdict(pert), sort_keys=True).encode()).hexdigest()[:8]
    dst = Path(dst_root) / f"{root.name}-{pert.tag()}-{digest}"
    if (dst / "transforms.json").is_file() and (dst / "perturbation.json").is_file():
        return dst
    out = copy.deepcopy(meta)
    eval_names = _eval_names(meta)
    has_splits = bool(eval_names) or "eval_splits" in meta or "train_filenames" in meta
    if pert.keep_every > 1 and not has_splits:
        raise DataError("keeping a subset of views needs explicit eval splits (eval_splits or *_filenames), "
                        "else the held-out frames would change too", path)
    train_names = {str(n) for n in meta.get("train_filenames") or []}
    is_train = [(str(f.get("file_path")) in train_names) if train_names else (str(f.get("file_path")) not in eval_names) for f in frames]
    mpu = float(meta.get("metres_per_unit", meta.get("scale_metric", 1.0)) or 1.0)
    rng = np.random.default_rng(pert.seed)
    n_kept = len(range(0, sum(is_train), pert.keep_every))
    drop_rng = np.random.default_rng([pert.seed, 1])  # its own stream, as the exposure's
    mask_drops = set(drop_rng.choice(n_kept, size=int(round(pert.mask_drop_fraction * n_kept)), replace=False).tolist())
    exposures = exposure_draws(pert, n_kept)
    new_frames, kept_names, dropped, n_train = [], [], set(), 0
    masks_dropped, exposure_log = [], {}
    for fr, train in zip(frames, is_train):
        if not isinstance(fr, dict) or "file_path" not in fr or "transform_matrix" not in fr:
            raise DataError("a frame needs 'file_path' and 'transform_matrix'", path)
        new = _rewrite_frame(fr, root, pert.drop_masks)
        if train:
            n_train += 1
            if (n_train - 1) % pert.keep_every:
                dropped.add(str(fr["file_path"]))
                continue
            if pert.rotation_deg or pert.translation_m:
                new["transform_matrix"] = perturb_pose(fr["transform_matrix"], pert.rotation_deg, pert.translation_m / mpu, rng)
            k = (n_train - 1) // pert.keep_every  # index among the kept training frames
            if k in mask_drops or pert.mask_erode_px or pert.mask_dilate_px:
                _stress_masks(new, dst, pert, drop=k in mask_drops)
                if k in mask_drops:
                    masks_dropped.append(str(fr["file_path"]))
            if pert.exposure_spread:
                _stress_exposure(new, dst, *exposures[k])
                exposure_log[str(fr["file_path"])] = list(exposures[k])
        kept_names.append((str(fr["file_path"]), new["file_path"]))
        new_frames.append(new)
    out["frames"] = new_frames
    rename = dict(kept_names)
    for key in ("train_filenames", "val_filenames", "test_filenames"):
        if key in meta:
            out[key] = [rename[str(n)] for n in meta[key] if str(n) not in dropped and str(n) in rename]
    if isinstance(meta.get("eval_splits"), dict):
        out["eval_splits"] = {name: [rename.get(str(e), str(e)) if isinstance(e, str) else _rewrite_frame(e, root, pert.drop_masks)
                                     for e in entries] for name, entries in meta["eval_splits"].items()}
    if meta.get("ply_file_path"):
        if pert.drop_points:
            out.pop("ply_file_path")
        else:
            out["ply_file_path"] = _absolute(root, meta["ply_file_path"])
    dst.mkdir(parents=True, exist_ok=True)
    atomic_write_text(dst / "transforms.json", json.dumps(out, indent=1))
    info = {"source": str(root.resolve()), "perturbation": asdict(pert), "train_frames": n_train,
            "train_frames_kept": n_train - len(dropped), "masks_dropped": masks_dropped, "exposure": exposure_log}
    atomic_write_text(dst / "perturbation.json", json.dumps(info, indent=1))
    return dst


def pose_difference(a: Any, b: Any) -> tuple[float, float]:
    """(rotation angle in degrees, centre distance) between two camera-to-world matrices."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    r = a[:3, :3].T @ b[:3, :3]
    # ||R - I||_F = 2 sqrt(2) sin(angle / 2): well conditioned for small angles, unlike acos of the trace
    angle = math.degrees(2 * math.asin(min(1.0, float(np.linalg.norm(r - np.eye(3))) / (2 * math.sqrt(2)))))
    return angle, float(np.linalg.norm(a[:3, 3] - b[:3, 3]))


def describe(dst: Path) -> Optional[dict]:
    """The ``perturbation.json`` of a copy, if it is one."""
    p = Path(dst) / "perturbation.json"
    return json.loads(p.read_text()) if p.is_file() else None
